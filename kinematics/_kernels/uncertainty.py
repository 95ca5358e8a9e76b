"""The Fisher information of a fitted posture: J^T Σ^-1 J of the pair residuals at the
posture, over the free state entries, from which :mod:`kinematics.fit.uncertainty` gives
each axis its standard deviation. The Jacobian is refinement's
(:func:`kinematics._kernels.refine.jacobian`); its NumPy twin is
:func:`kinematics.fit.refine.cramer_rao_bound`."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from kinematics._kernels.codes import OBJ_CLOUD_VIEWS
from kinematics._kernels.posture import has_pinhole, project_posture
from kinematics._kernels.records import frame_obs
from kinematics._kernels.refine import (
    assign_pairs,
    entry_spans,
    fill_residuals,
    jacobian,
    normal_equations,
    packed_index,
    pair_rows,
    row_view,
)


@njit(cache=True, nogil=True)
def posture_information(angles, free_idx, gate, root_pos, root_rot, body, cams, obs,
                        row_scale, info):
    """``info`` (n_free, n_free) = J^T W J at the state ``angles`` over the pairs within
    ``gate`` (:func:`kinematics._kernels.refine.assign_pairs`), each residual row scaled by
    ``row_scale`` (1/σ of its view; entry ``n_views`` for the 3D rows); returns the pairs.
    ``body``, ``cams``: the folded body and cameras; ``obs``: a FrameObs."""
    objective, points, conf, view_off, obs3 = (obs.objective, obs.points, obs.conf,
                                               obs.view_off, obs.obs3)
    parent, marker_joint = body.parent, body.marker_joint
    views = cams.kind
    nv = views.shape[0]
    nm = marker_joint.shape[0]
    nj = parent.shape[0]
    na = angles.shape[0]
    nf = free_idx.shape[0]
    both = objective == OBJ_CLOUD_VIEWS
    nr = 2 * nv * nm + 3 * nm if both else max(2 * nv * nm, 3 * nm)
    pair = np.empty(nv * nm + nm if both else max(nv * nm, nm), np.int64)
    jac = np.zeros((nr, nf))
    res = np.zeros(nr)
    res1 = np.zeros(nr)
    rows = np.empty(nr, np.int64)
    packed = np.zeros(nr)
    proj = np.empty((nv, nm, 2))
    cs = np.empty(na)
    sn = np.empty(na)
    rot = np.empty((nj, 3, 3))
    pos = np.empty((nj, 3))
    mk = np.empty((nm, 3))
    jtr = np.empty(nf)
    pk = np.empty(nr + 1, np.int64)
    span = entry_spans(free_idx, parent, body.elem_axis, body.elem_index, body.slide_index,
                       marker_joint)
    saved = np.empty_like(rot), np.empty_like(pos), np.empty_like(mk), np.empty_like(proj)
    project_posture(angles, root_pos, root_rot, body, cams, cs, sn, rot, pos, mk, proj)
    n_pairs = assign_pairs(objective, proj, mk, points, conf, view_off, obs3, gate, pair)
    info[:, :] = 0.0
    if n_pairs == 0:
        return 0
    fill_residuals(objective, proj, mk, points, conf, obs3, pair, res)
    n_rows = pair_rows(objective, pair, nv, nm, rows)
    packed_index(rows, n_rows, pk)
    jacobian(angles, free_idx, span, root_pos, root_rot, body, cams, views, obs, pair, rows, pk,
             res, res1, cs, sn, rot, pos, mk, proj, saved, has_pinhole(views), jac)
    for kk in range(n_rows):  # rows in units of their σ
        w = row_scale[row_view(objective, nv, nm, rows[kk])]
        for q in range(nf):
            jac[kk, q] *= w
    normal_equations(objective, nv, nm, span, pk, jac, packed, info, jtr)
    return n_pairs


@njit(cache=True, nogil=True, parallel=True)
def information_frames(angles, root_pos, root_rot, body, cams, free_idx, gate, obs,
                       row_scale, out_info, out_pairs):
    """:func:`posture_information` of many frames in parallel: ``angles`` (n, n_state),
    ``root_pos`` (n, n_chains, 3), ``root_rot`` (n, n_chains, 3, 3), ``body``, ``cams``
    and ``obs`` the namedtuples of ``fit_frames``; ``out_info`` (n, n_free, n_free),
    ``out_pairs`` (n,). Rows holding NaN get no pairs and zero information."""
    nv = cams.kind.shape[0]
    for f in prange(angles.shape[0]):
        out_pairs[f] = 0
        if np.isfinite(angles[f, 0]):
            out_pairs[f] = posture_information(
                angles[f], free_idx, gate, root_pos[f], root_rot[f], body, cams,
                frame_obs(obs, f, nv), row_scale, out_info[f])
        else:
            out_info[f] = 0.0
