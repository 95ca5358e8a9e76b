"""E against 3D points: labelled 3D points and the unlabelled cloud of detections
triangulated across views (nearest point, one to one, claims, unexplained counts). Twin:
:mod:`kinematics.fit.error_function`."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from kinematics._kernels.codes import NAN_MARKER_COST
from kinematics._kernels.error2d import may_take, one_to_one, takes


@njit(cache=True, nogil=True)
def points3d_error(mk, obs, cap):
    """3D point error: ``E = sum_i w_i min(|X_i - Y_i|, cap)`` over the markers whose point
    ``obs[i] = (x, y, z, w)`` is finite with ``w > 0``; in the body's length units."""
    total = 0.0
    for i in range(mk.shape[0]):
        w = obs[i, 3]
        if w > 0.0 and math.isfinite(obs[i, 0]) and math.isfinite(obs[i, 1]) and math.isfinite(
                obs[i, 2]):
            dx = mk[i, 0] - obs[i, 0]
            dy = mk[i, 1] - obs[i, 1]
            dz = mk[i, 2] - obs[i, 2]
            total += w * min(math.sqrt(dx * dx + dy * dy + dz * dz), cap)
    return total


@njit(cache=True, nogil=True, inline="always")
def cloud_nearest(mk, i, cloud, claimed):
    """Marker ``i``'s nearest cloud point not ``claimed`` (in px-equivalents: the 3D
    distance times the point's px per length unit, ``cloud[c, 3]``; 0 marks padding) among
    those it may take (:func:`may_take`); returns (distance, row), row -1 when there is
    none."""
    best = np.inf
    arg = -1
    for c in range(cloud.shape[0]):
        s = cloud[c, 3]
        dx = mk[i, 0] - cloud[c, 0]
        dy = mk[i, 1] - cloud[c, 1]
        dz = mk[i, 2] - cloud[c, 2]
        d2 = s * s * (dx * dx + dy * dy + dz * dz)
        if s > 0.0 and d2 < best and not (c < claimed.shape[0] and claimed[c]) and (
                may_take(cloud, c, i)):
            best = d2
            arg = c
    return math.sqrt(best), arg


@njit(cache=True, nogil=True)
def cloud_error(mk, cloud, m0, m1, claimed, penalty, cap, penalty_cap, one, nearest):
    """Unlabelled 3D points (:data:`OBJ_CLOUD`), the 3D twin of Eq. 5: ``E = sum_i
    min(s_c |X_i - Y_c|, cap)`` over the markers ``m0:m1``, ``Y_c`` marker i's nearest cloud
    point among those not ``claimed`` (by other partitions; an empty ``claimed`` claims
    nothing) and ``s_c`` its px per length unit (``cloud`` (k, 4): x, y, z, s; s = 0 marks
    padding; with a column per marker after them, only where it may take the point,
    :func:`may_take`), so E reads in pixels like Eq. 5's. With ``penalty > 0`` (the
    bidirectional modes) each unclaimed point that none of these markers takes adds
    ``penalty · min(s_c · distance to the nearest of them that may take it, penalty_cap)``
    (nothing where none may). With ``one`` each point explains at
    most one marker (:func:`one_to_one`). ``nearest`` (n_markers,) is scratch."""
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    for i in range(m0, m1):
        d, nearest[i] = cloud_nearest(mk, i, cloud, claimed)
        total += min(d if nearest[i] >= 0 else missing, cap)
    if one:
        total = one_to_one(mk, cloud, 0, cloud.shape[0], m0, m1, True, claimed, cap, nearest)
    if penalty > 0.0:
        for c in range(cloud.shape[0]):
            s = cloud[c, 3]
            taken = s <= 0.0 or (c < claimed.shape[0] and claimed[c])
            best = np.inf
            for i in range(m0, m1):
                taken = taken or takes(nearest[i], c)
                dx = mk[i, 0] - cloud[c, 0]
                dy = mk[i, 1] - cloud[c, 1]
                dz = mk[i, 2] - cloud[c, 2]
                if may_take(cloud, c, i):
                    best = min(best, dx * dx + dy * dy + dz * dz)
            if not taken and best < np.inf:
                total += penalty * min(s * math.sqrt(best), penalty_cap)
    return total


