"""numba kernels of triangulation (private; see :mod:`kinematics.observe.triangulation`).

Their NumPy twins (``_linearise_numpy``, ``_dlt_numpy``, ``_ransac_numpy``,
``_mean_errors_numpy``, ``_residuals_numpy`` in :mod:`kinematics.observe.triangulation`;
LAPACK's SVD
and QR for the solver) are the readable specification and the test oracle.

Cameras come twice: as linear 3x4 matrices ``mats`` (C, 3, 4) acting on the *linearised*
image points (pinhole: ``[R | t]`` and the undistorted normalised coordinates, exactly what
``cv2.undistortPoints`` gives, as aniposelib uses them; orthographic: ``[P; 0 0 0 1]`` and the
pixels themselves), and packed (``kinematics.cameras.CameraArrays``) for projection in pixels.
A keypoint takes part where its weight ``w`` is > 0 (the API puts 0 where it is missing).
The kernels run single-threaded and release the GIL: on small inputs a thread pool's start
costs more than it saves, and a caller can run blocks of points in threads.

Speed comes from SIMD across points, not from threads: arrays are planar (``u``, ``v`` of shape
(C, N) rather than (C, N, 2)) and the hot loops run over points with each camera's parameters
in locals (undistortion and reprojection per camera) or over a block of points in lanes (the
DLT's QR and inverse iteration), branch-free where a lane may differ. A point's result does
not depend on its block or lane, to the bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from kinematics._kernels.camera import ORTHOGRAPHIC, project_point

LOSS_LINEAR = 0
LOSS_SOFT_L1 = 1
LOSS_HUBER = 2

#: Iterations of the undistortion, cv2.undistortPoints' default (TermCriteria MAX_ITER, 5).
UNDISTORT_ITERATIONS = 5


#: Points whose DLTs are solved together, in SIMD lanes. Every step of the QR is a short loop
#: whose set-up costs about as much as a few lanes: 512 lanes run 1.4x faster than 128 and
#: about as fast as 1024 (a block's scratch, 130 kB with 4 cameras, stays in L2).
BLOCK = 512

#: Lane states of :func:`smallest_right_singular` (NULL: R has an exact null direction).
ITERATE, DONE, NULL = 0, 1, 2


#: Rows of the per-lane scratch ``lane`` (13, lanes) of the solver: 0-3 the vector h, 4-7
#: 1 / diag(R), 8 the last change of h, 9-12 the Householder step's alpha, v0, |v|², f.
_ALPHA, _V0, _VN2, _F = 9, 10, 11, 12


@njit(cache=True, nogil=True, error_model="numpy")
def qr_lanes(a, rows, lane, lanes):
    """Householder QR of ``a[:rows, :, i]`` (rows >= 4, 4 columns) of every lane ``i <
    lanes``, in place: R, which has the same singular values and right singular vectors,
    ends up in ``a[:4, :, i]`` (zeros below). Every step is a loop across the lanes, which
    runs in SIMD. Rows of zeros (cameras left out) leave R that of the other rows, up to the
    signs of its rows (and rounding where one of them is among the first four)."""
    for k in range(4):
        for i in range(lanes):
            lane[_VN2, i] = 0.0
        for row in range(k + 1, rows):
            for i in range(lanes):
                lane[_VN2, i] += a[row, k, i] * a[row, k, i]
        for i in range(lanes):
            head, tail = a[k, k, i], lane[_VN2, i]
            norm = np.sqrt(head * head + tail)
            alpha = -norm if head > 0.0 else norm
            lane[_ALPHA, i] = alpha
            lane[_V0, i] = head - alpha
            lane[_VN2, i] = (head - alpha) * (head - alpha) + tail
        for j in range(k + 1, 4):
            for i in range(lanes):
                lane[_F, i] = lane[_V0, i] * a[k, j, i]
            for row in range(k + 1, rows):
                for i in range(lanes):
                    lane[_F, i] += a[row, k, i] * a[row, j, i]
            for i in range(lanes):
                vn2 = lane[_VN2, i]
                f = 2.0 * lane[_F, i] / vn2 if vn2 != 0.0 else 0.0  # 0: a zero column
                a[k, j, i] -= f * lane[_V0, i]
                lane[_F, i] = f
            for row in range(k + 1, rows):
                for i in range(lanes):
                    a[row, j, i] -= lane[_F, i] * a[row, k, i]
        for i in range(lanes):
            a[k, k, i] = lane[_ALPHA, i]
    for row in range(1, 4):
        for k in range(row):
            for i in range(lanes):
                a[row, k, i] = 0.0


@njit(cache=True, nogil=True)
def _null_vector(r, i, h):
    """The exact null direction of the upper-triangular lane ``i`` of ``r`` (its first
    diagonal entry at rounding level), unit length, into ``h[:4, i]``."""
    big = max(abs(r[0, 0, i]), abs(r[1, 1, i]), abs(r[2, 2, i]), abs(r[3, 3, i]))
    k = 0
    while abs(r[k, k, i]) > 1e-15 * big:
        k += 1
    for j in range(4):
        h[j, i] = 0.0
    h[k, i] = 1.0
    for row in range(k - 1, -1, -1):
        acc = 0.0
        for j in range(row + 1, k + 1):
            acc -= r[row, j, i] * h[j, i]
        h[row, i] = acc / r[row, row, i]
    norm = np.sqrt(h[0, i] ** 2 + h[1, i] ** 2 + h[2, i] ** 2 + h[3, i] ** 2)
    for j in range(4):
        h[j, i] /= norm


@njit(cache=True, nogil=True, error_model="numpy")
def _start(r, lane, state, lanes):
    """Each iterating lane's start, the inhomogeneous solution (X, 1) with
    R[:3, :3] X = -R[:3, 3] normalised: close to the answer, which then takes a few steps
    instead of many from (0, 0, 0, 1); and 1 / diag(R). A lane whose R has a diagonal entry
    at rounding level (an exact null direction) becomes NULL. Branch-free: runs in SIMD."""
    for i in range(lanes):
        r00, r11, r22, r33 = r[0, 0, i], r[1, 1, i], r[2, 2, i], r[3, 3, i]
        d0, d1, d2, d3 = 1.0 / r00, 1.0 / r11, 1.0 / r22, 1.0 / r33
        z2 = -r[2, 3, i] * d2
        z1 = (-r[1, 3, i] - r[1, 2, i] * z2) * d1
        z0 = (-r[0, 3, i] - r[0, 1, i] * z1 - r[0, 2, i] * z2) * d0
        norm = np.sqrt(z0 * z0 + z1 * z1 + z2 * z2 + 1.0)
        big = max(max(abs(r00), abs(r11)), max(abs(r22), abs(r33)))
        small = min(min(abs(r00), abs(r11)), min(abs(r22), abs(r33)))
        go = state[i] == ITERATE
        lane[0, i] = z0 / norm if go else lane[0, i]
        lane[1, i] = z1 / norm if go else lane[1, i]
        lane[2, i] = z2 / norm if go else lane[2, i]
        lane[3, i] = 1.0 / norm if go else lane[3, i]
        lane[4, i] = d0
        lane[5, i] = d1
        lane[6, i] = d2
        lane[7, i] = d3
        lane[8, i] = np.inf
        state[i] = NULL if go & (small <= 1e-15 * big) else state[i]


@njit(cache=True, nogil=True, error_model="numpy")
def _inverse_step(r, lane, state, lanes):
    """One step of inverse iteration in every iterating lane, two triangular solves (RᵀR is
    never formed, so the condition number is not squared); it converges by (σ4 / σ3)² a
    step. A lane is done when its vector has converged to rounding: no change, or the
    change stopped shrinking at that level. Branch-free (finished lanes keep their
    values), so it runs in SIMD. Returns how many lanes still iterate."""
    left = 0
    for i in range(lanes):
        h0, h1, h2, h3 = lane[0, i], lane[1, i], lane[2, i], lane[3, i]
        d0, d1, d2, d3 = lane[4, i], lane[5, i], lane[6, i], lane[7, i]
        y0 = h0 * d0  # Rᵀ y = h (forward)
        y1 = (h1 - r[0, 1, i] * y0) * d1
        y2 = (h2 - r[0, 2, i] * y0 - r[1, 2, i] * y1) * d2
        y3 = (h3 - r[0, 3, i] * y0 - r[1, 3, i] * y1 - r[2, 3, i] * y2) * d3
        z3 = y3 * d3  # R z = y (backward)
        z2 = (y2 - r[2, 3, i] * z3) * d2
        z1 = (y1 - r[1, 2, i] * z2 - r[1, 3, i] * z3) * d1
        z0 = (y0 - r[0, 1, i] * z1 - r[0, 2, i] * z2 - r[0, 3, i] * z3) * d0
        scale = 1.0 / np.sqrt(z0 * z0 + z1 * z1 + z2 * z2 + z3 * z3)  # divisions are slow
        z0, z1, z2, z3 = z0 * scale, z1 * scale, z2 * scale, z3 * scale
        sign = 1.0 if z0 * h0 + z1 * h1 + z2 * h2 + z3 * h3 >= 0.0 else -1.0
        delta = max(max(abs(z0 - sign * h0), abs(z1 - sign * h1)),
                    max(abs(z2 - sign * h2), abs(z3 - sign * h3)))
        go = state[i] == ITERATE
        done = go & ((delta <= 2e-16) | ((delta < 1e-14) & (delta > 0.5 * lane[8, i])))
        lane[0, i] = z0 if go else h0
        lane[1, i] = z1 if go else h1
        lane[2, i] = z2 if go else h2
        lane[3, i] = z3 if go else h3
        lane[8, i] = delta if go else lane[8, i]
        state[i] = DONE if done else state[i]
        if go and not done:
            left += 1
    return left


@njit(cache=True, nogil=True)
def _jacobi(r, out):
    """Smallest right singular vector of ``r`` (4, 4) by one-sided Jacobi rotations
    (Hestenes), accurate whatever the gap between the two smallest singular values."""
    v = np.zeros((4, 4))
    for i in range(4):
        v[i, i] = 1.0
    for _ in range(40):
        rotated = False
        for p in range(3):
            for q in range(p + 1, 4):
                alpha = 0.0
                beta = 0.0
                gamma = 0.0
                for i in range(4):
                    alpha += r[i, p] * r[i, p]
                    beta += r[i, q] * r[i, q]
                    gamma += r[i, p] * r[i, q]
                if gamma == 0.0 or abs(gamma) <= 1e-16 * np.sqrt(alpha * beta):
                    continue
                rotated = True
                zeta = (beta - alpha) / (2.0 * gamma)
                tan = (1.0 if zeta >= 0.0 else -1.0) / (abs(zeta) + np.sqrt(1.0 + zeta * zeta))
                cos = 1.0 / np.sqrt(1.0 + tan * tan)
                sin = cos * tan
                for i in range(4):
                    rp = r[i, p]
                    r[i, p] = cos * rp - sin * r[i, q]
                    r[i, q] = sin * rp + cos * r[i, q]
                    vp = v[i, p]
                    v[i, p] = cos * vp - sin * v[i, q]
                    v[i, q] = sin * vp + cos * v[i, q]
        if not rotated:
            break
    best, k_min = np.inf, 0
    for k in range(4):
        norm = r[0, k] ** 2 + r[1, k] ** 2 + r[2, k] ** 2 + r[3, k] ** 2
        if norm < best:
            best, k_min = norm, k
    for i in range(4):
        out[i] = v[i, k_min]


@njit(cache=True, nogil=True)
def smallest_right_singular(r, lane, state, lanes, steps=12):
    """For each lane ``i < lanes`` with ``state[i] == ITERATE``: the right singular vector of
    the smallest singular value of the upper-triangular ``r[:4, :, i]`` (4, 4; from
    :func:`qr_lanes`) into ``lane[:4, i]``, sign arbitrary, as LAPACK's SVD gives it (to
    rounding) but many times faster on these tiny matrices: inverse iteration, run across
    the lanes, or Jacobi rotations where the two smallest singular values are too close for
    it to converge in ``steps``. ``lane`` (13, lanes) scratch; every state ends DONE."""
    _start(r, lane, state, lanes)
    for i in range(lanes):
        if state[i] == NULL:
            _null_vector(r, i, lane)
            state[i] = DONE
    for _ in range(steps):
        if _inverse_step(r, lane, state, lanes) == 0:
            break
    for i in range(lanes):
        if state[i] == ITERATE:
            _jacobi(r[:, :, i], lane[:4, i])
            state[i] = DONE


@njit(cache=True, nogil=True)
def solver_scratch(n_cam, lanes):
    """Scratch of :func:`dlt_point` and the linear kernel: the rows (2 C, 4, lanes), the
    lanes' vectors (13, lanes) and states, one point's weights (C, 1)."""
    return (np.zeros((2 * n_cam, 4, lanes)), np.zeros((13, lanes)), np.zeros(lanes, np.int64),
            np.zeros((n_cam, 1)))


@njit(cache=True, nogil=True)
def rows_into(mats, lx, ly, w, first, lanes, a):
    """The DLT's rows of points ``first + i`` into lanes ``i < lanes`` of ``a`` (2 C, 4,
    lanes), camera ``c``'s in rows 2c, 2c + 1: ``w (x M[2] - M[0])``, ``w (y M[2] - M[1])``
    (aniposelib's ``triangulate_simple`` when every weight is 1), zeros where ``w`` is 0
    (as aniposelib does: they change no singular vector). Runs in SIMD across the lanes."""
    for c in range(mats.shape[0]):
        for k in range(4):
            m0, m1, m2 = mats[c, 0, k], mats[c, 1, k], mats[c, 2, k]
            for i in range(lanes):
                wt = w[c, first + i]
                a[2 * c, k, i] = wt * (lx[c, first + i] * m2 - m0) if wt > 0.0 else 0.0
                a[2 * c + 1, k, i] = wt * (ly[c, first + i] * m2 - m1) if wt > 0.0 else 0.0


@njit(cache=True, nogil=True)
def _dehomogenise(lane, i, out):
    """``out`` (3,) the point of lane ``i``'s homogeneous vector; NaN at infinity."""
    h3 = lane[3, i]
    for k in range(3):
        out[k] = lane[k, i] / h3 if h3 != 0.0 else np.nan


@njit(cache=True, nogil=True)
def dlt_point(mats, lx, ly, w, n, cams, m, scratch, out):
    """Weighted homogeneous DLT of one point over the first ``m`` cameras listed in ``cams``:
    the right singular vector of the smallest singular value of its rows (:func:`rows_into`).
    ``lx``, ``ly`` (C, N) linearised points, weights ``w[:, n]``; ``scratch`` from
    :func:`solver_scratch` (one lane); writes ``out`` (3,), NaN when fewer than two cameras
    or the point is at infinity."""
    if m < 2:
        out[:] = np.nan
        return
    a, lane, state, wp = scratch
    wp[:] = 0.0
    for i in range(m):
        wp[cams[i], 0] = w[cams[i], n]
    rows_into(mats, lx[:, n:n + 1], ly[:, n:n + 1], wp, 0, 1, a)
    qr_lanes(a, a.shape[0], lane, 1)
    state[0] = ITERATE
    smallest_right_singular(a, lane, state, 1)
    _dehomogenise(lane, 0, out)


@njit(cache=True, nogil=True, error_model="numpy")
def linearise(kind, K, dist, c, u, v, x, y):
    """The linearised image points ``x``, ``y`` (N,) of pixels ``u``, ``v`` (N,) in camera
    ``c``: orthographic, the pixels; pinhole, the undistorted normalised coordinates by
    OpenCV's fixed-point iteration, the same arithmetic and number of steps as
    ``cv2.undistortPoints`` (its result to rounding; like OpenCV it returns the distorted
    coordinates where a step leaves the model's range). It runs all steps and decides at
    the end (numpy's error model: a step past a bad one may divide by zero harmlessly). The
    camera's parameters are read into locals first: the loop then runs in SIMD lanes."""
    if kind[c] == ORTHOGRAPHIC:
        x[:] = u
        y[:] = v
        return
    cx, cy, ifx, ify = K[c, 0, 2], K[c, 1, 2], 1.0 / K[c, 0, 0], 1.0 / K[c, 1, 1]
    k1, k2, p1, p2 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3]
    k3, k4, k5, k6 = dist[c, 4], dist[c, 5], dist[c, 6], dist[c, 7]
    for n in range(u.shape[0]):
        x0 = (u[n] - cx) * ifx
        y0 = (v[n] - cy) * ify
        xn, yn = x0, y0
        bad = False
        for _ in range(UNDISTORT_ITERATIONS):
            r2 = xn * xn + yn * yn
            icdist = (1.0 + ((k6 * r2 + k5) * r2 + k4) * r2) / (
                1.0 + ((k3 * r2 + k2) * r2 + k1) * r2)
            bad |= icdist < 0.0  # OpenCV stops there and keeps (x0, y0)
            dx = 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn)
            dy = p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn
            xn = (x0 - dx) * icdist
            yn = (y0 - dy) * icdist
        x[n] = x0 if bad else xn
        y[n] = y0 if bad else yn


