"""Refining camera poses from the animal: corresponding 2D points across views (tracked
markers or keypoints, as Anipose's "animal calibration" and DeepFly3D do).

The intrinsics stay; the poses of all cameras but the reference, and the 3D points, are
adjusted jointly with the same iterative, robust bundle adjustment as the board calibration
(:func:`videotrack.calibration.bundle.adjust_iterative`). Without a board the points fix the
rig only up to a similarity, and a small scene seen from afar lets rotations trade against the
points' depth: priors hold each moving camera's centre and orientation near where they were
(the rig keeps its size), and a change past the tolerance is refused unless the rig is freed.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import coo_matrix

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

__all__ = ["RigChange", "refine_extrinsics", "triangulated_errors"]


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

    def __init__(self, uv_all: np.ndarray, free_cam: np.ndarray,
                 before: list | None = None, sd: tuple[float, float] = (np.inf, np.inf)
                 ) -> None:
        self.cam, self.view = np.nonzero(np.isfinite(uv_all[..., 0]))  # view = point index
        self.point = self.view
        self.uv = uv_all[self.cam, self.view]
        self.n_cams, self.n_views = uv_all.shape[:2]
        self.mask = np.r_[free_cam.ravel(), np.ones(self.n_views * 3, bool)]
        self.nfev = 0
        # The rig's gauge and its plausible moves: each moving camera's centre and
        # orientation held near where they were (``before``: the cameras; ``sd``: the
        # centre's sd in length units, the orientation's in radians). Without it the points
        # fix the cameras only up to a similarity, and a small scene seen from afar lets
        # rotations trade against the points' depth.
        self.held = [c for c in range(self.n_cams) if free_cam[c, :6].any()] \
            if before is not None and np.isfinite(sd).all() else []
        if self.held:
            self.centres = np.array([c.centre for c in before])
            self.rotations = np.array([c.R for c in before])
            self.sd = sd

    def _prior_of(self, c: int, q: np.ndarray) -> np.ndarray:
        """Camera ``c``'s prior residuals (centre, rotation) at its parameters ``q``."""
        R = cv2.Rodrigues(q[:3])[0]
        turn = cv2.Rodrigues(R @ self.rotations[c].T)[0].ravel()
        return np.r_[(-R.T @ q[3:6] - self.centres[c]) / self.sd[0], turn / self.sd[1]]

    def prior(self, full, jacobian=True):
        if not self.held:
            return None
        cams, _ = self.unpack(full)
        res = np.concatenate([self._prior_of(c, cams[c]) for c in self.held])
        if not jacobian:
            return res, None
        rows, cols, vals = [], [], []
        col_of = np.cumsum(self.mask) - 1
        for k, c in enumerate(self.held):  # central differences: 6 parameters a camera
            for j in range(6):
                if not self.mask[c * _N_CAM + j]:
                    continue
                h = 1e-6 * max(1.0, abs(cams[c, j]))
                up, down = cams[c].copy(), cams[c].copy()
                up[j] += h
                down[j] -= h
                d = (self._prior_of(c, up) - self._prior_of(c, down)) / (2 * h)
                rows.extend(range(6 * k, 6 * k + 6))
                cols.extend([col_of[c * _N_CAM + j]] * 6)
                vals.extend(d)
        J = coo_matrix((vals, (rows, cols)), shape=(res.size, int(self.mask.sum()))).tocsr()
        return res, J

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


#: The rig's plausible moves between the board recording and the session, the sd of the
#: priors that hold each moving camera: its centre by this share of the rig's median
#: baseline (the rig keeps its size), its orientation by RIG_TURN_SD_DEG (a bumped mount
#: turns; a camera's place is what the points determine least). On the sleap-anipose
#: mouse rig the animal's keypoints pulled a free rig's baselines by up to 66 %
#: (docs/benchmarks.md, "Refining a rig from the animal").
RIG_CENTRE_SD = 0.002
RIG_TURN_SD_DEG = 2.0
#: A refinement that changes a baseline by more than this share, or turns a camera by more
#: than RIG_TURN_TOLERANCE_DEG, is refused unless the rig is freed (``free_rig``).
RIG_BASELINE_TOLERANCE = 0.01
RIG_TURN_TOLERANCE_DEG = 5.0


