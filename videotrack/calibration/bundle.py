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

The world frame is the reference camera's (x right, y down, z forward, mm).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.sparse import coo_matrix

from kinematics.calibration_math import (
    N_INTRINSICS,
    camera_from_params,
    compose,
    invert,
    mean_pose,
    params_from_camera,
    rodrigues,
)
from kinematics.cameras import PinholeCamera
from videotrack.calibration.detect import Corners
from videotrack.errors import VideoTrackError, VideoTrackWarning

__all__ = ["Calibration", "Options", "calibrate"]

#: Corners a view needs to enter a camera's intrinsics or a board pose.
MIN_VIEW_CORNERS = 6
#: Above this many free parameters the normal equations are solved by the Schur complement.
_DENSE_MAX = 400
_N_CAM = 6 + N_INTRINSICS  # rvec, t, fx, fy, cx, cy, k1, k2, p1, p2, k3


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


# --- step 3: bundle adjustment ----------------------------------------------------------------


def project_by_camera(cams: np.ndarray, cam: np.ndarray, xw: np.ndarray, jacobian: bool):
    """Project world points ``xw`` (k, 3) through the cameras ``cams[cam]`` (parameter rows,
    :data:`_N_CAM` each): pixels (k, 2) and, with ``jacobian``, d pixel / d camera parameters
    (k, 2, _N_CAM) and d pixel / d world point (k, 2, 3) (else None, None)."""
    uv = np.empty((len(cam), 2))
    jc = np.empty((len(cam), 2, _N_CAM)) if jacobian else None
    jx = np.empty((len(cam), 2, 3)) if jacobian else None
    for c in np.unique(cam):
        sel = np.flatnonzero(cam == c)
        q = cams[c]
        K = np.array([[q[6], 0.0, q[8]], [0.0, q[7], q[9]], [0.0, 0.0, 1.0]])
        pix, J = cv2.projectPoints(xw[sel], q[:3], q[3:6], K, q[10:])
        uv[sel] = pix.reshape(-1, 2)
        if jacobian:
            J = J.reshape(-1, 2, _N_CAM)
            jc[sel] = J
            jx[sel] = J[:, :, 3:6] @ cv2.Rodrigues(q[:3])[0]  # d x_cam / d x_world = R_c
    return uv, jc, jx


