"""Triangulation of labelled 2D keypoints seen by several calibrated cameras.

Three backends, each returning a :class:`Triangulation` (xyz, reprojection error, number of
cameras and score per point, as Anipose's ``pose-3d`` files hold them):

- :func:`triangulate_linear` — the homogeneous DLT (SVD) over every camera that sees a
  point, each camera's two rows weighted by the keypoint's confidence; pinhole points are
  undistorted with ``cv2.undistortPoints`` first, as aniposelib does. With unit weights it is
  aniposelib's ``CameraGroup.triangulate``.
- :func:`triangulate_ransac` — aniposelib's ``triangulate_ransac``: the camera subset with
  the lowest mean reprojection error wins (the search stops at one below ``good_px``),
  optionally refitted over every camera within ``inlier_px`` of it.
- :func:`triangulate_optim` — the spatiotemporal optimisation of the Anipose paper (Karashchuk
  et al. 2021, Methods 4.5): robust reprojection + n-th derivative smoothness + limb lengths,
  a sparse nonlinear least-squares problem (``scipy.optimize.least_squares``, analytic sparse
  Jacobian) solved over chunks of frames with overlap, started from the linear or RANSAC result.

Arrays: ``xy`` (n_cams, n_frames, n_points, 2) pixels, NaN where missing; ``score``
(n_cams, n_frames, n_points) confidences (missing or ``< min_score``: not used). The per-point
loops are numba kernels (:mod:`kinematics._kernels.triangulation`); the ``_*_numpy``
functions here are their readable twins, which the tests compare them against.
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from kinematics._kernels import triangulation as _k
from kinematics.cameras import Camera, OrthographicCamera, PinholeCamera, pack_cameras
from kinematics.errors import KinematicsError

__all__ = [
    "LOSSES",
    "Triangulation",
    "triangulate_linear",
    "triangulate_optim",
    "triangulate_ransac",
]

#: Robust losses of the reprojection term of :func:`triangulate_optim`.
LOSSES = {"linear": _k.LOSS_LINEAR, "soft_l1": _k.LOSS_SOFT_L1, "huber": _k.LOSS_HUBER}


@dataclass(frozen=True, eq=False)
class Triangulation:
    """3D points and how well they are supported.

    Attributes
    ----------
    xyz : (n_frames, n_points, 3) world coordinates, NaN where not triangulated
    error : (n_frames, n_points) mean reprojection error in px over the cameras used
    ncams : (n_frames, n_points) int, number of cameras used
    score : (n_frames, n_points) lowest confidence among the cameras used (Anipose's score)
    used : (n_cams, n_frames, n_points) bool, the keypoints the point was solved from
    """

    xyz: np.ndarray
    error: np.ndarray
    ncams: np.ndarray
    score: np.ndarray
    used: np.ndarray


# --- inputs ---------------------------------------------------------------------------------


def _camera_list(cameras) -> list[Camera]:
    cams = list(cameras.values()) if isinstance(cameras, Mapping) else list(cameras)
    if len(cams) < 2:
        raise KinematicsError(f"triangulation needs at least two cameras, got {len(cams)}",
                              field="cameras")
    for c, cam in enumerate(cams):
        if not isinstance(cam, OrthographicCamera | PinholeCamera):
            raise KinematicsError(f"not a camera: {cam!r}", field=f"cameras[{c}]")
    return cams


def _inputs(cameras, xy, score, min_score: float, weighted: bool):
    """Cameras, keypoints (C, F, J, 2), scores (C, F, J) and weights (0 = not used)."""
    cams = _camera_list(cameras)
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 4 or xy.shape[0] != len(cams) or xy.shape[-1] != 2:
        raise KinematicsError(f"expected keypoints of shape ({len(cams)} cameras, frames, "
                              f"points, 2), got {xy.shape}", field="xy")
    if score is None:
        score = np.ones(xy.shape[:3])
    score = np.asarray(score, dtype=np.float64)
    if score.shape != xy.shape[:3]:
        raise KinematicsError(f"expected scores of shape {xy.shape[:3]}, got {score.shape}",
                              field="score")
    finite = np.isfinite(xy)  # (.all(axis=-1) reduces a length-2 axis 15x slower)
    present = finite[..., 0] & finite[..., 1] & np.isfinite(score) & (score > 0.0)
    present &= score >= min_score
    w = np.where(present, score if weighted else 1.0, 0.0)
    # contiguous copies: numba compiles (and caches) one kernel per array layout
    return cams, np.ascontiguousarray(xy), np.where(present, score, np.nan), w


def _matrices(cams: Sequence[Camera]) -> np.ndarray:
    """Linear camera matrices (C, 3, 4) of the kernels: ``[R | t]`` for pinhole cameras,
    ``[P; 0 0 0 1]`` for orthographic ones."""
    mats = np.zeros((len(cams), 3, 4))
    for c, cam in enumerate(cams):
        if isinstance(cam, OrthographicCamera):
            mats[c, :2], mats[c, 2, 3] = cam.P, 1.0
        else:
            mats[c, :, :3], mats[c, :, 3] = cam.R, cam.t
    return mats


def _linearise_numpy(cams: Sequence[Camera], xy: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Twin of the kernels' ``linearise``: points (C, N, 2) -> undistorted normalised
    coordinates by ``cv2.undistortPoints`` (pinhole; what aniposelib triangulates) or the
    pixels (orthographic), NaN where ``w`` is 0."""
    lin = np.full(xy.shape, np.nan)
    for c, cam in enumerate(cams):
        ok = w[c] > 0.0
        if isinstance(cam, OrthographicCamera):
            lin[c, ok] = xy[c, ok]
        elif ok.any():
            pts = np.ascontiguousarray(xy[c, ok].reshape(-1, 1, 2))
            lin[c, ok] = cv2.undistortPoints(pts, cam.K, cam.dist).reshape(-1, 2)
    return lin


def _planar(xy: np.ndarray, w: np.ndarray):
    """(C, F, J, 2) pixels and (C, F, J) weights -> u, v, w, each (C, F·J) and contiguous:
    the kernels loop over points in SIMD lanes, which needs unit strides."""
    c = xy.shape[0]
    return (np.ascontiguousarray(xy[..., 0]).reshape(c, -1),
            np.ascontiguousarray(xy[..., 1]).reshape(c, -1), w.reshape(c, -1))


def _mean_errors_numpy(cams: Sequence[Camera], pts, px, w) -> tuple[np.ndarray, np.ndarray]:
    """Twin of the kernels' ``mean_errors``: mean pixel distance of ``Camera.project`` of
    ``pts`` (N, 3) from ``px`` (C, N, 2) over the cameras where ``w`` (C, N) > 0, and their
    number."""
    dist = np.stack([np.linalg.norm(cam.project(pts) - px[c], axis=-1)
                     for c, cam in enumerate(cams)])
    ncams = (w > 0).sum(axis=0)
    with np.errstate(invalid="ignore"):
        return np.where(w > 0, dist, 0.0).sum(axis=0) / ncams, ncams


def _result(xyz, err, used, score, shape) -> Triangulation:
    f, j = shape
    used = used.reshape(used.shape[0], f, j)
    ncams = used.sum(axis=0)
    low = np.where(used, score, np.inf).min(axis=0)
    low[~np.isfinite(low)] = np.nan
    return Triangulation(xyz.reshape(f, j, 3), err.reshape(f, j), ncams.astype(np.int64),
                         low, used)


# --- linear ---------------------------------------------------------------------------------


def triangulate_linear(cameras, xy, score=None, *, min_score: float = 0.0,
                       weighted: bool = True) -> Triangulation:
    """Linear (DLT) triangulation of every point over every camera that sees it.

    Parameters
    ----------
    cameras : sequence or mapping of Camera, one per first axis of ``xy``
    xy : (n_cams, n_frames, n_points, 2) pixels, NaN where missing
    score : (n_cams, n_frames, n_points), optional confidences (default 1)
    min_score : keypoints with a lower score are not used
    weighted : weight each camera's equations by the keypoint's score (False: aniposelib's
        unweighted ``CameraGroup.triangulate``)

    Returns
    -------
    Triangulation
        NaN where fewer than two cameras see a point.
    """
    cams, xy, score, w = _inputs(cameras, xy, score, min_score, weighted)
    _, f, j, _ = xy.shape
    u, v, w = _planar(xy, w)
    n = u.shape[1]
    xyz, err, ncams = np.empty((n, 3)), np.empty(n), np.empty(n, np.int64)
    _k.linear_kernel(_matrices(cams), u, v, w, *pack_cameras(cams), xyz, err, ncams)
    return _result(xyz, err, (w > 0) & (ncams >= 2)[None], score, (f, j))


def _dlt_numpy(mats, lin, w) -> np.ndarray:
    """Twin of the linear kernel: (C, N, 2) linearised points -> (N, 3)."""
    out = np.full((lin.shape[1], 3), np.nan)
    for n in range(lin.shape[1]):
        cams = np.flatnonzero(w[:, n] > 0)
        if len(cams) < 2:
            continue
        rows = [w[c, n] * (lin[c, n, i] * mats[c, 2] - mats[c, i]) for c in cams for i in (0, 1)]
        h = np.linalg.svd(np.array(rows))[2][-1]
        out[n] = h[:3] / h[3] if h[3] != 0 else np.nan
    return out


# --- RANSAC ---------------------------------------------------------------------------------


def triangulate_ransac(cameras, xy, score=None, *, min_score: float = 0.0,
                       weighted: bool = True, min_cams: int = 2, good_px: float = 0.5,
                       max_px: float = 200.0, inlier_px: float = 0.0) -> Triangulation:
    """Triangulation over the best subset of cameras (aniposelib's ``triangulate_ransac``).

    Parameters
    ----------
    cameras, xy, score, min_score, weighted : as :func:`triangulate_linear`
    min_cams : smallest subset tried (all cameras that see a point when fewer do)
    good_px : the search stops at the first subset with a mean reprojection error below it
    max_px : a point whose best subset reprojects worse is not triangulated (NaN)
    inlier_px : if > 0, every camera within this many px of the winning point joins it and
        the point is solved again over these inliers

    Returns
    -------
    Triangulation
        ``used`` marks the cameras of each point's subset.
    """
    if isinstance(min_cams, bool) or not isinstance(min_cams, int | np.integer) or min_cams < 2:
        raise KinematicsError(f"expected an integer >= 2, got {min_cams!r}", field="min_cams")
    for name, value in (("good_px", good_px), ("max_px", max_px), ("inlier_px", inlier_px)):
        if not np.isfinite(value) or value < 0:
            raise KinematicsError(f"expected a number >= 0, got {value!r}", field=name)
    cams, xy, score, w = _inputs(cameras, xy, score, min_score, weighted)
    if len(cams) > 16:
        raise KinematicsError("RANSAC tries every subset of cameras: at most 16 cameras",
                              field="cameras")
    c, f, j, _ = xy.shape
    u, v, w = _planar(xy, w)
    n = u.shape[1]
    xyz, err, used = np.empty((n, 3)), np.empty(n), np.zeros((c, n), bool)
    _k.ransac_kernel(_matrices(cams), u, v, w, pack_cameras(cams), int(min_cams),
                     float(good_px), float(max_px), float(inlier_px), xyz, err, used)
    return _result(xyz, err, used, score, (f, j))


def _mean_error_numpy(cams, px, x, subset) -> float:
    return float(np.mean([np.linalg.norm(cams[c].project(x) - px[c]) for c in subset]))


def _ransac_numpy(cams, mats, lin, w, px, min_cams, good_px, max_px, inlier_px):
    """Twin of the RANSAC kernel, written as aniposelib's loop over ``itertools.product``."""
    n = lin.shape[1]
    xyz, err = np.full((n, 3), np.nan), np.full(n, np.nan)
    used = np.zeros((len(cams), n), bool)
    for p in range(n):
        avail = np.flatnonzero(w[:, p] > 0)
        best, pick = max_px, None
        for picked in itertools.product(*[(c, None) for c in avail]):
            subset = [c for c in picked if c is not None]
            if len(subset) < 2 or (len(subset) < min_cams and len(subset) != len(avail)):
                continue
            mask = np.isin(np.arange(len(cams)), subset)[:, None]
            x = _dlt_numpy(mats, lin[:, p:p + 1], w[:, p:p + 1] * mask)[0]
            e = _mean_error_numpy(cams, px[:, p], x, subset)
            if e < best:
                best, pick, xyz[p] = e, subset, x
                if best < good_px:
                    break
        if pick is None:
            continue
        err[p], used[pick, p] = best, True
        if inlier_px > 0:
            for c in avail:
                if np.linalg.norm(cams[c].project(xyz[p]) - px[c, p]) < inlier_px:
                    used[c, p] = True
            subset = np.flatnonzero(used[:, p])
            x = _dlt_numpy(mats, lin[:, p:p + 1], w[:, p:p + 1] * used[:, p:p + 1])[0]
            e = _mean_error_numpy(cams, px[:, p], x, subset)
            if np.isfinite(e):
                xyz[p], err[p] = x, e
    return xyz, err, used


# --- spatiotemporal optimisation ------------------------------------------------------------


def _residuals_numpy(cams, cam, point, uv, weight, xyz, scale, loss, h=1e-6):
    """Twin of ``reprojection_residuals``: robust residuals from ``Camera.project`` and their
    Jacobian by central differences."""
    def res(pts):
        proj = np.array([cams[c].project(pts[p]) for c, p in zip(cam, point, strict=True)])
        r = (weight[:, None] * (proj - uv)).ravel()
        a = np.abs(r)
        if loss == "soft_l1":
            return np.sign(r) * 2 * scale * (np.sqrt(1 + a / scale) - 1)
        if loss == "huber":
            return np.where(a <= scale, r, np.sign(r) * scale * (2 * np.sqrt(a / scale) - 1))
        return r

    jac = np.empty((2 * len(cam), 3))
    for k in range(3):
        step = np.zeros_like(xyz)
        step[:, k] = h * np.maximum(1.0, np.abs(xyz[:, k]))
        jac[:, k] = ((res(xyz + step) - res(xyz - step))
                     / (2 * np.repeat(step[point, k], 2)))
    return res(xyz), jac


def _difference_matrix(n_frames: int, n_points: int, order: int):
    """The n-th forward difference along frames of (n_frames, n_points, 3) flattened, a
    sparse matrix."""
    import scipy.sparse

    d = scipy.sparse.identity(n_frames, format="csr")
    for _ in range(order):
        d = (d[1:] - d[:-1]).tocsr()
    return scipy.sparse.kron(d, scipy.sparse.identity(n_points * 3), format="csr")


class _Problem:
    """One chunk of frames as a sparse least-squares problem over
    x = [points (F, J, 3) | limb lengths (if free)]; ``fun`` and ``jac`` share one
    evaluation (least_squares asks for both at the same x)."""

    def __init__(self, packed, xy, w, limbs, lengths, free_lengths, smooth, n_deriv,
                 limb_weight, loss, loss_px):
        _, f, j, _ = xy.shape
        self.packed, self.shape = packed, (f, j)
        self.cam, frame, joint = np.nonzero(w > 0)
        self.point = (frame * j + joint).astype(np.int64)
        self.uv = np.ascontiguousarray(xy[self.cam, frame, joint])
        self.weight = w[self.cam, frame, joint]
        self.cam = self.cam.astype(np.int64)
        self.limbs, self.lengths, self.free = limbs, lengths, free_lengths
        self.limb_weight, self.loss, self.loss_px = limb_weight, loss, loss_px
        self.n3 = f * j * 3
        self.smooth = smooth * _difference_matrix(f, j, n_deriv) if f > n_deriv else None
        self._x = None
        self._structure()

    def _structure(self):
        """Rows and columns of every Jacobian entry, in the order ``_evaluate`` fills them,
        and the permutation to CSR order (no entry repeats)."""
        import scipy.sparse

        m, f = len(self.cam), self.shape[0]
        rows = [np.repeat(np.arange(2 * m), 3)]
        cols = [(3 * np.repeat(self.point, 2)[:, None] + np.arange(3)).ravel()]
        start = 2 * m
        if self.smooth is not None:
            s = self.smooth.tocoo()
            rows.append(s.row + start)
            cols.append(s.col)
            start += s.shape[0]
        self.smooth_data = None if self.smooth is None else self.smooth.tocoo().data
        n_limb = len(self.limbs) * f
        if n_limb:
            lr = start + np.arange(n_limb)
            frames = np.tile(np.arange(f), len(self.limbs))
            a = np.repeat(self.limbs[:, 0], f)
            b = np.repeat(self.limbs[:, 1], f)
            pa = 3 * (frames * self.shape[1] + a)
            pb = 3 * (frames * self.shape[1] + b)
            rows.append(np.repeat(lr, 6))
            cols.append(np.stack([pa, pa + 1, pa + 2, pb, pb + 1, pb + 2], 1).ravel())
            if self.free:
                rows.append(lr)
                cols.append(self.n3 + np.repeat(np.arange(len(self.limbs)), f))
            self.limb_pa, self.limb_pb = pa, pb
        self.n_rows = start + n_limb
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        n_par = self.n3 + (len(self.limbs) if self.free else 0)
        order = scipy.sparse.csr_matrix((np.arange(1, len(rows) + 1), (rows, cols)),
                                        shape=(self.n_rows, n_par))
        self.perm = order.data.astype(np.int64) - 1
        self.jac_matrix = order.astype(np.float64)

    def _evaluate(self, x):
        if self._x is not None and np.array_equal(x, self._x):
            return
        pts = x[: self.n3].reshape(-1, 3)
        m = len(self.cam)
        res = np.empty(2 * m)
        jr = np.empty((2 * m, 3))
        _k.reprojection_residuals(*self.packed, self.cam, self.point, self.uv, self.weight,
                                  pts, self.loss_px, self.loss, res, jr)
        parts, vals = [res], [jr.ravel()]
        if self.smooth is not None:
            parts.append(self.smooth @ x[: self.n3])
            vals.append(self.smooth_data)
        if len(self.limbs):
            lengths = x[self.n3:] if self.free else self.lengths
            f = self.shape[0]
            big_l = np.repeat(lengths, f)
            d = pts[self.limb_pa // 3] - pts[self.limb_pb // 3]
            dist = np.linalg.norm(d, axis=1)
            g = self.limb_weight * 100.0 / big_l
            parts.append(g * (dist - big_l))
            unit = np.divide(d, dist[:, None], out=np.zeros_like(d), where=dist[:, None] > 0)
            vals.append(np.concatenate([g[:, None] * unit, -g[:, None] * unit], 1).ravel())
            if self.free:
                vals.append(-self.limb_weight * 100.0 * dist / big_l ** 2)
        self._res = np.concatenate(parts)
        self.jac_matrix.data[:] = np.concatenate(vals)[self.perm]
        self._x = x.copy()

    def fun(self, x):
        self._evaluate(x)
        return self._res

    def jac(self, x):
        self._evaluate(x)
        return self.jac_matrix


def _fill_gaps(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation over frames of every coordinate (held at the ends); points never
    triangulated become 0. Returns the filled copy and (n_points,) 'ever seen'."""
    out = xyz.copy()
    frames = np.arange(len(xyz))
    seen = np.isfinite(xyz).all(axis=2).any(axis=0)
    for jj in range(xyz.shape[1]):
        ok = np.isfinite(xyz[:, jj]).all(axis=1)
        for k in range(3):
            out[:, jj, k] = np.interp(frames, frames[ok], xyz[ok, jj, k]) if ok.any() else 0.0
    return out, seen


def _limb_array(limbs, n_points: int) -> np.ndarray:
    arr = np.asarray(limbs if limbs is not None else [], dtype=np.int64).reshape(-1, 2)
    if arr.size and (arr.min() < 0 or arr.max() >= n_points or np.any(arr[:, 0] == arr[:, 1])):
        raise KinematicsError(f"limbs must be pairs of two different point indices in "
                              f"[0, {n_points}), got {arr.tolist()}", field="limbs")
    return arr


def triangulate_optim(cameras, xy, score=None, *, min_score: float = 0.0,
                      weighted: bool = True, init: str = "linear", limbs=(),
                      limb_lengths=None, smooth: float = 2.0, n_deriv: int = 1,
                      limb_weight: float = 2.0, loss: str = "soft_l1", loss_px: float = 15.0,
                      chunk: int = 300, overlap: int = 30, ftol: float = 1e-4,
                      progress: Callable[[int, int], None] | None = None,
                      **init_options) -> Triangulation:
    """Spatiotemporally constrained triangulation of a whole trial (Anipose's ``optim``).

    Minimises, over the 3D points of all frames (and the limb lengths unless given),
    ``sum robust(w * reprojection)² + sum (smooth · γ · Δⁿ p)² + sum (limb_weight · 100 ·
    (|p_a - p_b| - d) / d)²`` with ``γ`` = 1 / mean |Δp| of the median-filtered initial
    points (the paper's scale-free smoothness; the residuals of aniposelib's ``optim_points``,
    its robust transform applied to each pixel coordinate).

    Parameters
    ----------
    cameras, xy, score, min_score : as :func:`triangulate_linear`
    weighted : weight each reprojection residual by the keypoint's score (and the linear
        start's equations)
    init : "linear" or "ransac", the starting points (``init_options`` go to it)
    limbs : pairs (a, b) of point indices whose distance stays constant (the chain's segments)
    limb_lengths : their lengths in world units; None: unknown (free, one per limb and chunk,
        started at the median over the trial)
    smooth : β_time, weight of the smoothness term; n_deriv : order of the derivative
    limb_weight : α_limb; loss, loss_px : robust loss of the reprojection term (LOSSES)
        and its scale in px
    chunk, overlap : frames solved together, and frames of context on each side
    ftol : least_squares' relative cost tolerance
    progress : called with (frames done, n_frames) after each chunk

    Returns
    -------
    Triangulation
        Every keypoint present is used; points never triangulated in the trial stay NaN.
    """
    from scipy.ndimage import median_filter
    from scipy.optimize import least_squares

    if loss not in LOSSES:
        raise KinematicsError(f"expected one of {', '.join(LOSSES)}, got {loss!r}",
                              field="loss")
    if init not in ("linear", "ransac"):
        raise KinematicsError(f"expected 'linear' or 'ransac', got {init!r}", field="init")
    for name, value, low in (("n_deriv", n_deriv, 1), ("chunk", chunk, 1), ("overlap", overlap, 0)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
            raise KinematicsError(f"expected an integer >= {low}, got {value!r}", field=name)
    for name, value in (("smooth", smooth), ("limb_weight", limb_weight)):
        if not np.isfinite(value) or value < 0:
            raise KinematicsError(f"expected a number >= 0, got {value!r}", field=name)
    if not np.isfinite(loss_px) or loss_px <= 0:
        raise KinematicsError(f"expected a number > 0, got {loss_px!r}", field="loss_px")
    cams, xy_arr, score_arr, w = _inputs(cameras, xy, score, min_score, weighted)
    c, f, j, _ = xy_arr.shape
    limbs = _limb_array(limbs, j)
    start = (triangulate_ransac if init == "ransac" else triangulate_linear)(
        cams, xy, score, min_score=min_score, weighted=weighted, **init_options)
    if init == "ransac":  # RANSAC's outliers stay out of the optimisation too
        w = np.where(start.used, w, 0.0)
    x0, seen = _fill_gaps(start.xyz)
    step = np.abs(np.diff(median_filter(x0, size=(7, 1, 1), mode="reflect"), axis=0))
    gamma = 1.0 / step.mean() if step.size and step.mean() > 0 else 1.0
    lengths, free = _initial_lengths(limbs, x0, limb_lengths)
    packed = pack_cameras(cams)
    out = x0.copy()
    for s in range(0, f, chunk):
        e = min(f, s + chunk)
        a, b = max(0, s - overlap), min(f, e + overlap)
        problem = _Problem(packed, xy_arr[:, a:b], w[:, a:b], limbs, lengths, free,
                           smooth * gamma, n_deriv, limb_weight, LOSSES[loss], loss_px)
        x_start = np.concatenate([x0[a:b].ravel(), lengths if free else []])
        with _one_blas_thread():
            sol = least_squares(problem.fun, x_start, jac=problem.jac, method="trf",
                                ftol=ftol, tr_solver="lsmr")
        out[s:e] = sol.x[: problem.n3].reshape(b - a, j, 3)[s - a:e - a]
        if progress is not None:
            progress(e, f)
    out[:, ~seen] = np.nan
    used = w > 0
    n = f * j
    err, ncams = np.empty(n), np.empty(n, np.int64)
    u, v, _ = _planar(xy_arr, w)
    _k.mean_errors(*packed, np.ascontiguousarray(out.reshape(-1, 3).T), u, v,
                   used.reshape(c, -1).astype(float), err, ncams)
    return _result(out, err, used, score_arr, (f, j))


def _one_blas_thread():
    """BLAS on one thread: LSMR's thousands of short vector products gain nothing from BLAS
    threads, which on a busy machine wait on each other (the optimisation ran 0.06-1.1 s
    instead of 0.06 s on 2 shared CPUs)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # a declared dependency, but the solve does not need it
        return contextlib.nullcontext()
    return threadpool_limits(1)


def _initial_lengths(limbs, x0, given) -> tuple[np.ndarray, bool]:
    """Limb lengths: the given ones (fixed), or the median over the trial (free)."""
    if given is not None:
        lengths = np.asarray(given, dtype=np.float64).ravel()
        if lengths.shape != (len(limbs),) or not np.all(np.isfinite(lengths) & (lengths > 0)):
            raise KinematicsError(f"expected {len(limbs)} positive lengths, one per limb, got "
                                  f"{np.asarray(given).tolist()}", field="limb_lengths")
        return lengths, False
    d = np.linalg.norm(x0[:, limbs[:, 0]] - x0[:, limbs[:, 1]], axis=2)
    lengths = np.median(d, axis=0) if len(d) else np.ones(len(limbs))
    fallback = np.median(lengths[lengths > 0]) if np.any(lengths > 0) else 1.0
    return np.where(lengths > 0, lengths, fallback), True
