"""numba kernels of triangulation (private; see :mod:`kinematics.triangulation`).

Their NumPy twins (``_dlt_numpy``, ``_ransac_numpy``, ``_residuals_numpy`` in
:mod:`kinematics.triangulation`) are the readable specification and the test oracle.

Cameras come twice: as linear 3x4 matrices ``mats`` (C, 3, 4) acting on the *linearised*
image points (pinhole: ``[R | t]`` and the undistorted normalised coordinates, exactly what
``cv2.undistortPoints`` gives, as aniposelib uses them; orthographic: ``[P; 0 0 0 1]`` and the
pixels themselves), and packed (``kinematics.cameras.CameraArrays``) for projection in pixels.
A keypoint takes part where its weight ``w`` is > 0 (the API puts 0 where it is missing).
The kernels run single-threaded and release the GIL: on small inputs a thread pool's start
costs more than it saves, and a caller can run blocks of points in threads.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from kinematics._camera_kernels import ORTHOGRAPHIC, project_point

LOSS_LINEAR = 0
LOSS_SOFT_L1 = 1
LOSS_HUBER = 2

#: Iterations of the undistortion, cv2.undistortPoints' default (TermCriteria MAX_ITER, 5).
UNDISTORT_ITERATIONS = 5


@njit(cache=True, nogil=True)
def _householder_r(a, rows):
    """Householder QR of ``a[:rows]`` (rows >= 4, 4 columns) in place: R, which has the
    same singular values and right singular vectors, ends up in ``a[:4]`` (zeros below)."""
    for k in range(4):
        head = a[k, k]
        tail = 0.0
        for i in range(k + 1, rows):
            tail += a[i, k] * a[i, k]
        norm = np.sqrt(head * head + tail)
        if norm == 0.0:
            continue
        alpha = -norm if head > 0.0 else norm
        v0 = head - alpha
        vn2 = v0 * v0 + tail
        for j in range(k + 1, 4):
            dot = v0 * a[k, j]
            for i in range(k + 1, rows):
                dot += a[i, k] * a[i, j]
            f = 2.0 * dot / vn2
            a[k, j] -= f * v0
            for i in range(k + 1, rows):
                a[i, j] -= f * a[i, k]
        a[k, k] = alpha
    for i in range(1, 4):
        for k in range(i):
            a[i, k] = 0.0


@njit(cache=True, nogil=True)
def _inverse_iteration(r, h, steps):
    """Smallest right singular vector of the upper-triangular ``r`` (4, 4) by inverse
    iteration, two triangular solves a step (RᵀR is never formed, so the condition number is
    not squared); converges by (σ4 / σ3)² a step. ``h`` (4,) gets the vector. False when it
    has not converged to rounding within ``steps``."""
    big = max(abs(r[0, 0]), abs(r[1, 1]), abs(r[2, 2]), abs(r[3, 3]))
    for k in range(4):
        if abs(r[k, k]) <= 1e-15 * big:  # an exact null direction: that is the answer
            h[:] = 0.0
            h[k] = 1.0
            for i in range(k - 1, -1, -1):
                acc = 0.0
                for j in range(i + 1, k + 1):
                    acc -= r[i, j] * h[j]
                h[i] = acc / r[i, i]
            norm = np.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2 + h[3] ** 2)
            for i in range(4):
                h[i] /= norm
            return True
    d0, d1, d2, d3 = 1.0 / r[0, 0], 1.0 / r[1, 1], 1.0 / r[2, 2], 1.0 / r[3, 3]
    # start from the inhomogeneous solution (X, 1) with R[:3, :3] X = -R[:3, 3]: close to
    # the answer, which then takes two or three steps instead of eight from (0, 0, 0, 1)
    z2 = -r[2, 3] * d2
    z1 = (-r[1, 3] - r[1, 2] * z2) * d1
    z0 = (-r[0, 3] - r[0, 1] * z1 - r[0, 2] * z2) * d0
    norm = np.sqrt(z0 * z0 + z1 * z1 + z2 * z2 + 1.0)
    h[0], h[1], h[2], h[3] = z0 / norm, z1 / norm, z2 / norm, 1.0 / norm
    last = np.inf
    for _ in range(steps):
        y0 = h[0] * d0  # Rᵀ y = h (forward)
        y1 = (h[1] - r[0, 1] * y0) * d1
        y2 = (h[2] - r[0, 2] * y0 - r[1, 2] * y1) * d2
        y3 = (h[3] - r[0, 3] * y0 - r[1, 3] * y1 - r[2, 3] * y2) * d3
        z3 = y3 * d3  # R z = y (backward)
        z2 = (y2 - r[2, 3] * z3) * d2
        z1 = (y1 - r[1, 2] * z2 - r[1, 3] * z3) * d1
        z0 = (y0 - r[0, 1] * z1 - r[0, 2] * z2 - r[0, 3] * z3) * d0
        norm = np.sqrt(z0 * z0 + z1 * z1 + z2 * z2 + z3 * z3)
        z0, z1, z2, z3 = z0 / norm, z1 / norm, z2 / norm, z3 / norm
        sign = 1.0 if z0 * h[0] + z1 * h[1] + z2 * h[2] + z3 * h[3] >= 0.0 else -1.0
        delta = max(abs(z0 - sign * h[0]), abs(z1 - sign * h[1]), abs(z2 - sign * h[2]),
                    abs(z3 - sign * h[3]))
        h[0], h[1], h[2], h[3] = z0, z1, z2, z3
        # converged to rounding: no change, or the change stopped shrinking at its level
        if delta <= 2e-16 or (delta < 1e-14 and delta > 0.5 * last):
            return True
        last = delta
    return False


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
def smallest_right_singular(a, rows, out):
    """Right singular vector of the smallest singular value of ``a[:rows]`` (rows >= 4, 4
    columns) into ``out`` (4,), sign arbitrary, as LAPACK's SVD gives it (to rounding) but
    several times faster on these tiny matrices: Householder QR to R (4, 4), then inverse
    iteration, or Jacobi rotations when the two smallest singular values are too close for
    it to converge in 12 steps. ``a`` is overwritten.
    """
    _householder_r(a, rows)
    if not _inverse_iteration(a[:4], out, 12):
        _jacobi(a[:4], out)


@njit(cache=True, nogil=True, error_model="numpy")
def linearise(kind, K, dist, c, u, v):
    """The linearised image point of pixel (u, v) in camera ``c``: orthographic, the pixel;
    pinhole, the undistorted normalised coordinates by OpenCV's fixed-point iteration, the
    same arithmetic and number of steps as ``cv2.undistortPoints`` (its result to rounding;
    like OpenCV it returns the distorted coordinates where a step leaves the model's range).
    It runs all steps and decides at the end (numpy's error model: a step past a bad one may
    divide by zero harmlessly)."""
    if kind[c] == ORTHOGRAPHIC:
        return u, v
    x0 = (u - K[c, 0, 2]) * (1.0 / K[c, 0, 0])
    y0 = (v - K[c, 1, 2]) * (1.0 / K[c, 1, 1])
    k1, k2, p1, p2 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3]
    k3, k4, k5, k6 = dist[c, 4], dist[c, 5], dist[c, 6], dist[c, 7]
    x, y = x0, y0
    bad = False
    for _ in range(UNDISTORT_ITERATIONS):
        r2 = x * x + y * y
        icdist = (1.0 + ((k6 * r2 + k5) * r2 + k4) * r2) / (1.0 + ((k3 * r2 + k2) * r2 + k1) * r2)
        bad |= icdist < 0.0  # OpenCV stops there and keeps (x0, y0)
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        x = (x0 - dx) * icdist
        y = (y0 - dy) * icdist
    if bad:
        return x0, y0
    return x, y


@njit(cache=True, nogil=True)
def _gather(kind, K, dist, px, w, n, cams, lin):
    """Cameras seeing point ``n`` (weight > 0) into ``cams``, their linearised points into
    ``lin`` (C, 2); returns how many."""
    m = 0
    for c in range(w.shape[0]):
        if w[c, n] > 0.0:
            cams[m] = c
            m += 1
            lin[c, 0], lin[c, 1] = linearise(kind, K, dist, c, px[c, n, 0], px[c, n, 1])
    return m


@njit(cache=True, nogil=True)
def dlt_point(mats, lin, w, n, cams, m, work, out):
    """Weighted homogeneous DLT of one point over the first ``m`` cameras listed in ``cams``:
    the right singular vector of the smallest singular value of the stacked rows
    ``w (x M[2] - M[0])``, ``w (y M[2] - M[1])`` (aniposelib's ``triangulate_simple`` when
    every weight is 1). ``lin`` (C, 2), weights ``w[:, n]``; ``work`` (>= 2 m + 1, 4)
    scratch; writes ``out`` (3,), NaN when fewer than two cameras or the point is at
    infinity."""
    if m < 2:
        out[:] = np.nan
        return
    for i in range(m):
        c = cams[i]
        for k in range(4):
            work[2 * i, k] = w[c, n] * (lin[c, 0] * mats[c, 2, k] - mats[c, 0, k])
            work[2 * i + 1, k] = w[c, n] * (lin[c, 1] * mats[c, 2, k] - mats[c, 1, k])
    h = work[2 * m]
    smallest_right_singular(work, 2 * m, h)
    if h[3] == 0.0:
        out[:] = np.nan
        return
    for k in range(3):
        out[k] = h[k] / h[3]


@njit(cache=True, nogil=True)
def mean_error(kind, P, K, dist, R, t, px, n, cams, m, x):
    """Mean pixel distance between the projections of ``x`` (3,) and ``px[c, n]`` over the
    first ``m`` cameras ``c`` of ``cams``; NaN if the point does not project into one."""
    total = 0.0
    x0, x1, x2 = x[0], x[1], x[2]
    for i in range(m):
        c = cams[i]
        u, v = project_point(kind, P, K, dist, R, t, c, x0, x1, x2)
        total += np.sqrt((u - px[c, n, 0]) ** 2 + (v - px[c, n, 1]) ** 2)
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
def linear_kernel(mats, px, w, kind, P, K, dist, R, t, xyz, err, ncams):
    """Linear triangulation of every point. ``px`` (C, N, 2) pixels, ``w`` (C, N); writes
    ``xyz`` (N, 3), ``err`` (N,) mean reprojection error in px and ``ncams`` (N,)."""
    n_cam = px.shape[0]
    cams = np.empty(n_cam, np.int64)
    lin = np.empty((n_cam, 2))
    work = np.empty((2 * n_cam + 1, 4))
    for p in range(px.shape[1]):
        m = _gather(kind, K, dist, px, w, p, cams, lin)
        ncams[p] = m
        dlt_point(mats, lin, w, p, cams, m, work, xyz[p])
        err[p] = mean_error(kind, P, K, dist, R, t, px, p, cams, m, xyz[p]) if (
            m >= 2) else np.nan


@njit(cache=True, nogil=True)
def ransac_kernel(mats, px, w, kind, P, K, dist, R, t, min_cams, good_px, max_px, inlier_px,
                  xyz, err, used):
    """RANSAC over camera subsets, aniposelib's ``triangulate_ransac`` semantics: every
    subset of the cameras that see the point (at least ``min_cams`` of them, or all when
    fewer see it) is triangulated in aniposelib's order (all cameras first, then dropping
    the last ones first); the subset with the lowest mean reprojection error below
    ``max_px`` wins, and the search stops at the first one below ``good_px``. With
    ``inlier_px`` > 0 every other camera within ``inlier_px`` of the winner's projection is
    added and the point re-solved over those inliers. ``px`` (C, N, 2) pixels, ``w`` (C, N);
    writes ``xyz`` (N, 3), ``err`` (N,) and ``used`` (C, N) the cameras of the result."""
    n_cam = px.shape[0]
    avail = np.empty(n_cam, np.int64)
    cams = np.empty(n_cam, np.int64)
    lin = np.empty((n_cam, 2))
    work = np.empty((2 * n_cam + 1, 4))
    x = np.empty(3)
    for n in range(px.shape[1]):
        m = _gather(kind, K, dist, px, w, n, avail, lin)
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
            dlt_point(mats, lin, w, n, cams, count, work, x)
            e = mean_error(kind, P, K, dist, R, t, px, n, cams, count, x)
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
                u, v = project_point(kind, P, K, dist, R, t, c, xyz[n, 0], xyz[n, 1], xyz[n, 2])
                if used[c, n] or np.sqrt((u - px[c, n, 0]) ** 2 + (v - px[c, n, 1]) ** 2) < (
                        inlier_px):
                    used[c, n] = True
                    cams[count] = c
                    count += 1
            dlt_point(mats, lin, w, n, cams, count, work, x)
            e = mean_error(kind, P, K, dist, R, t, px, n, cams, count, x)
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


@njit(cache=True, nogil=True)
def errors_kernel(kind, P, K, dist, R, t, px, used, xyz, err, ncams):
    """Mean reprojection error ``err`` (N,) in px of the points ``xyz`` (N, 3) over the
    cameras ``used`` (C, N) (float, > 0: used) that see them at ``px`` (C, N, 2), and their
    number ``ncams``."""
    cams = np.empty(used.shape[0], np.int64)
    for p in range(xyz.shape[0]):
        m = _present(used, p, cams)
        ncams[p] = m
        err[p] = mean_error(kind, P, K, dist, R, t, px, p, cams, m, xyz[p]) if (
            m >= 1) else np.nan
