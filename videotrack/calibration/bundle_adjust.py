"""Bundle adjustment (step 3 of :mod:`videotrack.calibration.bundle`): all cameras and board
poses (or 3D points, :mod:`videotrack.calibration.refine`) adjusted jointly by
Levenberg-Marquardt with a sparse analytic Jacobian and a soft-L1 robust loss, iterated with a
shrinking outlier threshold (Anipose, Algorithm 1).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np
from scipy.sparse import coo_matrix

from kinematics.cameras.calibration_math import N_INTRINSICS

if TYPE_CHECKING:
    from videotrack.calibration.bundle import Options

#: Above this many free parameters the normal equations are solved by the Schur complement.
_DENSE_MAX = 400
_N_CAM = 6 + N_INTRINSICS  # rvec, t, fx, fy, cx, cy, k1, k2, p1, p2, k3


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

    def prior(self, full: np.ndarray, jacobian: bool = True):
        """Residuals of priors on the parameters, in their standard deviations, and with
        ``jacobian`` their sparse Jacobian over the free parameters; None: no prior."""
        return None

    def prior_cost(self, full: np.ndarray) -> float:
        p = self.prior(full, jacobian=False)
        return 0.0 if p is None else 0.5 * float(p[0] @ p[0])

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
        c0 = cost(r) + self.prior_cost(x)
        lam = 1e-4
        for _ in range(max_iter):
            J = self.jacobian(jc, jv, rows)
            e2 = (r.reshape(-1, 2) ** 2).sum(1) / f_scale**2
            w = np.repeat(1.0 / np.sqrt(1.0 + e2), 2)  # IRLS weight of soft-L1
            H = (J.T @ J.multiply(w[:, None])).tocsr()
            g = J.T @ (w * r)
            prior = self.prior(x)
            if prior is not None:  # 0.5 |r_p|^2 in cost units, f_scale^2 times in H's
                rp, Jp = prior
                H = (H + (Jp.T @ Jp) * f_scale**2).tocsr()
                g = g + (Jp.T @ rp) * f_scale**2
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
                    c_new = (cost(r_new) + self.prior_cost(trial)
                             if np.all(np.isfinite(r_new)) else np.inf)
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