@njit(cache=True, nogil=True)
def linearise_all(kind, K, dist, u, v):
    """:func:`linearise` of every camera: (C, N) pixels -> (C, N) x, y."""
    x, y = np.empty(u.shape), np.empty(u.shape)
    for c in range(u.shape[0]):
        linearise(kind, K, dist, c, u[c], v[c], x[c], y[c])
    return x, y


@njit(cache=True, nogil=True, error_model="numpy")
def add_distances(kind, P, K, dist, R, t, c, pts, u, v, w, total):
    """``total[n] +=`` the pixel distance between the projection of ``pts[:, n]`` (3, N)
    through camera ``c`` and (``u[n]``, ``v[n]``), where ``w[n] > 0``. The arithmetic of
    :func:`project_point` (NaN behind the camera), written again with the camera's
    parameters in locals: there the loop runs in SIMD lanes, 20-30x faster than a call of
    ``project_point`` per point, whose parameter reads numba cannot hoist."""
    x, y, z = pts[0], pts[1], pts[2]
    if kind[c] == ORTHOGRAPHIC:
        a0, a1, a2, a3 = P[c, 0, 0], P[c, 0, 1], P[c, 0, 2], P[c, 0, 3]
        b0, b1, b2, b3 = P[c, 1, 0], P[c, 1, 1], P[c, 1, 2], P[c, 1, 3]
        for n in range(u.shape[0]):
            pu = a0 * x[n] + a1 * y[n] + a2 * z[n] + a3
            pv = b0 * x[n] + b1 * y[n] + b2 * z[n] + b3
            d = np.sqrt((pu - u[n]) ** 2 + (pv - v[n]) ** 2)
            total[n] += d if w[n] > 0.0 else 0.0
        return
    r00, r01, r02, t0 = R[c, 0, 0], R[c, 0, 1], R[c, 0, 2], t[c, 0]
    r10, r11, r12, t1 = R[c, 1, 0], R[c, 1, 1], R[c, 1, 2], t[c, 1]
    r20, r21, r22, t2 = R[c, 2, 0], R[c, 2, 1], R[c, 2, 2], t[c, 2]
    k1, k2, p1, p2 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3]
    k3, k4, k5, k6 = dist[c, 4], dist[c, 5], dist[c, 6], dist[c, 7]
    fx, fy, cx, cy = K[c, 0, 0], K[c, 1, 1], K[c, 0, 2], K[c, 1, 2]
    for n in range(u.shape[0]):
        xc = r00 * x[n] + r01 * y[n] + r02 * z[n] + t0
        yc = r10 * x[n] + r11 * y[n] + r12 * z[n] + t1
        zc = r20 * x[n] + r21 * y[n] + r22 * z[n] + t2
        xn = xc / zc
        yn = yc / zc
        r2 = xn * xn + yn * yn
        radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (
            1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = xn * radial + 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn)
        yd = yn * radial + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn
        d = np.sqrt((fx * xd + cx - u[n]) ** 2 + (fy * yd + cy - v[n]) ** 2)
        d = d if zc > 0.0 else np.nan
        total[n] += d if w[n] > 0.0 else 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def mean_errors(kind, P, K, dist, R, t, pts, u, v, w, err, ncams):
    """Mean reprojection error ``err`` (N,) in px of the points ``pts`` (3, N) over the
    cameras where ``w`` (C, N) > 0, which see them at ``u``, ``v`` (C, N); their number
    ``ncams`` (N,). NaN where no camera is used or the point is NaN or behind one."""
    err[:] = 0.0
    for c in range(u.shape[0]):
        add_distances(kind, P, K, dist, R, t, c, pts, u[c], v[c], w[c], err)
    for n in range(u.shape[1]):
        m = 0
        for c in range(u.shape[0]):
            m += w[c, n] > 0.0
        ncams[n] = m
        err[n] /= m  # 0 / 0: NaN


