"""E of a posture by objective: which error function a frame's observations ask for,
for the whole body or for one partition, and per-marker residuals of a block of frames."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from kinematics._kernels.codes import (
    NAN_MARKER_COST,
    NO_CLAIMS,
    OBJ_CLOUD,
    OBJ_LABELLED,
    OBJ_NEAREST,
    OBJ_POINTS3D,
    UNSEEN,
)
from kinematics._kernels.error2d import (
    labelled_error,
    nearest_in_view,
    nearest_residuals,
    one_to_one,
    projection_error,
    takes,
)
from kinematics._kernels.error3d import cloud_error, points3d_error
from kinematics._kernels.posture import hidden_in, project_posture


@njit(cache=True, nogil=True)
def block_residuals(states, ran, root_pos, root_rot, body, cams, points, offsets, gate, out,
                    unexplained):
    """:func:`nearest_residuals` of many frames' fitted postures in one call (a block's
    results; per frame from Python it was a third of the per-frame Python): for each frame k
    with ``ran[k]``, posture ``states[k]`` projected and every marker's distance to the
    nearest detection of its view written into ``out[k]`` (n_views, n_markers), the
    detections farther than ``gate`` from every marker counted into ``unexplained[k]``.
    ``offsets`` (n_frames * n_views + 1) index ``points``; every marker is seen."""
    nv, nm = cams.kind.shape[0], body.marker_joint.shape[0]
    na, nj = states.shape[1], body.parent.shape[0]
    seen = np.ones((nv, nm), np.bool_)
    cs, sn = np.empty(na), np.empty(na)
    rot, pos = np.empty((nj, 3, 3)), np.empty((nj, 3))
    mk, proj = np.empty((nm, 3)), np.empty((nv, nm, 2))
    for k in range(states.shape[0]):
        if ran[k]:
            project_posture(states[k], root_pos[k], root_rot[k], body, cams, cs, sn, rot, pos,
                            mk, proj)
            unexplained[k] = nearest_residuals(proj, points, offsets[k * nv: (k + 1) * nv + 1],
                                               seen, gate, out[k])


@njit(cache=True, nogil=True, inline="always")
def observed(objective, view_off, obs3):
    """Whether a frame has anything to fit: a detection in some view (``view_off``, its
    views' offsets), or for 3D points and clouds a point of weight > 0 (``obs3``)."""
    if objective in (OBJ_POINTS3D, OBJ_CLOUD):
        has = False
        for i in range(obs3.shape[0]):
            has = has or obs3[i, 3] > 0.0
        return has
    return view_off[view_off.shape[0] - 1] > view_off[0]


@njit(cache=True, nogil=True, inline="always")
def evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional, weight, cap,
             penalty_cap, one, per_view, nearest):
    """E of projected (``proj``) and 3D (``mk``) markers under ``objective``; fills
    ``per_view`` (zeros for 3D points, which have no views)."""
    if objective == OBJ_NEAREST:
        return projection_error(proj, points, view_off, obs3, bidirectional, weight, cap,
                                penalty_cap, one, per_view, nearest)
    if objective == OBJ_LABELLED:
        return labelled_error(proj, points, conf, view_off, cap, per_view)
    per_view[:] = 0.0
    if objective == OBJ_CLOUD:
        return cloud_error(mk, obs3, 0, mk.shape[0], NO_CLAIMS, weight if bidirectional
                           else 0.0, cap, penalty_cap, one, nearest)
    return points3d_error(mk, obs3, cap)



