"""The start of a calibration (steps 1 and 2 of :mod:`videotrack.calibration.bundle`):
each camera's intrinsics and the board's pose in every view it sees, then the cameras
chained from the reference camera along a maximum spanning tree of the views they share.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

from kinematics.cameras.calibration_math import compose, invert, mean_pose, rodrigues
from videotrack.calibration.detect import Corners
from videotrack.errors import VideoTrackError

if TYPE_CHECKING:
    from videotrack.calibration.bundle import Options

#: Corners a view needs to enter a camera's intrinsics or a board pose.
MIN_VIEW_CORNERS = 6


# --- step 1: intrinsics and board poses per camera -------------------------------------------


def _view_points(corners: Corners, v: int, object_points: np.ndarray):
    seen = np.isfinite(corners.uv[v, :, 0])
    return (object_points[seen].astype(np.float32),
            corners.uv[v, seen].astype(np.float32), seen)


def _cv_flags(n_dist: int) -> int:
    flags = 0
    if n_dist < 5:
        flags |= cv2.CALIB_FIX_K3
    if n_dist == 0:
        flags |= cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_ZERO_TANGENT_DIST
    return flags


def intrinsics(corners: Corners, object_points: np.ndarray, opts: Options,
               rng: np.random.Generator) -> np.ndarray:
    """(9,) intrinsics of one camera from its own views (Zhang's method)."""
    counts = np.isfinite(corners.uv[..., 0]).sum(axis=1)
    views = np.flatnonzero(counts >= MIN_VIEW_CORNERS)
    if len(views) < 3:
        raise VideoTrackError(f"the board is seen in {len(views)} usable view(s); intrinsics "
                              "need at least 3 views of the board in different poses",
                              field=f"camera {corners.name}")
    if len(views) > opts.max_intrinsic_views:  # spread over the recording, most corners first
        views = np.sort(rng.choice(views, opts.max_intrinsic_views, replace=False))
    obj, img = zip(*(_view_points(corners, v, object_points)[:2] for v in views), strict=True)
    w, h = corners.size
    K0 = np.array([[max(w, h), 0, (w - 1) / 2], [0, max(w, h), (h - 1) / 2], [0, 0, 1.0]])
    # ChArUco partial views are not all planar-homography friendly for OpenCV's own start:
    # start from a plausible guess (focal = image size) instead.
    flags = _cv_flags(opts.n_dist) | cv2.CALIB_USE_INTRINSIC_GUESS
    try:
        _, K, dist, _, _ = cv2.calibrateCamera(list(obj), list(img), (w, h), K0, None,
                                               flags=flags)
    except cv2.error as err:
        raise VideoTrackError(f"OpenCV could not calibrate this camera: {err.err}",
                              field=f"camera {corners.name}") from None
    d = np.zeros(5)
    d[: min(5, dist.size)] = dist.ravel()[:5]
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d])


def board_poses(corners: Corners, object_points: np.ndarray, intr: np.ndarray) -> np.ndarray:
    """(n_views, 6) pose of the board in the camera per view; NaN where not posed."""
    K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1.0]])
    out = np.full((len(corners.uv), 6), np.nan)
    for v in range(len(corners.uv)):
        obj, img, seen = _view_points(corners, v, object_points)
        if seen.sum() < MIN_VIEW_CORNERS:
            continue
        # RANSAC: a few misdetected corners must not tilt the start of a whole view
        ok, r, t, inl = cv2.solvePnPRansac(obj, img, K, intr[4:], reprojectionError=3.0,
                                           iterationsCount=50, flags=cv2.SOLVEPNP_IPPE)
        if ok and inl is not None and len(inl) >= MIN_VIEW_CORNERS:
            inl = inl.ravel()
            ok, r, t = cv2.solvePnP(obj[inl], img[inl], K, intr[4:], r, t, True,
                                    flags=cv2.SOLVEPNP_ITERATIVE)
        if ok and t[2, 0] > 0:
            out[v] = np.r_[r.ravel(), t.ravel()]
    return out


# --- step 2: spanning tree --------------------------------------------------------------------