class Problem:
    """Residuals of all observed corners, and their analytic Jacobian, for packed camera and
    board-pose parameters.

    Projection and its derivatives with respect to the camera are ``cv2.projectPoints``'
    (the model :class:`~kinematics.cameras.PinholeCamera` implements); the derivatives with
    respect to the board pose follow by the chain rule. One call per camera, vectorised over
    its corners.
    """

    def __init__(self, uv_all: np.ndarray, object_points: np.ndarray, n_views: int,
                 free_cam: np.ndarray, free_view: np.ndarray) -> None:
        self.cam, self.view, self.point = np.nonzero(np.isfinite(uv_all[..., 0]))
        self.uv = uv_all[self.cam, self.view, self.point]
        self.obj = object_points
        self.n_cams = uv_all.shape[0]
        self.n_views = n_views
        # free parameters: a mask over [cams (n_cams, 15) | views (n_views, 6)]
        self.mask = np.r_[free_cam.ravel(), free_view.ravel()]
        self.nfev = 0

    def unpack(self, full: np.ndarray):
        cams = full[: self.n_cams * _N_CAM].reshape(self.n_cams, _N_CAM)
        views = full[self.n_cams * _N_CAM:].reshape(self.n_views, 6)
        return cams, views

    def evaluate(self, full: np.ndarray, rows: np.ndarray, jacobian: bool = True):
        """Residuals (2k,) of observations ``rows`` and, with ``jacobian``, the blocks
        d/d camera (k, 2, 15) and d/d board pose (k, 2, 6)."""
        cams, views = self.unpack(full)
        c, v, p = self.cam[rows], self.view[rows], self.point[rows]
        Rv = np.empty((self.n_views, 3, 3))
        dRv = np.empty((self.n_views, 3, 3, 3))
        for i in np.unique(v):
            R, dR = cv2.Rodrigues(views[i, :3])
            Rv[i], dRv[i] = R, dR.reshape(3, 3, 3)  # dRv[i, j] = dR / d r_j
        xb = self.obj[p]
        xw = np.einsum("nij,nj->ni", Rv[v], xb) + views[v, 3:]
        uv, jc, duv_dxw = project_by_camera(cams, c, xw, jacobian)
        res = uv - self.uv[rows]
        jv = None
        if jacobian:
            jv = np.empty((len(rows), 2, 6))
            dxw_drv = np.einsum("njab,nb->naj", dRv[v], xb)
            jv[:, :, :3] = duv_dxw @ dxw_drv
            jv[:, :, 3:] = duv_dxw
        return res.ravel(), jc, jv

    def residuals(self, full: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return self.evaluate(full, rows, jacobian=False)[0]

    def errors(self, full: np.ndarray) -> np.ndarray:
        r = self.residuals(full, np.arange(len(self.cam))).reshape(-1, 2)
        return np.hypot(r[:, 0], r[:, 1])

    def _columns(self, rows: np.ndarray) -> np.ndarray:
        cols_cam = np.arange(_N_CAM)[None] + self.cam[rows, None] * _N_CAM
        cols_view = self.n_cams * _N_CAM + np.arange(6)[None] + self.view[rows, None] * 6
        return np.hstack([cols_cam, cols_view])  # (k, 21) full indices per observation

    def jacobian(self, jc, jv, rows: np.ndarray):
        """The sparse Jacobian (2k, n_free) over the free parameters."""
        col_of = np.cumsum(self.mask) - 1  # full index -> free index
        cols = self._columns(rows)
        values = np.concatenate([jc, jv], axis=2)  # (k, 2, 21)
        free = self.mask[cols]  # (k, 21)
        obs, which = np.nonzero(free)
        r = np.concatenate([2 * obs, 2 * obs + 1])
        cc = np.concatenate([col_of[cols[obs, which]]] * 2)
        vals = np.concatenate([values[obs, 0, which], values[obs, 1, which]])
        return coo_matrix((vals, (r, cc)), shape=(2 * len(rows), int(self.mask.sum()))).tocsr()

    #: parameters per board pose (or 3D point, in a subclass): the blocks of the Schur step
    block = 6

    def _blocks(self, H):
        """(A dense, B sparse, C (n, b, b)) of the normal matrix: cameras | poses or points.
        The free poses (points) come last, each a diagonal block of size :attr:`block`."""
        m = int(self.mask[: self.n_cams * _N_CAM].sum())
        b = self.block
        rest = H[m:, m:].tocoo()
        n = (H.shape[0] - m) // b
        C = np.zeros((n, b, b))
        same = rest.row // b == rest.col // b
        C[rest.row[same] // b, rest.row[same] % b, rest.col[same] % b] = rest.data[same]
        return H[:m, :m].toarray(), H[:m, m:].tocsr(), C

    def solve(self, full: np.ndarray, rows: np.ndarray, f_scale: float,
              max_iter: int) -> np.ndarray:
        """Minimise the soft-L1 robust cost of observations ``rows`` (Levenberg-Marquardt on
        the normal equations, re-weighted each step).

        Why not ``scipy.optimize.least_squares``: its trust-region step takes an SVD of the
        dense Jacobian (0.3-0.9 s per step for 30 views of 3 cameras on a shared 2-core
        machine) or LSMR iterations in Python (7 s per start, stopping short of the
        minimum); the normal equations of a few hundred parameters solve in milliseconds.
        """
        mask = self.mask
        x = full.copy()

        def cost(r):  # soft-L1 on the pixel distance of each corner
            e2 = (r.reshape(-1, 2) ** 2).sum(1) / f_scale**2
            return float(np.sum(np.sqrt(1.0 + e2) - 1.0))

        r, jc, jv = self.evaluate(x, rows)
        c0 = cost(r)
        lam = 1e-4
        for _ in range(max_iter):
            J = self.jacobian(jc, jv, rows)
            e2 = (r.reshape(-1, 2) ** 2).sum(1) / f_scale**2
            w = np.repeat(1.0 / np.sqrt(1.0 + e2), 2)  # IRLS weight of soft-L1
            H = (J.T @ J.multiply(w[:, None])).tocsr()
            g = J.T @ (w * r)
            diag = np.maximum(H.diagonal(), 1e-12)
            dense = H.shape[0] <= _DENSE_MAX
            H = H.toarray() if dense else self._blocks(H)
            while True:
                try:
                    step = (-np.linalg.solve(H + lam * np.diag(diag), g) if dense else
                            _schur_step(*H, diag, lam, g))
                    step = step if np.all(np.isfinite(step)) else None
                except np.linalg.LinAlgError:
                    step = None
                if step is not None:
                    trial = x.copy()
                    trial[mask] += step
                    r_new = self.evaluate(trial, rows, jacobian=False)[0]
                    c_new = cost(r_new) if np.all(np.isfinite(r_new)) else np.inf
                    if c_new < c0:
                        break
                lam *= 10.0
                if lam > 1e10:
                    return x
            self.nfev += 1
            x, done = trial, c0 - c_new < 1e-10 * c0
            lam = max(lam / 10.0, 1e-9)
            c0 = c_new
            if done:
                break
            r, jc, jv = self.evaluate(x, rows)
        return x


def _schur_step(A, B, C, diag, lam, g):
    """Solve (H + lam diag(H)) x = -g for H = [[A, B], [B^T, C]], C block diagonal: the
    camera part through the Schur complement, then each block alone (free 3D points or
    board poses make H an arrowhead matrix; a general sparse solve is 50x slower)."""
    m, b = A.shape[0], C.shape[1]
    Ad = A + lam * np.diag(diag[:m])
    Cd = C + lam * diag[m:].reshape(-1, b)[:, :, None] * np.eye(b)
    Ci = np.linalg.inv(Cd)
    ga, gc = g[:m], g[m:].reshape(-1, b)
    Bt = B.T.tocsr()
    # B C^-1 as a sparse product: scale the block columns of B by C^-1
    BCi = (B @ _block_diag(Ci)).tocsr() if m else B
    S = Ad - (BCi @ Bt).toarray() if m else Ad
    rhs = -ga + BCi @ gc.ravel() if m else -ga
    da = np.linalg.solve(S, rhs) if m else np.zeros(0)
    dc = np.einsum("nij,nj->ni", Ci, -gc - (Bt @ da).reshape(-1, b))
    return np.r_[da, dc.ravel()]


def _block_diag(blocks: np.ndarray):
    n, b, _ = blocks.shape
    rows = (np.arange(n)[:, None, None] * b + np.arange(b)[None, :, None]).repeat(b, 2)
    cols = (np.arange(n)[:, None, None] * b + np.arange(b)[None, None, :]).repeat(b, 1)
    return coo_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(n * b, n * b))


def adjust_iterative(problem: Problem, full: np.ndarray, opts: Options,
                     rng: np.random.Generator, sample: int = 4000):
    """Anipose's Algorithm 1: bundle adjustment on the corners below a threshold that
    shrinks from ``mu_start`` to ``mu_end``, clipped to the 15th-75th error percentiles.
    Early iterations use a random sample of the corners; the last one all of them."""
    n = len(problem.cam)
    threshold = opts.mu_start
    for i in range(1, opts.iterations + 1):
        last = i == opts.iterations
        rows = np.arange(n) if last or n <= sample else np.sort(rng.choice(n, sample, False))
        err = problem.errors(full)[rows]
        mu = opts.mu_start * (opts.mu_end / opts.mu_start) ** (i / opts.iterations)
        low, high = np.percentile(err, [15, 75])
        threshold = max(low, min(mu, high))
        picked = rows[err < threshold]
        full = problem.solve(full, picked, f_scale=max(threshold / 3, 0.3),
                             max_iter=100 if last else 20)
    # Polish on every corner within the final outlier threshold: the last iteration kept
    # only the best 75 %, a set that depends on the start; this one hardly does, so all
    # starts meet in the same minimum.
    for _ in range(3):  # until the set settles
        err = problem.errors(full)
        limit = inlier_threshold(err, opts)
        picked = np.flatnonzero(err < limit)
        if _ and np.array_equal(picked, last):
            break
        full, last = problem.solve(full, picked, f_scale=limit / 3, max_iter=100), picked
    err = problem.errors(full)
    return full, err, err < inlier_threshold(err, opts)


def inlier_threshold(err: np.ndarray, opts: Options) -> float:
    """Errors above this (px) count as outliers in the report."""
    return float(max(opts.mu_end, 3.0 * np.median(err)))


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
