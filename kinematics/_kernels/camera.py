"""numba kernels for camera projection (private; see :mod:`kinematics.cameras`).

The readable NumPy twin of these kernels is ``OrthographicCamera.project`` and
``PinholeCamera.project`` in :mod:`kinematics.cameras`; it is the specification and the
test oracle. The kernels take the packed arrays of :class:`kinematics.cameras.CameraArrays`
one by one (not the namedtuple) so that the fitter's hot loop passes plain arrays and
nothing is allocated per call.

Array layout, for ``n`` cameras indexed by ``c``:

- ``kind`` (n,) int64: 0 orthographic, 1 pinhole.
- ``P`` (n, 2, 4): orthographic matrix, ``(u, v) = P @ (x, y, z, 1)``.
- ``K`` (n, 3, 3), ``dist`` (n, 8), ``R`` (n, 3, 3), ``t`` (n, 3): OpenCV pinhole model.
"""

from __future__ import annotations

import numpy as np
from numba import njit

ORTHOGRAPHIC = 0
PINHOLE = 1


@njit(cache=True, nogil=True)
def project_point(kind, P, K, dist, R, t, c, x, y, z):
    """Project one world point through camera ``c``; returns ``(u, v)`` in pixels.

    Orthographic: paper Eq. 3 generalised, ``(u, v) = P[c] @ (x, y, z, 1)``.
    Pinhole: OpenCV's ``projectPoints`` with the rational distortion model; a point
    with camera-frame ``z <= 0`` (behind the camera) or NaN gives ``(nan, nan)``.
    Allocates nothing.
    """
    if kind[c] == ORTHOGRAPHIC:
        u = P[c, 0, 0] * x + P[c, 0, 1] * y + P[c, 0, 2] * z + P[c, 0, 3]
        v = P[c, 1, 0] * x + P[c, 1, 1] * y + P[c, 1, 2] * z + P[c, 1, 3]
        return u, v
    xc = R[c, 0, 0] * x + R[c, 0, 1] * y + R[c, 0, 2] * z + t[c, 0]
    yc = R[c, 1, 0] * x + R[c, 1, 1] * y + R[c, 1, 2] * z + t[c, 1]
    zc = R[c, 2, 0] * x + R[c, 2, 1] * y + R[c, 2, 2] * z + t[c, 2]
    if not zc > 0.0:  # also catches NaN
        return np.nan, np.nan
    xn = xc / zc
    yn = yc / zc
    k1, k2, p1, p2 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3]
    k3, k4, k5, k6 = dist[c, 4], dist[c, 5], dist[c, 6], dist[c, 7]
    r2 = xn * xn + yn * yn
    radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = xn * radial + 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn)
    yd = yn * radial + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn
    return K[c, 0, 0] * xd + K[c, 0, 2], K[c, 1, 1] * yd + K[c, 1, 2]


@njit(cache=True, nogil=True)
def project_points_kernel(kind, P, K, dist, R, t, c, pts, out):
    """Project ``pts`` (m, 3) through camera ``c`` into ``out`` (m, 2), in place."""
    for i in range(pts.shape[0]):
        u, v = project_point(kind, P, K, dist, R, t, c, pts[i, 0], pts[i, 1], pts[i, 2])
        out[i, 0] = u
        out[i, 1] = v
