"""Refining camera poses from the animal: corresponding 2D points across views (tracked
markers or keypoints, as Anipose's "animal calibration" and DeepFly3D do).

The intrinsics stay; the poses of all cameras but the reference, and the 3D points, are
adjusted jointly with the same iterative, robust bundle adjustment as the board calibration
(:func:`videotrack.calibration.bundle.adjust_iterative`). Without a board the scale is free:
it is restored afterwards from the camera centres' spread before refinement.
"""

from __future__ import annotations

import numpy as np

from kinematics.cameras import PinholeCamera
from kinematics.cameras.calibration_math import camera_from_params, params_from_camera, triangulate
from videotrack.calibration.bundle import Options
from videotrack.calibration.bundle_adjust import (
    _N_CAM,
    Problem,
    adjust_iterative,
    project_by_camera,
)
from videotrack.errors import VideoTrackError

__all__ = ["refine_extrinsics", "triangulated_errors"]


def triangulated_errors(cameras: list[PinholeCamera], uv: np.ndarray) -> np.ndarray:
    """Reprojection errors (n_cams, n_points) of points triangulated from all cameras
    (Anipose's measure of a calibration without a board); NaN where unseen."""
    uv = _points(cameras, uv)
    X = triangulate(cameras, uv)
    return np.array([np.linalg.norm(c.project(X) - uv[i], axis=-1)
                     for i, c in enumerate(cameras)])


def _points(cameras, uv) -> np.ndarray:
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 3 or uv.shape[0] != len(cameras) or uv.shape[2] != 2:
        raise VideoTrackError(f"expected points of shape ({len(cameras)} cameras, points, 2), "
                              f"got {uv.shape}", field="p2d")
    return uv


class PointProblem(Problem):
    """Residuals of 2D observations of free 3D points: parameters [cams | points (n, 3)]."""

    block = 3

    def __init__(self, uv_all: np.ndarray, free_cam: np.ndarray) -> None:
        self.cam, self.view = np.nonzero(np.isfinite(uv_all[..., 0]))  # view = point index
        self.point = self.view
        self.uv = uv_all[self.cam, self.view]
        self.n_cams, self.n_views = uv_all.shape[:2]
        self.mask = np.r_[free_cam.ravel(), np.ones(self.n_views * 3, bool)]
        self.nfev = 0

    def unpack(self, full):
        cams = full[: self.n_cams * _N_CAM].reshape(self.n_cams, _N_CAM)
        return cams, full[self.n_cams * _N_CAM:].reshape(self.n_views, 3)

    def evaluate(self, full, rows, jacobian=True):
        cams, pts = self.unpack(full)
        c, p = self.cam[rows], self.view[rows]
        uv, jc, jp = project_by_camera(cams, c, pts[p], jacobian)
        return (uv - self.uv[rows]).ravel(), jc, jp

    def _columns(self, rows):
        cols_cam = np.arange(_N_CAM)[None] + self.cam[rows, None] * _N_CAM
        cols_pt = self.n_cams * _N_CAM + np.arange(3)[None] + self.view[rows, None] * 3
        return np.hstack([cols_cam, cols_pt])


def refine_extrinsics(cameras: list[PinholeCamera], uv: np.ndarray, *, reference: int = 0,
                      opts: Options | None = None):
    """Refine the poses of ``cameras`` from corresponding points.

    Parameters
    ----------
    cameras : list of PinholeCamera (at most 5 distortion coefficients)
    uv : ndarray, shape (n_cams, n_points, 2)
        Pixel observations, NaN where a camera does not see a point; a point is one marker in
        one frame.
    reference : int
        The camera that stays where it is.

    Returns
    -------
    (cameras, errors)
        Refined cameras; reprojection errors (n_cams, n_points), NaN where unseen.
    """
    opts = opts or Options()
    uv = _points(cameras, uv)
    seen = np.isfinite(uv[..., 0])
    uv = np.where((seen.sum(0) >= 2)[None, :, None], uv, np.nan)  # 2+ views to constrain
    lonely = [cameras[c].name for c in range(len(cameras))
              if np.isfinite(uv[c, :, 0]).sum() < 6]
    if lonely:
        raise VideoTrackError(f"camera(s) {', '.join(lonely)} share fewer than 6 points with "
                              "the others", field="p2d")
    X = triangulate(cameras, uv)
    params = [params_from_camera(c) for c in cameras]
    full_cams = np.array([np.r_[r, t, i] for r, t, i in params])
    free = np.zeros_like(full_cams, bool)
    free[:, :6] = True
    free[reference, :6] = False
    problem = PointProblem(uv, free)
    start = np.r_[full_cams.ravel(), np.nan_to_num(X).ravel()]
    full, err, _ = adjust_iterative(problem, start, opts, np.random.default_rng(opts.seed))
    cams, _ = problem.unpack(full)
    out = [camera_from_params(c.name, cams[i, :3], cams[i, 3:6], cams[i, 6:], c.image_size)
           for i, c in enumerate(cameras)]
    # the gauge: the scene can shrink or grow about the reference camera; keep the size of
    # the rig as it was before
    before = np.array([c.centre for c in cameras])
    after = np.array([c.centre for c in out])
    ref = after[reference]
    scale = (np.linalg.norm(before - before[reference], axis=1).sum()
             / np.linalg.norm(after - ref, axis=1).sum())
    out = [PinholeCamera(c.name, c.K, c.dist[:5], R=c.R, t=-c.R @ (ref + scale * (a - ref)),
                         size=c.image_size) for c, a in zip(out, after, strict=True)]
    errors = np.full(uv.shape[:2], np.nan)
    errors[problem.cam, problem.view] = err
    return out, errors