@njit(cache=True, nogil=True)
def partition_error(objective, proj, mk, points, conf, view_off, obs3, cap, m0, m1, claimed,
                    penalty, penalty_cap, one, nearest):
    """E of the markers ``m0:m1`` only (one partition; the rest is constant while it moves).

    Unlabelled points: each marker's nearest detection among those not ``claimed`` by the
    markers of other partitions (:func:`claim_detections`), capped: a leg cannot take a
    neighbour's marker. With ``penalty > 0`` (the bidirectional modes) each unclaimed
    detection that none of these markers takes adds ``penalty · min(distance to the nearest
    of them, penalty_cap)``: a leg is pulled to explain the blobs left over, not to share
    another's. Labelled keypoints and 3D points: each marker against its own, as
    :func:`labelled_error` and :func:`points3d_error`. With ``one`` each detection (point)
    explains at most one of these markers (:func:`one_to_one`). A marker hidden in a view
    (:func:`hidden_in`) is left out of it. ``nearest`` (n_markers,) is scratch.
    """
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    if objective == OBJ_CLOUD:
        return cloud_error(mk, obs3, m0, m1, claimed, penalty, cap, penalty_cap, one,
                           nearest)
    if objective == OBJ_POINTS3D:
        for i in range(m0, m1):
            w = obs3[i, 3]
            if w > 0.0:
                dx = mk[i, 0] - obs3[i, 0]
                dy = mk[i, 1] - obs3[i, 1]
                dz = mk[i, 2] - obs3[i, 2]
                total += w * min(math.sqrt(dx * dx + dy * dy + dz * dz), cap)
        return total
    nm = proj.shape[1]
    for v in range(proj.shape[0]):
        a = view_off[v]
        b = view_off[v + 1]
        if b <= a:
            continue
        if objective == OBJ_LABELLED:
            if b - a == nm:
                for i in range(m0, m1):
                    w = conf[a + i]
                    if w > 0.0 and math.isfinite(points[a + i, 0]):
                        dx = proj[v, i, 0] - points[a + i, 0]
                        dy = proj[v, i, 1] - points[a + i, 1]
                        d = math.sqrt(dx * dx + dy * dy)
                        total += w * min(d if math.isfinite(d) else missing, cap)
            continue
        ev = 0.0
        n_seen = 0
        for i in range(m0, m1):
            if hidden_in(obs3, i, v):
                nearest[i] = UNSEEN
                continue
            n_seen += 1
            best, arg = nearest_in_view(proj[v, i, 0], proj[v, i, 1], points, a, b, claimed)
            nearest[i] = arg
            d = math.sqrt(best) if best < np.inf else missing
            ev += min(d, cap)
        if one:
            ev = one_to_one(proj[v], points, a, b, m0, m1, False, claimed, cap, nearest)
        total += ev
        if penalty > 0.0 and n_seen == 0:  # no marker of these in the view: each costs missing
            for c in range(a, b):
                total += 0.0 if claimed[c] else penalty * min(missing, penalty_cap)
        elif penalty > 0.0:
            for c in range(a, b):
                taken = claimed[c]
                best = np.inf
                for i in range(m0, m1):
                    taken = taken or takes(nearest[i], c)
                    dx = proj[v, i, 0] - points[c, 0]
                    dy = proj[v, i, 1] - points[c, 1]
                    seen = nearest[i] != UNSEEN
                    best = min(best, dx * dx + dy * dy) if seen else best
                if not taken:
                    total += penalty * min(math.sqrt(best), penalty_cap)
    return total


@njit(cache=True, nogil=True)
def posture_error(angles, root_pos, root_rot, body, cams, obs, error, per_view):
    """E (Eq. 5, a variant or another objective, :func:`evaluate`) of one posture ``angles``
    (n_state,) of the folded ``body`` seen by ``cams``; ``obs`` a FrameObs, ``error`` the
    ErrorArgs. Fills ``per_view`` (n_views,). Allocates its scratch: for single
    evaluations, not for loops."""
    na = angles.shape[0]
    nj = body.parent.shape[0]
    nm = body.marker_joint.shape[0]
    cs = np.empty(na)
    sn = np.empty(na)
    rot = np.empty((nj, 3, 3))
    pos = np.empty((nj, 3))
    mk = np.empty((nm, 3))
    proj = np.empty((cams.kind.shape[0], nm, 2))
    nearest = np.empty(nm, np.int64)
    project_posture(angles, root_pos, root_rot, body, cams, cs, sn, rot, pos, mk, proj)
    return evaluate(obs.objective, proj, mk, obs.points, obs.conf, obs.view_off, obs.obs3,
                    error.bidirectional, error.weight, error.cap, error.penalty_cap,
                    error.one_to_one, per_view, nearest)