@njit(cache=True, nogil=True)
def mean_error(kind, P, K, dist, R, t, u, v, n, cams, m, x):
    """Mean pixel distance between the projections of ``x`` (3,) and (``u[c, n]``,
    ``v[c, n]``) over the first ``m`` cameras ``c`` of ``cams``; NaN if the point does not
    project into one."""
    total = 0.0
    x0, x1, x2 = x[0], x[1], x[2]
    for i in range(m):
        c = cams[i]
        pu, pv = project_point(kind, P, K, dist, R, t, c, x0, x1, x2)
        total += np.sqrt((pu - u[c, n]) ** 2 + (pv - v[c, n]) ** 2)
    return total / m


@njit(cache=True, nogil=True)
def _present(w, n, cams):
    """Cameras (0 .. C-1) where point ``n`` has weight > 0 into ``cams``; their number."""
    m = 0
    for c in range(w.shape[0]):
        if w[c, n] > 0.0:
            cams[m] = c
            m += 1
    return m


@njit(cache=True, nogil=True)
def linear_kernel(mats, u, v, w, kind, P, K, dist, R, t, xyz, err, ncams):
    """Linear triangulation of every point. ``u``, ``v`` (C, N) pixels, ``w`` (C, N);
    writes ``xyz`` (N, 3), ``err`` (N,) mean reprojection error in px and ``ncams`` (N,).
    Each stage loops over points, so that it runs in SIMD: the undistortion and the
    reprojection camera by camera over all of them, the rows, QR and inverse iteration
    across blocks of :data:`BLOCK` lanes."""
    n_cam, n = u.shape
    lx, ly = linearise_all(kind, K, dist, u, v)
    a, lane, state, _ = solver_scratch(n_cam, max(1, min(BLOCK, n)))
    pts = np.empty((3, n))
    for start in range(0, n, BLOCK):
        lanes = min(BLOCK, n - start)
        rows_into(mats, lx, ly, w, start, lanes, a)
        for i in range(lanes):
            m = 0
            for c in range(n_cam):
                m += w[c, start + i] > 0.0
            state[i] = ITERATE if m >= 2 else DONE
            if m < 2:
                for k in range(4):
                    lane[k, i] = np.nan
        qr_lanes(a, 2 * n_cam, lane, lanes)
        smallest_right_singular(a, lane, state, lanes)
        for i in range(lanes):
            _dehomogenise(lane, i, xyz[start + i])
            for k in range(3):
                pts[k, start + i] = xyz[start + i, k]
    mean_errors(kind, P, K, dist, R, t, pts, u, v, w, err, ncams)


