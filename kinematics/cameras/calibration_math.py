"""Vectorised camera math for calibration: rotations, poses, board projection, triangulation.

Pure NumPy, no file formats. A pose ``(rvec, t)`` maps points of a source frame into a target
frame, ``x_target = R(rvec) @ x_source + t``, as OpenCV's ``solvePnP`` and
:class:`~kinematics.cameras.PinholeCamera` (world to camera) do. Intrinsics are packed as
``(fx, fy, cx, cy, k1, k2, p1, p2, k3)``; the projection is ``cv2.projectPoints`` with five
distortion coefficients, which the tests check.
"""

from __future__ import annotations

import cv2
import numpy as np

from kinematics.cameras import PinholeCamera

__all__ = [
    "N_INTRINSICS",
    "camera_from_params",
    "compose",
    "invert",
    "mean_pose",
    "params_from_camera",
    "project",
    "rodrigues",
    "rotation_to_rvec",
    "triangulate",
]

#: fx, fy, cx, cy, k1, k2, p1, p2, k3.
N_INTRINSICS = 9


def rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrices of Rodrigues vectors, shape (..., 3) -> (..., 3, 3)."""
    rvec = np.asarray(rvec, dtype=np.float64)
    theta = np.linalg.norm(rvec, axis=-1)[..., None, None]
    small = theta < 1e-12
    safe = np.where(small, 1.0, theta)
    k = (rvec / safe[..., 0, 0][..., None])[..., None, :]  # (..., 1, 3) unit axis
    kx, ky, kz = k[..., 0, 0], k[..., 0, 1], k[..., 0, 2]
    zero = np.zeros_like(kx)
    cross = np.stack([np.stack([zero, -kz, ky], -1), np.stack([kz, zero, -kx], -1),
                      np.stack([-ky, kx, zero], -1)], -2)
    outer = k.swapaxes(-1, -2) @ k
    eye = np.eye(3)
    rot = np.cos(safe) * eye + np.sin(safe) * cross + (1.0 - np.cos(safe)) * outer
    return np.where(small, eye, rot)


def rotation_to_rvec(R: np.ndarray) -> np.ndarray:
    """Rodrigues vectors of rotation matrices, shape (..., 3, 3) -> (..., 3)."""
    R = np.asarray(R, dtype=np.float64)
    flat = R.reshape(-1, 3, 3)
    out = np.array([cv2.Rodrigues(np.ascontiguousarray(m))[0].ravel() for m in flat])
    return out.reshape((*R.shape[:-2], 3))


def compose(r_ab, t_ab, r_bc, t_bc):
    """Pose c -> a from poses b -> a and c -> b (all as Rodrigues vector, translation)."""
    R_ab, R_bc = rodrigues(r_ab), rodrigues(r_bc)
    R = R_ab @ R_bc
    t = (R_ab @ np.asarray(t_bc)[..., None])[..., 0] + t_ab
    return rotation_to_rvec(R), t


def invert(r, t):
    """Inverse of the pose (r, t)."""
    R = rodrigues(r)
    Rt = np.swapaxes(R, -1, -2)
    return rotation_to_rvec(Rt), -(Rt @ np.asarray(t)[..., None])[..., 0]


def mean_pose(r: np.ndarray, t: np.ndarray):
    """Robust mean of poses (n, 3), (n, 3): chordal L2 mean of the rotations after dropping
    those far from the element-wise median, median of the translations."""
    R = rodrigues(r)
    med = rodrigues(np.median(r, axis=0))
    # angle between each rotation and the median guess; drop gross outliers (flipped boards)
    cos = (np.trace(np.swapaxes(med, -1, -2) @ R, axis1=-2, axis2=-1) - 1.0) / 2.0
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    keep = angle <= max(np.median(angle) * 3.0, np.deg2rad(5.0))
    u, _, vt = np.linalg.svd(R[keep].sum(axis=0))
    Rm = u @ vt
    if np.linalg.det(Rm) < 0:
        Rm = u @ np.diag([1.0, 1.0, -1.0]) @ vt
    return rotation_to_rvec(Rm), np.median(t[keep], axis=0)


def project(points_cam: np.ndarray, intrinsics: np.ndarray) -> np.ndarray:
    """Pixels of camera-frame points (n, 3) with per-point intrinsics (n, 9) or one (9,)."""
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = np.moveaxis(np.asarray(intrinsics), -1, 0)
    z = points_cam[..., 2]
    z = np.where(np.abs(z) < 1e-9, 1e-9, z)
    x, y = points_cam[..., 0] / z, points_cam[..., 1] / z
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([fx * xd + cx, fy * yd + cy], axis=-1)


def params_from_camera(camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rvec, t, intrinsics (9,)) of a pinhole camera with at most 5 distortion terms."""
    k = camera.K
    d = camera.dist
    intr = np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2], *d[:5]])
    rvec = camera.rvec if camera.rvec is not None else rotation_to_rvec(camera.R)
    return np.array(rvec, dtype=float), np.array(camera.t, dtype=float), intr


def camera_from_params(name: str, rvec, t, intrinsics, size=None,
                       n_dist: int = 5) -> PinholeCamera:
    """A :class:`PinholeCamera` from packed parameters, keeping ``n_dist`` coefficients."""
    fx, fy, cx, cy = intrinsics[:4]
    K = [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]
    dist = list(intrinsics[4:4 + n_dist]) if n_dist else []
    return PinholeCamera(name, K, dist, t=t, size=size, rvec=np.asarray(rvec, dtype=float))


def triangulate(cameras: list[PinholeCamera], uv: np.ndarray) -> np.ndarray:
    """Linear (DLT) triangulation of distortion-corrected pixels.

    Parameters
    ----------
    cameras : list of PinholeCamera, length c
    uv : ndarray, shape (c, n, 2)
        Pixels, NaN where a camera does not see a point.

    Returns
    -------
    ndarray, shape (n, 3)
        World points; NaN where fewer than two cameras see a point.
    """
    c, n, _ = uv.shape
    rows = np.zeros((n, 2 * c, 4))
    for i, cam in enumerate(cameras):
        seen = np.all(np.isfinite(uv[i]), axis=-1)
        if not seen.any():
            continue
        und = cv2.undistortPoints(np.ascontiguousarray(uv[i][seen].reshape(-1, 1, 2)),
                                  cam.K, cam.dist).reshape(-1, 2)  # normalised coordinates
        P = np.hstack([cam.R, cam.t[:, None]])
        rows[seen, 2 * i] = und[:, :1] * P[2] - P[0]
        rows[seen, 2 * i + 1] = und[:, 1:] * P[2] - P[1]
    n_seen = np.all(np.isfinite(uv), axis=-1).sum(axis=0)
    _, _, vt = np.linalg.svd(rows)
    X = vt[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = X[:, :3] / X[:, 3:]
    out[n_seen < 2] = np.nan
    return out