@njit(cache=True, nogil=True, inline="always")
def cloud_error_once(mk, cloud, m0, m1, penalty, cap, penalty_cap, nearest, marker_d2,
                     point_d2):
    """:func:`cloud_error` of a cloud nothing is claimed from, without one-to-one: the same
    E to the bit, each marker-point distance computed once for both terms (the nearest
    point of each marker and the nearest marker of each point; :func:`cloud_error` computes
    them twice). Points outer, markers inner, so each marker's search still meets the
    points in order (ties to the lower row). ``marker_d2`` (n_markers,), ``point_d2``
    (n_points or more,) float scratch."""
    missing = cap if cap < np.inf else NAN_MARKER_COST
    for i in range(m0, m1):
        marker_d2[i] = np.inf
        nearest[i] = -1
    for c in range(cloud.shape[0]):
        s = cloud[c, 3]
        nearest_c = np.inf
        if s > 0.0:
            ss = s * s
            for i in range(m0, m1):
                if may_take(cloud, c, i):
                    dx = mk[i, 0] - cloud[c, 0]
                    dy = mk[i, 1] - cloud[c, 1]
                    dz = mk[i, 2] - cloud[c, 2]
                    d2 = dx * dx + dy * dy + dz * dz
                    if ss * d2 < marker_d2[i]:
                        marker_d2[i] = ss * d2
                        nearest[i] = c
                    nearest_c = min(nearest_c, d2)
        point_d2[c] = nearest_c
    total = 0.0
    for i in range(m0, m1):
        total += min(math.sqrt(marker_d2[i]) if nearest[i] >= 0 else missing, cap)
    if penalty > 0.0:
        for c in range(cloud.shape[0]):
            taken = cloud[c, 3] <= 0.0
            for i in range(m0, m1):
                taken = taken or takes(nearest[i], c)
            if not taken and point_d2[c] < np.inf:
                total += penalty * min(cloud[c, 3] * math.sqrt(point_d2[c]), penalty_cap)
    return total


@njit(cache=True, nogil=True)
def claim_cloud(mk, cloud, claimers, gate, claimed):
    """:func:`claim_detections` for a 3D cloud: each marker flagged in ``claimers`` claims
    its nearest point within ``gate`` px-equivalents."""
    claimed[:] = False
    for i in range(mk.shape[0]):
        if not claimers[i]:
            continue
        d, arg = cloud_nearest(mk, i, cloud, claimed[:0])
        if arg >= 0 and d <= gate:
            claimed[arg] = True


@njit(cache=True, nogil=True)
def unclaimed_cloud(cloud, claimed):
    """The rows of ``cloud`` that are points (s > 0) and not ``claimed``, in order, and an
    empty claim mask: what :func:`cloud_error` scores with ``claimed``, to the bit, without
    testing every claimed or padding row on every call (a limb's search and annealing score
    the same points hundreds of thousands of times; in a later round every other limb's
    points are claimed)."""
    keep = np.empty(cloud.shape[0], np.int64)
    n = 0
    for c in range(cloud.shape[0]):
        if cloud[c, 3] > 0.0 and not (c < claimed.shape[0] and claimed[c]):
            keep[n] = c
            n += 1
    out = np.empty((n, cloud.shape[1]))
    for k in range(n):
        out[k, :] = cloud[keep[k]]
    return out, np.zeros(0, np.bool_)


@njit(cache=True, nogil=True)
def count_unexplained_cloud(mk, cloud, gate):
    """Cloud points farther than ``gate`` px-equivalents from every model marker."""
    n = 0
    for c in range(cloud.shape[0]):
        s = cloud[c, 3]
        near = s <= 0.0
        for i in range(mk.shape[0]):
            dx = mk[i, 0] - cloud[c, 0]
            dy = mk[i, 1] - cloud[c, 1]
            dz = mk[i, 2] - cloud[c, 2]
            near = near or (s * math.sqrt(dx * dx + dy * dy + dz * dz) <= gate and
                            may_take(cloud, c, i))
        n += 0 if near else 1
    return n