@dataclass(frozen=True)
class RigChange:
    """How a refinement changed the rig: each camera's centre move (length units) and turn
    (degrees), each baseline (camera, camera, before, after), and the scale (the mean
    baseline after / before)."""

    moved: dict[str, float]
    turned_deg: dict[str, float]
    baselines: list[tuple[str, str, float, float]]
    scale: float

    @classmethod
    def between(cls, before: list, after: list) -> RigChange:
        moved = {a.name: float(np.linalg.norm(a.centre - b.centre))
                 for a, b in zip(before, after, strict=True)}
        turned = {a.name: float(np.degrees(np.arccos(np.clip(
            (np.trace(a.R @ b.R.T) - 1.0) / 2.0, -1.0, 1.0))))
            for a, b in zip(before, after, strict=True)}
        pairs = [(i, j) for i in range(len(before)) for j in range(i + 1, len(before))]
        lines = [(before[i].name, before[j].name,
                  float(np.linalg.norm(before[i].centre - before[j].centre)),
                  float(np.linalg.norm(after[i].centre - after[j].centre))) for i, j in pairs]
        scale = float(np.mean([b for *_, b in lines]) / np.mean([a for _, _, a, _ in lines])) \
            if lines else 1.0
        return cls(moved, turned, lines, scale)

    def worst_baseline(self) -> tuple[str, str, float, float, float]:
        """(camera, camera, before, after, relative change) of the baseline that changed most."""
        a, b, x, y = max(self.baselines, key=lambda r: abs(r[3] / r[2] - 1.0))
        return a, b, x, y, y / x - 1.0

    def refused(self) -> str | None:
        """Why the change is past the documented tolerance, or None."""
        if self.baselines:
            a, b, x, y, rel = self.worst_baseline()
            if abs(rel) > RIG_BASELINE_TOLERANCE:
                return (f"the baseline {a}-{b} would change by {100 * rel:+.1f} % ({x:.4g} -> "
                        f"{y:.4g}; tolerance {100 * RIG_BASELINE_TOLERANCE:.0f} %)")
        name = max(self.turned_deg, key=self.turned_deg.get)
        if self.turned_deg[name] > RIG_TURN_TOLERANCE_DEG:
            return (f"camera {name} would turn by {self.turned_deg[name]:.1f}° (tolerance "
                    f"{RIG_TURN_TOLERANCE_DEG:.0f}°)")
        return None

    def lines(self) -> list[str]:
        """The change as report lines: each camera's move and turn, each baseline's change."""
        out = [f"  {name}: moved {self.moved[name]:.4g}, turned {self.turned_deg[name]:.2f}°"
               for name in self.moved]
        out += [f"  baseline {a}-{b}: {x:.5g} -> {y:.5g} ({100 * (y / x - 1):+.2f} %)"
                for a, b, x, y in self.baselines]
        out.append(f"  scale: x{self.scale:.4f}")
        return out


def refine_extrinsics(cameras: list[PinholeCamera], uv: np.ndarray, *, reference: int = 0,
                      opts: Options | None = None, free_rig: bool = False):
    """Refine the poses of ``cameras`` from corresponding points.

    Parameters
    ----------
    cameras : list of PinholeCamera (at most 5 distortion coefficients)
    uv : ndarray, shape (n_cams, n_points, 2)
        Pixel observations, NaN where a camera does not see a point; a point is one marker in
        one frame.
    reference : int
        The camera that stays where it is.
    free_rig : bool
        Without the priors that hold each camera near where it was (:data:`RIG_CENTRE_SD`,
        :data:`RIG_TURN_SD_DEG`), the rig's size restored from the centres' spread after,
        and no tolerance: a rig that really moved. Else a change past the tolerance is
        refused (:meth:`RigChange.refused`).

    Returns
    -------
    (cameras, errors, change)
        Refined cameras; reprojection errors (n_cams, n_points), NaN where unseen; the
        :class:`RigChange`.
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
    centres = np.array([c.centre for c in cameras])
    spans = [np.linalg.norm(a - b) for i, a in enumerate(centres) for b in centres[i + 1:]]
    sd = (np.inf, np.inf) if free_rig else (RIG_CENTRE_SD * float(np.median(spans)),
                                            np.radians(RIG_TURN_SD_DEG))
    problem = PointProblem(uv, free, cameras, sd)
    start = np.r_[full_cams.ravel(), np.nan_to_num(X).ravel()]
    full, err, _ = adjust_iterative(problem, start, opts, np.random.default_rng(opts.seed))
    cams, _ = problem.unpack(full)
    out = [camera_from_params(c.name, cams[i, :3], cams[i, 3:6], cams[i, 6:], c.image_size)
           for i, c in enumerate(cameras)]
    if free_rig:
        # the gauge: the scene can shrink or grow about the reference camera; keep the size
        # of the rig as it was before
        after = np.array([c.centre for c in out])
        ref = after[reference]
        scale = (np.linalg.norm(centres - centres[reference], axis=1).sum()
                 / np.linalg.norm(after - ref, axis=1).sum())
        out = [PinholeCamera(c.name, c.K, c.dist[:5], R=c.R, t=-c.R @ (ref + scale * (a - ref)),
                             size=c.image_size) for c, a in zip(out, after, strict=True)]
    change = RigChange.between(cameras, out)
    why = None if free_rig else change.refused()
    if why:
        raise VideoTrackError(f"refinement refused: {why}; the points do not hold the rig "
                              "(keypoints of a body are not exact correspondences). Keep the "
                              "calibration, or accept the change with --free-rig",
                              field="--refine-points")
    errors = np.full(uv.shape[:2], np.nan)
    errors[problem.cam, problem.view] = err
    return out, errors, change
