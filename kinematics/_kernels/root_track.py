"""Tracking a free root's translation through time from its detections (a damped
Gauss-Newton step per frame from the previous frame's position)."""

from __future__ import annotations

import numpy as np
from numba import njit

from kinematics._kernels.camera import project_point
from kinematics._kernels.fastmath import solve_spd


# -- root marker tracking (Sect. 2.1, 3.3.1) ---------------------------------------------
@njit(cache=True, nogil=True)
def track_root(det_points, det_off, x0, gate, ridge, cams, out):
    """Follow one root marker through frames by nearest neighbour in every view.

    For each frame in turn, the marker's previous 3D position is projected into every view;
    the nearest detection there (within ``gate`` pixels) is its observation; the new 3D
    position minimises the squared reprojection error over the observing views plus
    ``ridge`` times the squared distance to the previous position (so directions no view
    sees, e.g. depth in a single orthographic view, stay put). Gauss-Newton with numerical
    Jacobians: exact in one step for orthographic views, a few steps for pinhole ones. A
    frame where no view sees a detection keeps the previous position, and the gate doubles
    for every such frame until the marker is seen again (re-acquisition after a gap).

    Parameters
    ----------
    det_points : (n_points, 2); det_off : (n_frames * n_views + 1,) int64, frame-major.
    x0 : (3,) the marker's position before the first frame; cams : CameraArrays.
    out : (n_frames, 3) tracked positions.

    Returns
    -------
    n_lost : int, frames where no view observed the marker.
    """
    kind, P, K, dist, R, t = cams
    nv = kind.shape[0]
    nf = out.shape[0]
    obs = np.empty((nv, 2))
    seen = np.zeros(nv, np.bool_)
    prev = x0.copy()
    x = x0.copy()
    a = np.empty((3, 3))
    g = np.empty(3)
    jv = np.empty((2, 3))
    n_lost = 0
    h = 1e-6 * (1.0 + np.abs(x0).max())
    search = gate
    for f in range(nf):
        n_seen = 0
        for v in range(nv):
            pu, pv = project_point(kind, P, K, dist, R, t, v, prev[0], prev[1], prev[2])
            lo = det_off[f * nv + v]
            hi = det_off[f * nv + v + 1]
            best = search * search
            arg = -1
            for c in range(lo, hi):
                dx = det_points[c, 0] - pu
                dy = det_points[c, 1] - pv
                d2 = dx * dx + dy * dy
                if d2 < best or (arg < 0 and d2 <= best):
                    best = d2
                    arg = c
            seen[v] = arg >= 0
            if arg >= 0:
                obs[v, 0] = det_points[arg, 0]
                obs[v, 1] = det_points[arg, 1]
                n_seen += 1
        if n_seen == 0:
            n_lost += 1
            search *= 2.0  # re-acquisition: the marker may have moved on during the gap
        else:
            search = gate
            for k in range(3):
                x[k] = prev[k]
            for _ in range(8):
                for r in range(3):
                    g[r] = ridge * (prev[r] - x[r])
                    for c in range(3):
                        a[r, c] = ridge if r == c else 0.0
                for v in range(nv):
                    if seen[v]:
                        u0, w0 = project_point(kind, P, K, dist, R, t, v, x[0], x[1], x[2])
                        for k in range(3):
                            x[k] += h
                            u1, w1 = project_point(kind, P, K, dist, R, t, v, x[0], x[1], x[2])
                            x[k] -= h
                            jv[0, k] = (u1 - u0) / h
                            jv[1, k] = (w1 - w0) / h
                        ru = obs[v, 0] - u0
                        rv = obs[v, 1] - w0
                        for r in range(3):
                            g[r] += jv[0, r] * ru + jv[1, r] * rv
                            for c in range(3):
                                a[r, c] += jv[0, r] * jv[0, c] + jv[1, r] * jv[1, c]
                solve_spd(a, g, 3)
                for k in range(3):
                    x[k] += g[k]
            for k in range(3):
                prev[k] = x[k]
        for k in range(3):
            out[f, k] = prev[k]
    return n_lost