@njit(cache=True, nogil=True)
def ransac_kernel(mats, u, v, w, cams, min_cams, good_px, max_px, inlier_px, xyz, err, used):
    """RANSAC over camera subsets, aniposelib's ``triangulate_ransac`` semantics: every
    subset of the cameras that see the point (at least ``min_cams`` of them, or all when
    fewer see it) is triangulated in aniposelib's order (all cameras first, then dropping
    the last ones first); the subset with the lowest mean reprojection error below
    ``max_px`` wins, and the search stops at the first one below ``good_px``. With
    ``inlier_px`` > 0 every other camera within ``inlier_px`` of the winner's projection is
    added and the point re-solved over those inliers. ``u``, ``v`` (C, N) pixels, ``w``
    (C, N); writes ``xyz`` (N, 3), ``err`` (N,) and ``used`` (C, N) the cameras of the
    result. ``cams``: CameraArrays."""
    kind, P, K, dist, R, t = cams.kind, cams.P, cams.K, cams.dist, cams.R, cams.t
    n_cam = u.shape[0]
    lx, ly = linearise_all(kind, K, dist, u, v)
    avail = np.empty(n_cam, np.int64)
    cams = np.empty(n_cam, np.int64)
    scratch = solver_scratch(n_cam, 1)
    x = np.empty(3)
    for n in range(u.shape[1]):
        m = _present(w, n, avail)
        best = max_px
        best_mask = -1
        xyz[n] = np.nan
        err[n] = np.nan
        used[:, n] = False
        for k in range(1 << m):
            count = 0
            for i in range(m):
                if (k >> (m - 1 - i)) & 1 == 0:  # bit clear: camera i is in the subset
                    cams[count] = avail[i]
                    count += 1
            if count < 2 or (count < min_cams and count != m):
                continue
            dlt_point(mats, lx, ly, w, n, cams, count, scratch, x)
            e = mean_error(kind, P, K, dist, R, t, u, v, n, cams, count, x)
            if e < best:
                best = e
                best_mask = k
                xyz[n] = x
                if best < good_px:
                    break
        if best_mask < 0:
            continue
        err[n] = best
        for i in range(m):
            if (best_mask >> (m - 1 - i)) & 1 == 0:
                used[avail[i], n] = True
        if inlier_px > 0.0:
            count = 0
            for i in range(m):
                c = avail[i]
                pu, pv = project_point(kind, P, K, dist, R, t, c, xyz[n, 0], xyz[n, 1],
                                       xyz[n, 2])
                if used[c, n] or np.sqrt((pu - u[c, n]) ** 2 + (pv - v[c, n]) ** 2) < (
                        inlier_px):
                    used[c, n] = True
                    cams[count] = c
                    count += 1
            dlt_point(mats, lx, ly, w, n, cams, count, scratch, x)
            e = mean_error(kind, P, K, dist, R, t, u, v, n, cams, count, x)
            if e == e:  # not NaN
                xyz[n] = x
                err[n] = e