def spanning_tree(poses: np.ndarray, reference: int, names: list[str],
                  rng: np.random.Generator | None = None, fraction: float = 1.0):
    """Camera poses (n_cams, 6) in the reference camera's frame, and the tree's edges.

    ``poses[c, v]`` is the board pose in camera c for view v. With ``rng``, each pair's
    relative pose comes from a random ``fraction`` of its shared views and the edge weights
    are perturbed, so different starts take different trees.
    """
    n = len(poses)
    posed = np.all(np.isfinite(poses), axis=-1)  # (n_cams, n_views)
    shared = (posed[:, None] & posed[None]).sum(-1)
    weight = shared.astype(float)
    if rng is not None:
        weight = weight * rng.uniform(0.5, 1.5, weight.shape)
    rel = {}
    in_tree, edges = {reference}, []
    world = np.full((n, 6), np.nan)
    world[reference] = 0.0
    while len(in_tree) < n:
        best = None
        for a in in_tree:
            for b in set(range(n)) - in_tree:
                if shared[a, b] >= 1 and (best is None or weight[a, b] > weight[best]):
                    best = (a, b)
        if best is None:
            missing = [names[c] for c in sorted(set(range(n)) - in_tree)]
            linked = [names[c] for c in sorted(in_tree)]
            raise VideoTrackError(
                f"camera(s) {', '.join(missing)} never see the board in the same frame as "
                f"{', '.join(linked)}: record views where the board is seen by both groups at "
                "once (or calibrate them separately with --intrinsics-only)", field="--camera")
        a, b = best
        views = np.flatnonzero(posed[a] & posed[b])
        if rng is not None and fraction < 1.0 and len(views) > 2:
            views = rng.choice(views, max(2, round(fraction * len(views))), replace=False)
        # camera b from camera a: x_b = T_b<-board T_a<-board^-1 x_a, per shared view
        ra, ta = invert(poses[a, views, :3], poses[a, views, 3:])
        r, t = compose(poses[b, views, :3], poses[b, views, 3:], ra, ta)
        rel[(a, b)] = mean_pose(r, t)
        # world -> b = (a -> b) (world -> a)
        world[b, :3], world[b, 3:] = compose(*rel[(a, b)], world[a, :3], world[a, 3:])
        in_tree.add(b)
        edges.append((a, b, int(shared[a, b])))
    return world, edges


def world_board_poses(cam_world: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(n_views, 6) board pose in the world per view, averaged over the cameras posing it."""
    n_views = poses.shape[1]
    out = np.full((n_views, 6), np.nan)
    for v in range(n_views):
        cams = np.flatnonzero(np.all(np.isfinite(poses[:, v]), axis=-1))
        if len(cams) == 0:
            continue
        # world <- board = (world <- cam)(cam <- board)
        rc, tc = invert(cam_world[cams, :3], cam_world[cams, 3:])
        r, t = compose(rc, tc, poses[cams, v, :3], poses[cams, v, 3:])
        out[v, :3], out[v, 3:] = mean_pose(r, t) if len(cams) > 1 else (r[0], t[0])
    return out


def unflip(corners: list[Corners], poses: np.ndarray, object_points: np.ndarray,
           intr: np.ndarray, reference: int, names: list[str]) -> int:
    """Reverse the corner order of checkerboard views detected turned by 180° relative to
    the other cameras (OpenCV may start at either end of a symmetric board); the views of
    ``corners`` and ``poses`` are updated in place. Returns how many were reversed."""
    world, _ = spanning_tree(poses, reference, names)  # robust to a minority of flips
    n_flipped = 0
    for v in range(poses.shape[1]):
        cams = np.flatnonzero(np.all(np.isfinite(poses[:, v]), axis=-1))
        if len(cams) < 2:
            continue
        # board normal of each camera's pose, in the world: flips turn it about the normal,
        # so compare the board's x axis instead
        rc, tc = invert(world[cams, :3], world[cams, 3:])
        r, _ = compose(rc, tc, poses[cams, v, :3], poses[cams, v, 3:])
        x_axis = rodrigues(r)[:, :, 0]
        anchor = x_axis[0]
        for j, c in enumerate(cams[1:], 1):
            if x_axis[j] @ anchor < 0:
                corners[c].uv[v] = corners[c].uv[v, ::-1].copy()
                poses[c, v] = board_poses_one(corners[c], v, object_points, intr[c])
                n_flipped += 1
    return n_flipped


def board_poses_one(corners: Corners, v: int, object_points, intr) -> np.ndarray:
    single = Corners(corners.name, corners.size, corners.frames[v:v + 1],
                     corners.uv[v:v + 1], corners.labels[v:v + 1])
    return board_poses(single, object_points, intr)[0]
