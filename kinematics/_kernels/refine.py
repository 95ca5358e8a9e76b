"""numba kernels of local refinement after annealing (private; the public wrapper is
:mod:`kinematics.fit.refine`, the scipy twin :func:`kinematics.fit.refine.refine_reference`).

Refinement is Levenberg-Marquardt on the pairs (model marker i in view v, its nearest
detection), kept only within a distance gate so ghosts and occluded markers drop out.
Residuals are ``p_i^v - d^v`` (two per pair); the Jacobian is taken by forward differences
of :func:`kinematics._kernels.posture.project_posture`; steps are clipped to the axis ranges
and never touch locked axes; pairs are re-assigned after every accepted step (as in ICP).
For Gaussian centroid noise this is the maximum-likelihood posture given the pairs, which
annealing on the sum of distances (Eq. 5) only approaches. Body and cameras in the folded
layout of :mod:`kinematics._kernels.posture`; :func:`kinematics._kernels.frames.fit_frames` calls
:func:`refine_posture` on every annealing run when refinement is on.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from kinematics._kernels.codes import (
    DOF_HISTOGRAM,
    NO_CLAIMS,
    OBJ_CLOUD,
    OBJ_CLOUD_ONE,
    OBJ_CLOUD_VIEWS,
    OBJ_LABELLED,
    OBJ_POINTS3D,
)
from kinematics._kernels.error2d import one_to_one, point_of
from kinematics._kernels.error3d import cloud_nearest
from kinematics._kernels.fastmath import sincos, solve_spd
from kinematics._kernels.posture import (
    has_pinhole,
    hidden_in,
    posture_frames,
    posture_markers,
    project_posture,
)
from kinematics._kernels.records import frame_obs

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
def assign_pairs(objective, proj, mk, points, conf, view_off, obs3, gate, pair):
    """Pairs of model markers and observations within ``gate``; returns their number.

    Unlabelled points (``OBJ_NEAREST``): ``pair[v * nm + i]`` = index of marker i's nearest
    detection in view v, none where it is hidden
    (:func:`kinematics._kernels.posture.hidden_in`). Labelled keypoints: the row of marker
    i's own keypoint in view v (if present, with confidence > 0). 3D points: ``pair[i] =
    i`` where marker i's point is present. Unlabelled 3D points (``OBJ_CLOUD``):
    ``pair[i]`` = the row of marker i's nearest cloud point (px-equivalents, as
    :func:`kinematics._kernels.error3d.cloud_error`); with ``OBJ_CLOUD_ONE`` each point
    pairs with one marker at most (:func:`kinematics._kernels.error2d.one_to_one`), so a
    marker whose own point is missing does not take a neighbour's; ``OBJ_CLOUD_VIEWS``
    pairs as ``OBJ_CLOUD_ONE``, and a marker left without a point with its nearest
    detection in each view among those within their own gate, ``conf`` (px):
    ``pair[nm + v * nm + i]`` (its point is missing where its blob fused with another in
    one view, and the other views still place it). -1 marks no pair (farther than
    ``gate``: pixels, or length units for labelled 3D).
    """
    nv = proj.shape[0]
    nm = mk.shape[0]
    n = 0
    g2 = gate * gate
    pair[:] = -1
    if objective in (OBJ_CLOUD, OBJ_CLOUD_ONE, OBJ_CLOUD_VIEWS):
        one = objective != OBJ_CLOUD
        for i in range(nm):
            _, pair[i] = cloud_nearest(mk, i, obs3, NO_CLAIMS)
        if one:  # losers hold -(the point they took instead + 2)
            one_to_one(mk, obs3, 0, obs3.shape[0], 0, nm, True, NO_CLAIMS, np.inf, pair)
        for i in range(nm):
            c = point_of(pair[i])
            ok = c >= 0
            if ok:
                s = obs3[c, 3]
                dx = mk[i, 0] - obs3[c, 0]
                dy = mk[i, 1] - obs3[c, 1]
                dz = mk[i, 2] - obs3[c, 2]
                ok = s * s * (dx * dx + dy * dy + dz * dz) <= g2
            # one_to_one lets two losers take the same spare point: the first keeps it
            for j in range(i if one and ok else 0):
                ok = ok and pair[j] != c
            pair[i] = c if ok else -1
            n += 1 if ok else 0
        if objective == OBJ_CLOUD_VIEWS:
            for v in range(nv):
                for i in range(nm):
                    if pair[i] < 0:
                        arg = _nearest_in_gate(proj, v, i, points, conf, view_off[v],
                                               view_off[v + 1])
                        pair[nm + v * nm + i] = arg
                        n += 1 if arg >= 0 else 0
        return n
    if objective == OBJ_POINTS3D:
        for i in range(nm):
            d2 = 0.0
            for k in range(3):
                d2 += (mk[i, k] - obs3[i, k]) ** 2
            if obs3[i, 3] > 0.0 and d2 <= g2:  # NaN compares false: missing points drop out
                pair[i] = i
                n += 1
        return n
    for v in range(nv):
        a = view_off[v]
        b = view_off[v + 1]
        for i in range(nm):
            arg = -1
            if objective == OBJ_LABELLED:
                if b - a == nm and conf[a + i] > 0.0:
                    d2 = (proj[v, i, 0] - points[a + i, 0]) ** 2 + (
                        proj[v, i, 1] - points[a + i, 1]) ** 2
                    arg = a + i if d2 <= g2 else -1
            elif not hidden_in(obs3, i, v):
                arg = _nearest_within(proj, v, i, points, a, b, g2)
            pair[v * nm + i] = arg
            n += 1 if arg >= 0 else 0
    return n


@njit(cache=True, nogil=True, inline="always")
def _nearest_in_gate(proj, v, i, points, gates, a, b):
    """The row of ``a:b`` nearest marker i's projection in view v among those within their
    own ``gates`` (px); -1 if none. (:func:`_nearest_within`, one gate, is its own loop: one
    helper for both made the locust's refinement 7 % slower.)"""
    best = np.inf
    arg = -1
    for c in range(a, b):
        dx = proj[v, i, 0] - points[c, 0]
        dy = proj[v, i, 1] - points[c, 1]
        d2 = dx * dx + dy * dy
        if d2 < best and d2 <= gates[c] * gates[c]:
            best = d2
            arg = c
    return arg


@njit(cache=True, nogil=True, inline="always")
def _nearest_within(proj, v, i, points, a, b, g2):
    """The row of ``a:b`` nearest marker i's projection in view v, -1 beyond ``sqrt(g2)``."""
    best = np.inf
    arg = -1
    for c in range(a, b):
        dx = proj[v, i, 0] - points[c, 0]
        dy = proj[v, i, 1] - points[c, 1]
        d2 = dx * dx + dy * dy
        if d2 < best:
            best = d2
            arg = c
    return arg if best <= g2 else -1


@njit(cache=True, nogil=True)
def fill_residuals(objective, proj, mk, points, conf, obs3, pair, res):
    """Residuals of the pairs of :func:`assign_pairs` into ``res`` (zero where unpaired;
    weighted by the square root of the confidence); returns their sum of squares."""
    res[:] = 0.0
    return fill_rows(objective, proj, mk, points, conf, obs3, pair, res, 0, mk.shape[0])


@njit(cache=True, nogil=True)
def fill_rows(objective, proj, mk, points, conf, obs3, pair, res, m0, m1):
    """The rows of :func:`fill_residuals` of markers ``m0:m1`` only (zero where unpaired; the
    other rows untouched); returns their sum of squares."""
    s = 0.0
    nm = mk.shape[0]
    off = 0  # the rows and pairs before the views' (OBJ_CLOUD_VIEWS: the cloud's)
    if objective in (OBJ_POINTS3D, OBJ_CLOUD, OBJ_CLOUD_ONE, OBJ_CLOUD_VIEWS):
        for i in range(m0, m1):
            c = pair[i]
            for k in range(3):
                res[3 * i + k] = 0.0
            if c >= 0:  # a cloud point's weight is its px per unit, labelled ones' a variance
                w = np.sqrt(obs3[c, 3]) if objective == OBJ_POINTS3D else obs3[c, 3]
                for k in range(3):
                    r = w * (mk[i, k] - obs3[c, k])
                    res[3 * i + k] = r
                    s += r * r
        if objective != OBJ_CLOUD_VIEWS:
            return s
        off = nm
    for v in range(proj.shape[0]):
        for m in range(m0, m1):
            k = v * nm + m
            c = pair[off + k]
            rx = ry = 0.0
            if c >= 0:
                w = np.sqrt(conf[c]) if objective == OBJ_LABELLED else 1.0
                rx = w * (proj[v, m, 0] - points[c, 0])
                ry = w * (proj[v, m, 1] - points[c, 1])
                s += rx * rx + ry * ry
            res[3 * off + 2 * k] = rx
            res[3 * off + 2 * k + 1] = ry
    return s


@njit(cache=True, nogil=True)
def entry_spans(free_idx, parent, elem_axis, elem_index, slide_index, marker_joint):
    """(n_free, 4) ``(j0, j1, m0, m1)`` per free state entry: the joints and markers it
    moves, its joint's subtree (contiguous in depth-first order) and that subtree's markers;
    the whole body where the joints or markers are not in that order (always correct:
    recomputing an unmoved joint or marker changes nothing)."""
    nj, nm, nf = parent.shape[0], marker_joint.shape[0], free_idx.shape[0]
    end = np.arange(1, nj + 1)  # one past each joint's subtree, if depth-first
    for j in range(nj - 1, -1, -1):
        if parent[j] >= 0:
            end[parent[j]] = max(end[parent[j]], end[j])
    ordered = True
    for j in range(nj):
        ordered = ordered and parent[j] < j
        for k in range(j + 1, end[j]):  # a subtree holds only descendants
            ordered = ordered and j <= parent[k] < k
    out = np.empty((nf, 4), np.int64)
    for q in range(nf):
        i = free_idx[q]
        owner = -1
        for j in range(nj):
            for e in range(3):
                if elem_axis[j, e] >= 0 and elem_index[j, e] == i:
                    owner = j
            if slide_index[j] >= 0 and slide_index[j] <= i < slide_index[j] + 3:
                owner = j
        out[q, 0], out[q, 1], out[q, 2], out[q, 3] = 0, nj, 0, nm
        if ordered and owner >= 0:
            m0, m1, inside = nm, 0, 0
            for m in range(nm):
                if owner <= marker_joint[m] < end[owner]:
                    m0, m1, inside = min(m0, m), max(m1, m + 1), inside + 1
            out[q, 0], out[q, 1] = owner, end[owner]
            if inside == 0:
                out[q, 2], out[q, 3] = 0, 0
            elif inside == m1 - m0:  # contiguous
                out[q, 2], out[q, 3] = m0, m1
    return out


@njit(cache=True, nogil=True, inline="always")
def _row_block(objective, nv, nm, a, b, k):
    """The k-th contiguous block of residual rows (:func:`fill_residuals`' layout) of markers
    ``a:b``: the 3D rows first (objectives with 3D points), then one block per view; ``(0,
    0)`` past the last."""
    has3d = objective in (OBJ_POINTS3D, OBJ_CLOUD, OBJ_CLOUD_ONE, OBJ_CLOUD_VIEWS)
    if has3d:
        if k == 0:
            return 3 * a, 3 * b
        if objective != OBJ_CLOUD_VIEWS:
            return 0, 0
        k -= 1
    if k >= nv:
        return 0, 0
    base = 3 * nm if has3d else 0
    return base + 2 * (k * nm + a), base + 2 * (k * nm + b)


@njit(cache=True, nogil=True, inline="always")
def row_view(objective, nv, nm, row):
    """The view of residual ``row`` (:func:`fill_residuals`' layout); ``nv`` for a 3D row."""
    if objective in (OBJ_POINTS3D, OBJ_CLOUD, OBJ_CLOUD_ONE):
        return nv
    base = 3 * nm if objective == OBJ_CLOUD_VIEWS else 0
    return nv if row < base else (row - base) // (2 * nm)


@njit(cache=True, nogil=True)
def pair_rows(objective, pair, nv, nm, rows):
    """The residual rows of :func:`fill_residuals` that the pairs fill, in order, into
    ``rows``; returns their number (the other rows are zero and are skipped)."""
    n = 0
    off = 0
    if objective in (OBJ_POINTS3D, OBJ_CLOUD, OBJ_CLOUD_ONE, OBJ_CLOUD_VIEWS):
        for i in range(nm):
            if pair[i] >= 0:
                for k in range(3):
                    rows[n] = 3 * i + k
                    n += 1
        if objective != OBJ_CLOUD_VIEWS:
            return n
        off = nm
    for k in range(nv * nm):
        if pair[off + k] >= 0:
            rows[n] = 3 * off + 2 * k
            rows[n + 1] = 3 * off + 2 * k + 1
            n += 2
    return n


@njit(cache=True, nogil=True)
def packed_index(rows, n_rows, pk):
    """``pk[row]``: how many of the used ``rows[:n_rows]`` (ascending) come before original
    row ``row``, for row 0..len(pk) - 1."""
    k = 0
    for row in range(pk.shape[0]):
        while k < n_rows and rows[k] < row:
            k += 1
        pk[row] = k


@njit(cache=True, nogil=True)
def jacobian(angles, free_idx, span, root_pos, root_rot, body, cams, views, obs, pair, rows,
             pk, res, res1, cs, sn, rot, pos, mk, proj, saved, pinhole, jac):
    """The Jacobian of the used residual ``rows`` (packed: ``pk``) by forward differences,
    one column per free entry from its subtree ``span`` only, into ``jac``. ``res`` holds
    the residuals at ``angles``; ``rot``, ``pos``, ``mk``, ``proj``, ``cs`` and ``sn`` its
    posture, which they hold again on return (each column's subtree is put back from
    ``saved``: scratch like ``rot``, ``pos``, ``mk``, ``proj``). ``obs``: a FrameObs."""
    objective, points, conf, obs3 = obs.objective, obs.points, obs.conf, obs.obs3
    rot0, pos0, mk0, proj0 = saved
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body  # the loop's arrays (records: refcounts)
    P, K, dist, R, t = cams.P, cams.K, cams.dist, cams.R, cams.t
    any_pinhole = pinhole
    nv = proj.shape[0]
    nm = mk.shape[0]
    nb = nv + 1  # row blocks of a marker range at most (:func:`_row_block`)
    rot0[:], pos0[:], mk0[:], proj0[:] = rot, pos, mk, proj
    for q in range(free_idx.shape[0]):
        i = free_idx[q]
        j0, j1, m0, m1 = span[q, 0], span[q, 1], span[q, 2], span[q, 3]
        x, s0, c0 = angles[i], sn[i], cs[i]
        angles[i] = x + FD_STEP
        sn[i], cs[i] = sincos(angles[i])
        posture_frames(angles, cs, sn, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                       post_trans, elem_axis, elem_index, joint_flags, slide_index, rot,
                       pos, j0, j1)
        posture_markers(marker_joint, marker_local, rot, pos, mk, proj, views, P, K, dist,
                        R, t, any_pinhole, m0, m1, mk[:0])
        angles[i], sn[i], cs[i] = x, s0, c0
        fill_rows(objective, proj, mk, points, conf, obs3, pair, res1, m0, m1)
        for b in range(nb):  # the Jacobian's rows of the pairs, packed
            r0, r1 = _row_block(objective, nv, nm, m0, m1, b)
            for kk in range(pk[r0], pk[r1]):
                jac[kk, q] = (res1[rows[kk]] - res[rows[kk]]) / FD_STEP
        rot[j0:j1], pos[j0:j1] = rot0[j0:j1], pos0[j0:j1]
        mk[m0:m1], proj[:, m0:m1] = mk0[m0:m1], proj0[:, m0:m1]


@njit(cache=True, nogil=True)
def normal_equations(objective, nv, nm, span, pk, jac, packed, jtj, jtr):
    """``jtj`` = J^T J and ``jtr`` = -J^T r of the packed Jacobian ``jac`` and residuals
    ``packed``, each product once (symmetric), over the rows two columns share (their
    ``span``'s markers)."""
    nb = nv + 1
    nf = jtj.shape[0]
    for r in range(nf):
        s = 0.0
        for b in range(nb):
            r0, r1 = _row_block(objective, nv, nm, span[r, 2], span[r, 3], b)
            for k in range(pk[r0], pk[r1]):
                s -= jac[k, r] * packed[k]
        jtr[r] = s
        for c in range(r, nf):
            s = 0.0
            ma, mb = max(span[r, 2], span[c, 2]), min(span[r, 3], span[c, 3])
            if ma < mb:
                for b in range(nb):
                    r0, r1 = _row_block(objective, nv, nm, ma, mb, b)
                    for k in range(pk[r0], pk[r1]):
                        s += jac[k, r] * jac[k, c]
            jtj[r, c] = s
            jtj[c, r] = s


@njit(cache=True, nogil=True)
def refine_posture(angles, free_idx, dofs, n_steps, gate, root_pos, root_rot, body, cams,
                   views, obs):
    """Levenberg-Marquardt refinement of the state ``angles`` (n_state,), in place.

    Minimises the sum of squared pair residuals (:func:`assign_pairs`: marker/detection
    pairs within ``gate`` pixels for unlabelled points, marker/own keypoint for labelled
    ones, marker/own 3D point for 3D points) for at most ``n_steps`` accepted steps; free
    entries ``free_idx`` move within ``[lo, hi]`` (angles wrapped then clipped, other
    entries clipped), the others never.

    Returns
    -------
    sse : float
        Final sum of squared pair residuals (pixels², or squared length units for 3D).
    n_pairs : int
        Pairs used at the end (0: state unchanged).

    ``dofs``: DofArrays (ranges, kinds); ``body``, ``cams``: the folded body and cameras,
    projected into ``views`` (``cams.kind``, or none for a 3D objective); ``obs``: FrameObs.
    """
    lo, hi, dof_kind = dofs.lo, dofs.hi, dofs.dof_kind
    objective, points, conf, view_off, obs3 = (obs.objective, obs.points, obs.conf,
                                               obs.view_off, obs.obs3)
    parent, marker_joint = body.parent, body.marker_joint
    nv = views.shape[0]
    nm = marker_joint.shape[0]
    nj = parent.shape[0]
    na = angles.shape[0]
    nf = free_idx.shape[0]
    both = objective == OBJ_CLOUD_VIEWS  # rows and pairs of the cloud, then of the views
    nr = 2 * nv * nm + 3 * nm if both else max(2 * nv * nm, 3 * nm)
    pair = np.empty(nv * nm + nm if both else max(nv * nm, nm), np.int64)
    jac = np.zeros((nr, nf))
    res = np.zeros(nr)
    res1 = np.zeros(nr)
    rows = np.empty(nr, np.int64)
    packed = np.empty(nr)  # the residuals of those rows
    proj = np.empty((nv, nm, 2))
    cs = np.empty(na)
    sn = np.empty(na)
    rot = np.empty((nj, 3, 3))
    pos = np.empty((nj, 3))
    mk = np.empty((nm, 3))
    trial = angles.copy()
    jtj = np.empty((nf, nf))
    jtr = np.empty(nf)
    a = np.empty((nf, nf))
    g = np.empty(nf)
    # Each free entry moves only its joint's subtree: its Jacobian column is computed from
    # that subtree's joints and markers and is zero elsewhere, and J^T J sums only the rows
    # two columns share (a fly's six legs: a sixth of the work; the sums' order, and so
    # every bit of the result, as over all rows)
    span = entry_spans(free_idx, parent, body.elem_axis, body.elem_index, body.slide_index,
                       marker_joint)
    pinhole = has_pinhole(views)
    saved = np.empty_like(rot), np.empty_like(pos), np.empty_like(mk), np.empty_like(proj)
    pk = np.empty(nr + 1, np.int64)  # pk[row]: the used rows before original row ``row``
    project_posture(angles, root_pos, root_rot, body, cams, cs, sn, rot, pos, mk, proj)
    n_pairs = assign_pairs(objective, proj, mk, points, conf, view_off, obs3, gate, pair)
    cost = fill_residuals(objective, proj, mk, points, conf, obs3, pair, res)
    # The rows used: for OBJ_CLOUD_VIEWS those of the pairs (most rows are a view's of a
    # marker with a point: zero), else every row (packing them made the locust's
    # refinement 20 % slower: it has few unpaired rows to skip)
    n_rows = nr
    for k in range(nr):
        rows[k] = k
    if both:
        n_rows = pair_rows(objective, pair, nv, nm, rows)
    lam = 1e-3
    step = 0
    while step < n_steps and n_pairs > 0 and cost > 0.0:
        packed_index(rows, n_rows, pk)
        jacobian(angles, free_idx, span, root_pos, root_rot, body, cams, views, obs, pair, rows,
                 pk, res, res1, cs, sn, rot, pos, mk, proj, saved, pinhole, jac)
        for kk in range(n_rows):
            packed[kk] = res[rows[kk]]
        normal_equations(objective, nv, nm, span, pk, jac, packed, jtj, jtr)
        # Damped Gauss-Newton steps with growing damping until one lowers the cost.
        improved = False
        tries = 0
        c_trial = cost
        while not improved and tries < MAX_DAMPING_TRIES:
            a[:, :] = jtj
            g[:] = jtr
            for r in range(nf):
                a[r, r] += lam * a[r, r] + 1e-12
            solve_spd(a, g, nf)
            for q in range(nf):
                i = free_idx[q]
                x = angles[i] + g[q]
                trial[i] = (_wrap_clip(x, lo[i], hi[i]) if dof_kind[i] == DOF_HISTOGRAM
                            else min(max(x, lo[i]), hi[i]))
            project_posture(trial, root_pos, root_rot, body, cams, cs, sn, rot, pos, mk, proj)
            c_trial = fill_residuals(objective, proj, mk, points, conf, obs3, pair, res1)
            improved = c_trial < cost
            lam = max(lam / 3.0, 1e-9) if improved else lam * 4.0
            tries += 1
        if improved:
            converged = cost - c_trial <= CONVERGED * cost
            for q in range(nf):
                angles[free_idx[q]] = trial[free_idx[q]]
            n_pairs = assign_pairs(objective, proj, mk, points, conf, view_off, obs3, gate,
                                   pair)
            cost = fill_residuals(objective, proj, mk, points, conf, obs3, pair, res)
            if both:
                n_rows = pair_rows(objective, pair, nv, nm, rows)
            step = n_steps if converged else step + 1
        else:
            step = n_steps  # converged: no damped step lowers the cost
    return cost, n_pairs


@njit(cache=True, nogil=True, parallel=True)
def refine_frames(angles, root_pos, root_rot, body, cams, dofs, n_steps, gate, obs, out_sse,
                  out_pairs):
    """:func:`refine_posture` for many frames in parallel, in place: ``angles`` (n, n_state),
    ``root_pos`` (n, n_chains, 3), ``root_rot`` (n, n_chains, 3, 3); ``body``, ``cams``,
    ``dofs`` and ``obs`` the namedtuples of ``fit_frames``. Rows holding NaN are skipped.
    Writes ``out_sse`` (n,) and ``out_pairs`` (n,) int64."""
    nv = cams.kind.shape[0]
    for f in prange(angles.shape[0]):
        out_sse[f] = np.nan
        out_pairs[f] = 0
        if np.isfinite(angles[f, 0]):
            out_sse[f], out_pairs[f] = refine_posture(
                angles[f], dofs.free_idx, dofs, n_steps, gate, root_pos[f], root_rot[f], body,
                cams, cams.kind, frame_obs(obs, f, nv))
