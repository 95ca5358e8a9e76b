"""From board corners to calibrated cameras: intrinsics, a spanning-tree start, bundle
adjustment.

1. Intrinsics per camera with ``cv2.calibrateCamera`` (Zhang's method), then the pose of the
   board in every view a camera sees (``solvePnP``).
2. Relative poses of every pair of cameras that see the board in the same views (a robust
   mean over those views); the cameras are chained from the reference camera along a maximum
   spanning tree of this graph (edge weight: shared views).
3. Joint bundle adjustment of all cameras and board poses (the board is rigid and of known
   size, which fixes the scale): Levenberg-Marquardt with a sparse analytic Jacobian and a
   soft-L1 robust loss, iterated with a shrinking outlier threshold (Anipose, Algorithm 1).
4. Several starts (spanning trees from random subsets of the views); the best is kept, and
   the spread of the others measures how repeatable the calibration is.

The world frame is the reference camera's (x right, y down, z forward, mm). Steps 1 and 2 are
:mod:`videotrack.calibration.bundle_start`, step 3 :mod:`videotrack.calibration.bundle_adjust`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from kinematics.cameras import PinholeCamera
from kinematics.cameras.calibration_math import camera_from_params, compose, params_from_camera
from videotrack.calibration.bundle_adjust import (
    _N_CAM,
    Problem,
    adjust_iterative,
    inlier_threshold,
)
from videotrack.calibration.bundle_start import (
    board_poses,
    intrinsics,
    spanning_tree,
    unflip,
    world_board_poses,
)
from videotrack.calibration.detect import Corners
from videotrack.errors import VideoTrackError, VideoTrackWarning

__all__ = ["Calibration", "Options", "calibrate"]


@dataclass
class Options:
    """How to calibrate; the defaults suit most rigs."""

    reference: int = 0  # index of the camera that defines the world frame
    n_dist: int = 5  # 0, 4 (k1 k2 p1 p2) or 5 (+ k3) distortion coefficients
    fix_intrinsics: bool = False  # keep the intrinsics of step 1 (or the given ones)
    restarts: int = 5  # bundle adjustments from different starts
    iterations: int = 6  # of the shrinking threshold
    mu_start: float = 15.0  # px, first outlier threshold
    mu_end: float = 1.0  # px, last outlier threshold
    max_intrinsic_views: int = 40  # views per camera given to calibrateCamera
    intrinsics_only: bool = False
    symmetric: bool = False  # checkerboard: corner order may be turned 180° between cameras
    seed: int = 0
    known: dict = field(default_factory=dict)  # camera index -> PinholeCamera intrinsics


@dataclass
class Calibration:
    """The result: cameras and everything the report needs."""

    cameras: list[PinholeCamera]
    board_poses: np.ndarray  # (n_views, 6) rvec, t of the board in the world; NaN if unposed
    errors: np.ndarray  # (n_cams, n_views, n_corners) reprojection error px, NaN if unseen
    inlier: np.ndarray  # same shape, bool: kept by the last outlier threshold
    threshold: float  # px, the last outlier threshold
    restarts: list[dict]  # per start: cameras, median error, cost
    tree: list[tuple[int, int, int]]  # (parent, child, shared views) of the spanning tree
    views_used: np.ndarray  # (n_cams,) views with a board pose that the camera sees
    seconds: float = 0.0



# --- the whole calibration --------------------------------------------------------------------


def _pack_start(cam_world, intr, board_world, n_views):
    full_cams = np.hstack([cam_world, intr])
    return np.r_[full_cams.ravel(), np.nan_to_num(board_world).ravel()]


def calibrate(corners: list[Corners], object_points: np.ndarray, opts: Options,
              progress=None) -> Calibration:
    """Calibrate the cameras of ``corners`` (see the module docstring).

    ``progress(done, total)`` is called after each start.
    """
    try:  # the solves are small: BLAS threads only contend (10x slower on a busy machine)
        from threadpoolctl import threadpool_limits
    except ImportError:
        return _calibrate(corners, object_points, opts, progress)
    with threadpool_limits(1):
        return _calibrate(corners, object_points, opts, progress)


def _calibrate(corners, object_points, opts, progress):
    import time

    started = time.perf_counter()
    names = [c.name for c in corners]
    n_cams, n_views = len(corners), len(corners[0].uv)
    rng = np.random.default_rng(opts.seed)
    intr = np.array([_known_or_fit(c, i, object_points, opts, rng)
                     for i, c in enumerate(corners)])
    poses = [board_poses(c, object_points, intr[i]) for i, c in enumerate(corners)]
    free_cam = np.ones((n_cams, _N_CAM), bool)
    free_cam[:, 6 + 4 + opts.n_dist:] = False  # unused distortion terms
    if opts.fix_intrinsics:
        free_cam[:, 6:] = False
    if opts.intrinsics_only:  # (cameras may have different numbers of views here)
        return _intrinsics_only(corners, object_points, opts, intr, poses, free_cam, rng,
                                started)
    poses = np.array(poses)
    uv_all = np.array([c.uv for c in corners])

    free_cam[opts.reference, :6] = False  # the world frame
    if opts.symmetric:
        flipped = unflip(corners, poses, object_points, intr, opts.reference, names)
        if flipped:
            uv_all = np.array([c.uv for c in corners])
    runs = []
    for k in range(max(1, opts.restarts)):
        cam_world, tree = spanning_tree(poses, opts.reference, names,
                                        None if k == 0 else rng, fraction=0.6)
        board_world = world_board_poses(cam_world, poses)
        free_view = np.repeat(np.all(np.isfinite(board_world), axis=-1)[:, None], 6, 1)
        # corners of unposed views cannot enter the adjustment
        uv_used = np.where(free_view[None, :, :1, None], uv_all, np.nan)
        problem = Problem(uv_used, object_points, n_views, free_cam, free_view)
        start = _pack_start(cam_world, intr, board_world, n_views)
        full, err, inlier = adjust_iterative(problem, start, opts, rng)
        cams, views = problem.unpack(full)
        runs.append({"full": full, "cams": cams, "views": views, "median": float(np.median(err)),
                     "cost": float(np.mean(np.minimum(err, 5.0) ** 2)), "err": err,
                     "inlier": inlier, "problem": problem, "tree": tree,
                     "threshold": inlier_threshold(err, opts)})
        if progress is not None:
            progress(k + 1, max(1, opts.restarts))
    best = min(runs, key=lambda r: r["cost"])
    problem, cams = best["problem"], best["cams"]
    posed = problem.mask[n_cams * _N_CAM:].reshape(-1, 6)[:, 0]
    views = np.where(posed[:, None], best["views"], np.nan)
    cameras = [camera_from_params(names[i], cams[i, :3], cams[i, 3:6], cams[i, 6:],
                                  corners[i].size, opts.n_dist) for i in range(n_cams)]
    errors = np.full(uv_all.shape[:3], np.nan)
    errors[problem.cam, problem.view, problem.point] = best["err"]
    inlier = np.zeros(errors.shape, bool)
    inlier[problem.cam, problem.view, problem.point] = best["inlier"]
    restarts = [{"cameras": [camera_from_params(names[i], r["cams"][i, :3], r["cams"][i, 3:6],
                                                r["cams"][i, 6:], None, opts.n_dist)
                             for i in range(n_cams)],
                 "median": r["median"], "best": r is best} for r in runs]
    used = np.isfinite(errors).any(axis=2).sum(axis=1)
    return Calibration(cameras, views, errors, inlier, best["threshold"], restarts,
                       best["tree"], used, time.perf_counter() - started)


def _intrinsics_only(corners, object_points, opts, intr, poses, free_cam, rng, started):
    """Each camera alone (at the world origin): the same iterative adjustment of its
    intrinsics and its own board poses, so bad corners are rejected here too."""
    import time

    n_cams, n_max = len(corners), max(len(c.uv) for c in corners)
    errors = np.full((n_cams, n_max, len(object_points)), np.nan)
    inlier = np.zeros(errors.shape, bool)
    cameras = []
    for i, c in enumerate(corners):
        posed = np.all(np.isfinite(poses[i]), axis=-1)
        free_view = np.repeat(posed[:, None], 6, 1)
        free = free_cam[i:i + 1].copy()
        free[0, :6] = False
        uv = np.where(posed[None, :, None, None], c.uv[None], np.nan)
        problem = Problem(uv, object_points, len(c.uv), free, free_view)
        start = np.r_[np.zeros(6), intr[i], np.nan_to_num(poses[i]).ravel()]
        full, err, ok = adjust_iterative(problem, start, opts, rng)
        cameras.append(camera_from_params(c.name, np.zeros(3), np.zeros(3), full[6:_N_CAM],
                                          c.size, opts.n_dist))
        errors[i, problem.view, problem.point] = err
        inlier[i, problem.view, problem.point] = ok
    used = np.isfinite(errors).any(axis=2).sum(axis=1)
    return Calibration(cameras, np.full((n_max, 6), np.nan), errors, inlier,
                       float(opts.mu_end), [], [], used, time.perf_counter() - started)


def reframe(cal: Calibration, view: int) -> list[PinholeCamera]:
    """The cameras with the board of ``view`` as the world frame (origin at its first
    corner, x and y along the board, z into it)."""
    if not 0 <= view < len(cal.board_poses) or not np.all(np.isfinite(cal.board_poses[view])):
        raise VideoTrackError(f"view {view} has no board pose (not seen, or too few corners); "
                              "choose a view seen by several cameras", field="--world-view")
    rb, tb = cal.board_poses[view, :3], cal.board_poses[view, 3:]
    out = []
    for cam in cal.cameras:
        # x_cam = R_c (R_b x + t_b) + t_c
        r, t = compose(params_from_camera(cam)[0], cam.t, rb, tb)
        out.append(PinholeCamera(cam.name, cam.K, cam.dist[:5], t=t, size=cam.image_size,
                                 rvec=r))
    return out


def _known_or_fit(corners: Corners, i: int, object_points, opts: Options, rng) -> np.ndarray:
    cam = opts.known.get(i)
    if cam is None:
        return intrinsics(corners, object_points, opts, rng)
    if np.any(cam.dist[5:]):
        warnings.warn(f"{cam.name}: only 5 distortion coefficients are calibrated; k4-k6 of "
                      "the given intrinsics are dropped", VideoTrackWarning, stacklevel=3)
    k = cam.K
    return np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2], *cam.dist[:5]])
