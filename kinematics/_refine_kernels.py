"""numba kernels of local refinement after annealing (private; the public wrapper is
:mod:`kinematics.refine`, the scipy twin :func:`kinematics.refine.refine_reference`).

Refinement is Levenberg-Marquardt on the pairs (model marker i in view v, its nearest
detection), kept only within a distance gate so ghosts and occluded markers drop out.
Residuals are ``p_i^v - d^v`` (two per pair); the Jacobian is taken by forward differences
of :func:`kinematics._anneal_kernels.project_posture`; steps are clipped to the axis ranges
and never touch locked axes; pairs are re-assigned after every accepted step (as in ICP).
For Gaussian centroid noise this is the maximum-likelihood posture given the pairs, which
annealing on the sum of distances (Eq. 5) only approaches. Body and cameras in the folded
layout of :mod:`kinematics._anneal_kernels`, whose ``fit_frames`` calls
:func:`refine_posture` on every annealing run when refinement is on.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from kinematics._anneal_kernels import DOF_HISTOGRAM, project_posture, solve_spd

#: Forward-difference step of the Jacobian, radians.
FD_STEP = 1e-7
#: Damped steps tried per Jacobian before refinement gives up (damping x4 each).
MAX_DAMPING_TRIES = 8
#: Refinement stops once a step lowers the cost by less than this fraction.
CONVERGED = 1e-9


@njit(cache=True, nogil=True, inline="always")
def _wrap_clip(x, lo, hi):
    """Project angle x (radians) into [lo, hi], using the 2π-equivalent nearest the range;
    ranges of a full turn are not clipped."""
    if hi - lo >= 2.0 * np.pi - 1e-12:
        return x
    c = 0.5 * (lo + hi)
    x = x + 2.0 * np.pi * np.round((c - x) / (2.0 * np.pi))
    return min(max(x, lo), hi)


@njit(cache=True, nogil=True)
def assign_pairs(proj, points, view_off, gate, pair):
    """``pair[v * nm + i]`` = index of marker i's nearest detection in view v if within
    ``gate`` pixels, else -1; returns the number of pairs."""
    nv = proj.shape[0]
    nm = proj.shape[1]
    n = 0
    g2 = gate * gate
    for v in range(nv):
        for i in range(nm):
            best = np.inf
            arg = -1
            for c in range(view_off[v], view_off[v + 1]):
                dx = proj[v, i, 0] - points[c, 0]
                dy = proj[v, i, 1] - points[c, 1]
                d2 = dx * dx + dy * dy
                if d2 < best:
                    best = d2
                    arg = c
            ok = arg >= 0 and best <= g2
            pair[v * nm + i] = arg if ok else -1
            n += 1 if ok else 0
    return n


@njit(cache=True, nogil=True)
def pair_cost(proj, points, pair):
    """Sum of squared residuals over the pairs of :func:`assign_pairs`."""
    nm = proj.shape[1]
    s = 0.0
    for k in range(pair.shape[0]):
        c = pair[k]
        if c >= 0:
            dx = proj[k // nm, k % nm, 0] - points[c, 0]
            dy = proj[k // nm, k % nm, 1] - points[c, 1]
            s += dx * dx + dy * dy
    return s


@njit(cache=True, nogil=True)
def refine_posture(angles, free_idx, lo, hi, dof_kind, n_steps, gate, root_pos, root_rot,
                   parent, chain, pre_rot,
                   pre_trans, post_trans, elem_axis, elem_index, joint_flags, marker_joint,
                   marker_local, slide_index, kind, P, K, dist, R, t, points, view_off):
    """Levenberg-Marquardt refinement of ``angles`` (n_axes,) radians, in place.

    Minimises ``sum |p_i^v(angles) - d_pair(i, v)|^2`` over marker/detection pairs within
    ``gate`` pixels, for at most ``n_steps`` accepted steps; free axes ``free_idx`` move
    within ``[lo, hi]`` (radians, clipped), the others never.

    Returns
    -------
    sse : float
        Final sum of squared pair residuals (pixels²).
    n_pairs : int
        Pairs used at the end (0: angles unchanged).
    """
    nv = kind.shape[0]
    nm = marker_joint.shape[0]
    nj = parent.shape[0]
    na = angles.shape[0]
    nf = free_idx.shape[0]
    nr = 2 * nv * nm
    pair = np.empty(nv * nm, np.int64)
    jac = np.zeros((nr, nf))
    res = np.zeros(nr)
    base = np.empty((nv, nm, 2))
    proj = np.empty((nv, nm, 2))
    cs = np.empty(na)
    sn = np.empty(na)
    rot = np.empty((nj, 3, 3))
    pos = np.empty((nj, 3))
    mk = np.empty((nm, 3))
    trial = angles.copy()
    a = np.empty((nf, nf))
    g = np.empty(nf)
    project_posture(angles, root_pos, root_rot, parent, chain, pre_rot, pre_trans, post_trans,
                    elem_axis, elem_index, joint_flags, marker_joint, marker_local, slide_index,
                    kind, P, K, dist, R, t, cs, sn, rot, pos, mk, base)
    n_pairs = assign_pairs(base, points, view_off, gate, pair)
    cost = pair_cost(base, points, pair)
    lam = 1e-3
    step = 0
    while step < n_steps and n_pairs > 0 and cost > 0.0:
        for k in range(nv * nm):
            c = pair[k]
            res[2 * k] = base[k // nm, k % nm, 0] - points[c, 0] if c >= 0 else 0.0
            res[2 * k + 1] = base[k // nm, k % nm, 1] - points[c, 1] if c >= 0 else 0.0
        for q in range(nf):
            i = free_idx[q]
            x = angles[i]
            angles[i] = x + FD_STEP
            project_posture(angles, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                            post_trans, elem_axis, elem_index, joint_flags, marker_joint,
                            marker_local, slide_index, kind, P, K, dist, R, t, cs, sn, rot, pos,
                            mk, proj)
            angles[i] = x
            for k in range(nv * nm):
                on = pair[k] >= 0
                v = k // nm
                m = k % nm
                jac[2 * k, q] = (proj[v, m, 0] - base[v, m, 0]) / FD_STEP if on else 0.0
                jac[2 * k + 1, q] = (proj[v, m, 1] - base[v, m, 1]) / FD_STEP if on else 0.0
        # Damped Gauss-Newton steps with growing damping until one lowers the cost.
        improved = False
        tries = 0
        while not improved and tries < MAX_DAMPING_TRIES:
            for r in range(nf):
                s = 0.0
                for k in range(nr):
                    s -= jac[k, r] * res[k]
                g[r] = s
                for c in range(nf):
                    s = 0.0
                    for k in range(nr):
                        s += jac[k, r] * jac[k, c]
                    a[r, c] = s
                a[r, r] += lam * a[r, r] + 1e-12
            solve_spd(a, g, nf)
            for q in range(nf):
                i = free_idx[q]
                x = angles[i] + g[q]
                trial[i] = (_wrap_clip(x, lo[i], hi[i]) if dof_kind[i] == DOF_HISTOGRAM
                            else min(max(x, lo[i]), hi[i]))
            project_posture(trial, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                            post_trans, elem_axis, elem_index, joint_flags, marker_joint,
                            marker_local, slide_index, kind, P, K, dist, R, t, cs, sn, rot, pos,
                            mk, proj)
            c_trial = pair_cost(proj, points, pair)
            improved = c_trial < cost
            lam = max(lam / 3.0, 1e-9) if improved else lam * 4.0
            tries += 1
        if improved:
            converged = cost - c_trial <= CONVERGED * cost
            for q in range(nf):
                angles[free_idx[q]] = trial[free_idx[q]]
            base[:] = proj
            n_pairs = assign_pairs(base, points, view_off, gate, pair)
            cost = pair_cost(base, points, pair)
            step = n_steps if converged else step + 1
        else:
            step = n_steps  # converged: no damped step lowers the cost
    return cost, n_pairs


@njit(cache=True, nogil=True, parallel=True)
def refine_frames(angles, det_points, det_off, root_pos, root_rot, free_idx, lo, hi, dof_kind,
                  n_steps, gate,
                  parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index,
                  joint_flags, marker_joint, marker_local, slide_index, kind, P, K, dist, R, t,
                  out_sse, out_pairs):
    """:func:`refine_posture` for many frames in parallel, in place: ``angles`` (n, n_axes)
    radians, detections as in ``fit_frames``, ``root_pos`` (n, n_chains, 3). Rows holding
    NaN are skipped. Writes ``out_sse`` (n,) and ``out_pairs`` (n,) int64."""
    nv = kind.shape[0]
    for f in prange(angles.shape[0]):
        out_sse[f] = np.nan
        out_pairs[f] = 0
        if np.isfinite(angles[f, 0]):
            vo = det_off[f * nv: f * nv + nv + 1]
            out_sse[f], out_pairs[f] = refine_posture(
                angles[f], free_idx, lo, hi, dof_kind, n_steps, gate, root_pos[f], root_rot[f],
                parent, chain,
                pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
                marker_joint, marker_local, slide_index, kind, P, K, dist, R, t, det_points, vo)