@njit(cache=True, nogil=True)
def project_jacobian(kind, P, K, dist, R, t, c, x, y, z, jac):
    """Projection ``(u, v)`` of a world point through camera ``c`` and its derivative
    d(u, v)/d(x, y, z) into ``jac`` (2, 3): the chain rule through OpenCV's rational
    distortion model (``project_point`` gives the values)."""
    u, v = project_point(kind, P, K, dist, R, t, c, x, y, z)
    if kind[c] == ORTHOGRAPHIC:
        for i in range(2):
            for k in range(3):
                jac[i, k] = P[c, i, k]
        return u, v
    zc = R[c, 2, 0] * x + R[c, 2, 1] * y + R[c, 2, 2] * z + t[c, 2]
    if not zc > 0.0:
        jac[:] = np.nan
        return u, v
    a = (R[c, 0, 0] * x + R[c, 0, 1] * y + R[c, 0, 2] * z + t[c, 0]) / zc
    b = (R[c, 1, 0] * x + R[c, 1, 1] * y + R[c, 1, 2] * z + t[c, 1]) / zc
    k1, k2, p1, p2 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3]
    k3, k4, k5, k6 = dist[c, 4], dist[c, 5], dist[c, 6], dist[c, 7]
    r2 = a * a + b * b
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    radial = num / den
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    drad = (dnum * den - num * dden) / (den * den)  # d radial / d r2
    dxa = radial + 2.0 * a * a * drad + 2.0 * p1 * b + 6.0 * p2 * a
    dxb = 2.0 * a * b * drad + 2.0 * p1 * a + 2.0 * p2 * b
    dya = dxb
    dyb = radial + 2.0 * b * b * drad + 6.0 * p1 * b + 2.0 * p2 * a
    fx, fy = K[c, 0, 0], K[c, 1, 1]
    for k in range(3):
        da = (R[c, 0, k] - a * R[c, 2, k]) / zc
        db = (R[c, 1, k] - b * R[c, 2, k]) / zc
        jac[0, k] = fx * (dxa * da + dxb * db)
        jac[1, k] = fy * (dya * da + dyb * db)
    return u, v


