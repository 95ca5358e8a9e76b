"""Rendered board views through known cameras: test data with exact ground truth.

Used by the tests, the benchmark and the guide (docs/calibration.md) to make board images
for cameras whose parameters are known, including lens distortion (rendered by remapping).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from kinematics.cameras import PinholeCamera
from kinematics.cameras.calibration_math import rodrigues
from videotrack.calibration.boards import Board

__all__ = ["board_image", "board_poses_facing", "render_view", "write_views"]


def _grid_image(board: Board, m: int) -> tuple[np.ndarray, np.ndarray]:
    """An ArUco grid with ``m`` px per marker side and a one-marker white margin, each marker
    placed on whole pixels (``GridBoard.generateImage`` truncates fractional positions)."""
    scale = m / board.marker_mm
    gap = board.separation_mm * scale
    if abs(gap - round(gap)) > 1e-6:
        raise ValueError(f"the separation is {gap:g} px at {m} px per marker; choose "
                         "px_per_square so that it is a whole number of pixels")
    nx, ny = board.squares
    pitch = m + round(gap)
    image = np.full((ny * pitch - round(gap) + 2 * m, nx * pitch - round(gap) + 2 * m), 255,
                    np.uint8)
    dictionary = board._cv.getDictionary()
    for k in range(nx * ny):  # marker k at column k % nx, row k // nx, as GridBoard puts it
        x, y = m + (k % nx) * pitch, m + (k // nx) * pitch
        image[y:y + m, x:x + m] = dictionary.generateImageMarker(k, m)
    S = np.array([[scale, 0, m - 0.5], [0, scale, m - 0.5], [0, 0, 1.0]])
    return image, S


def board_image(board: Board, px_per_square: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """The board as a grey image with a one-square white margin, and the 3x3 matrix taking
    board coordinates (mm, z = 0 plane, homogeneous) to image pixels (centres at integers).
    For an ArUco grid, ``px_per_square`` is the pixels per marker side."""
    if board.type == "aruco":
        return _grid_image(board, px_per_square)
    nx, ny = board.squares
    m = px_per_square
    size = (nx * m + 2 * m, ny * m + 2 * m)
    if board.type == "charuco":
        image = board._cv.generateImage(size, marginSize=m)
        outer = np.zeros(2)  # ChArUco corners are counted from the outer corner
    else:
        yy, xx = np.mgrid[0:size[1], 0:size[0]] // m
        inside = (xx >= 1) & (xx <= nx) & (yy >= 1) & (yy <= ny)
        image = np.where(inside & ((xx + yy) % 2 == 0), 0, 255).astype(np.uint8)
        outer = -np.full(2, board.square_mm)  # checkerboard corners from the first inner one
    scale = m / board.square_mm
    S = np.array([[scale, 0, m - 0.5 - outer[0] * scale],
                  [0, scale, m - 0.5 - outer[1] * scale], [0, 0, 1.0]])
    return image, S


def render_view(image: np.ndarray, S: np.ndarray, camera: PinholeCamera, rvec, tvec,
                *, blur: float = 0.7, noise: float = 1.0, rng=None) -> np.ndarray:
    """The board image as ``camera`` sees it with the board at pose (rvec, tvec) in the
    world; lens distortion included. Grey background 128, mild blur and noise."""
    w, h = camera.image_size
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    pix = np.stack([u.ravel(), v.ravel()], -1).reshape(-1, 1, 2)
    norm = cv2.undistortPoints(pix, camera.K, camera.dist).reshape(-1, 2)
    # camera <- board: R_c (R_b x + t_b) + t_c; the board plane z = 0 maps by a homography
    Rb = rodrigues(np.asarray(rvec, float))
    R = camera.R @ Rb
    t = camera.R @ np.asarray(tvec, float) + camera.t
    H = np.column_stack([R[:, 0], R[:, 1], t])  # normalised image <- board mm
    src = (S @ np.linalg.inv(H)) @ np.column_stack([norm, np.ones(len(norm))]).T
    behind = src[2] <= 0
    mx = (src[0] / src[2]).reshape(h, w).astype(np.float32)
    my = (src[1] / src[2]).reshape(h, w).astype(np.float32)
    mx[behind.reshape(h, w)] = -1e4
    # supersampling would be exact; a blur of the source does the anti-aliasing well enough
    out = cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=128)
    if blur:
        out = cv2.GaussianBlur(out, (0, 0), blur)
    if noise:
        rng = rng or np.random.default_rng(0)
        out = np.clip(out + rng.normal(0, noise, out.shape), 0, 255).astype(np.uint8)
    return out


def _look_at(cameras: list[PinholeCamera]) -> np.ndarray:
    """The point nearest to all optical axes (least squares)."""
    A, b = np.zeros((3, 3)), np.zeros(3)
    for cam in cameras:
        d = cam.view_direction
        P = np.eye(3) - np.outer(d, d)
        A += P
        b += P @ cam.centre
    return np.linalg.lstsq(A, b, rcond=None)[0]


def board_poses_facing(board: Board, cameras: list[PinholeCamera], n: int, *, seed: int = 0,
                       spread: float = 0.35, tilt_deg: float = 35.0, min_cameras: int = 2,
                       full: bool = True):
    """``n`` random board poses (rvec, t in the world) near where the cameras look, tilted by
    up to ``tilt_deg``, each seen whole (``full``) or partly by ``min_cameras`` cameras."""
    rng = np.random.default_rng(seed)
    target = _look_at(cameras)
    look = np.mean([c.view_direction for c in cameras], axis=0)
    look /= np.linalg.norm(look)
    # a board frame whose z axis points away from the cameras (its printed side faces them)
    x = np.cross([0.0, 1.0, 0.0], look) if abs(look[1]) < 0.9 else np.cross([1.0, 0, 0], look)
    x /= np.linalg.norm(x)
    base = np.column_stack([x, np.cross(look, x), look])
    obj = board.object_points
    size = np.ptp(obj, axis=0).max()
    poses = []
    for _ in range(200 * n):
        tilt = rodrigues(rng.normal(0, np.deg2rad(tilt_deg) / 2, 3))
        R = base @ tilt
        t = target + rng.normal(0, spread * size, 3) - R @ obj.mean(0)
        world = obj @ R.T + t
        seen = 0
        for cam in cameras:
            p = cam.project(world)
            w, h = cam.image_size
            ok = np.all(np.isfinite(p), 1) & (p[:, 0] > 8) & (p[:, 0] < w - 9) & \
                (p[:, 1] > 8) & (p[:, 1] < h - 9)
            seen += ok.all() if full else ok.mean() > 0.3
        if seen >= min_cameras:
            poses.append((cv2.Rodrigues(R)[0].ravel(), t))
            if len(poses) == n:
                break
    return poses


def write_views(folder, board: Board, cameras: list[PinholeCamera], n_views: int, *,
                seed: int = 0, px_per_square: int = 40, full: bool = True) -> list:
    """Render ``n_views`` board poses into ``folder/CAMERA/view_NNN.png``; returns the poses."""
    folder = Path(folder)
    image, S = board_image(board, px_per_square)
    poses = board_poses_facing(board, cameras, n_views, seed=seed, full=full)
    rng = np.random.default_rng(seed)
    for cam in cameras:
        (folder / cam.name).mkdir(parents=True, exist_ok=True)
        for i, (r, t) in enumerate(poses):
            cv2.imwrite(str(folder / cam.name / f"view_{i:03d}.png"),
                        render_view(image, S, cam, r, t, rng=rng))
    return poses