@njit(cache=True, nogil=True)
def robust(r, scale, loss):
    """Robust residual and its derivative (aniposelib's per-coordinate transform, whose
    square is the soft-l1 or Huber cost at ``scale`` px)."""
    if loss == LOSS_LINEAR:
        return r, 1.0
    a = abs(r)
    s = 1.0 if r >= 0.0 else -1.0
    if loss == LOSS_SOFT_L1:
        q = np.sqrt(1.0 + a / scale)
        return s * 2.0 * scale * (q - 1.0), 1.0 / q
    if a <= scale:
        return r, 1.0
    q = np.sqrt(a / scale)
    return s * scale * (2.0 * q - 1.0), 1.0 / q


@njit(cache=True, nogil=True)
def reprojection_residuals(kind, P, K, dist, R, t, cam, point, uv, weight, xyz, scale, loss,
                           res, jac):
    """Robust weighted reprojection residuals of observations ``m``: camera ``cam[m]`` sees
    3D point ``point[m]`` (a row of ``xyz`` (n, 3)) at ``uv[m]`` with ``weight[m]``.
    Writes ``res`` (2 M,) and ``jac`` (2 M, 3), the derivative of each residual by the
    point's coordinates (projection off the image side of a camera: residual 0)."""
    j = np.empty((2, 3))
    for m in range(cam.shape[0]):
        p = point[m]
        u, v = project_jacobian(kind, P, K, dist, R, t, cam[m], xyz[p, 0], xyz[p, 1],
                                xyz[p, 2], j)
        for i in range(2):
            d = (u if i == 0 else v) - uv[m, i]
            r, dr = robust(weight[m] * d, scale, loss)
            if r != r:  # behind the camera: no pull until it is in front again
                r, dr = 0.0, 0.0
            res[2 * m + i] = r
            for k in range(3):
                g = dr * weight[m] * j[i, k]
                jac[2 * m + i, k] = g if g == g else 0.0
