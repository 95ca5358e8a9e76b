"""numba lane kernels, one annealing iteration of every lane (private; the procedure that
drives them is :mod:`kinematics._kernels.lanes`, whose docstring says what LLVM vectorises
and why these loops are written as they are): forward kinematics, projection and E of every
lane's candidate for each objective, the histogram's allowed runs, and the iterations."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from kinematics._kernels.anneal import hist_at
from kinematics._kernels.camera import ORTHOGRAPHIC
from kinematics._kernels.codes import NAN_MARKER_COST, ROOT_POSE
from kinematics._kernels.fastmath import log_unit, next_uniform, sincos
from kinematics._kernels.posture import mul33

_ALL_OK = np.uint64(0x0101010101010101)  # eight True bools read as one word

LANE_OPTS = {"cache": True, "nogil": True, "error_model": "numpy"}


@njit(**LANE_OPTS)
def sincos_lanes(x, s, c):
    """Fill ``s``, ``c`` with the kernels' ``sincos`` of ``x`` in a loop as the lanes run it
    (for tests)."""
    for k in range(x.shape[0]):
        s[k], c[k] = sincos(x[k])


# -- forward kinematics and projection of all lanes ----------------------------------------
@njit(inline="always", **LANE_OPTS)
def project_lanes(vals, cs, sn, parent, chain, pre_rot, pre_trans, post_trans, elem_axis,
                  elem_index, joint_flags, marker_joint, marker_local, slide_index, kind, P, K,
                  dist, R, t, rot, pos, mk, proj):
    """Markers of every lane's posture projected into every view (the scalar
    ``project_cs`` per lane, the same values to the last bit): fills ``proj``
    (nv, nm, 2, L), ``rot`` (nj + n_chains, 9, L), ``pos`` (nj + n_chains, 3, L) and ``mk``.
    Rows ``nj + c`` of ``rot`` and ``pos`` hold chain c's root: each lane's seed rotation
    (the identity for a root without one) and root position, set when a run is loaded.

    LLVM vectorises a loop over lanes only if it has no branch around a load, at most nine
    stores and its loads before its stores; and an array view (``rot[j]``) costs atomic
    reference counts. So every loop below indexes whole arrays, roots read their slot rows
    instead of branching, and the scalar kernel's shortcuts (identity G_j, zero h_j) are
    full products here, which give the same numbers exactly for finite values.
    """
    nl = vals.shape[1]  # a run-time count: LLVM vectorises the loops instead of unrolling
    nj = parent.shape[0]
    for j in range(nj):
        p = parent[j]
        m00, m01, m02 = pre_rot[j, 0, 0], pre_rot[j, 0, 1], pre_rot[j, 0, 2]
        m10, m11, m12 = pre_rot[j, 1, 0], pre_rot[j, 1, 1], pre_rot[j, 1, 2]
        m20, m21, m22 = pre_rot[j, 2, 0], pre_rot[j, 2, 1], pre_rot[j, 2, 2]
        q = p if p >= 0 else nj + chain[j]  # the parent's A' and p (or the root's slot)
        # A'_j = A'_q · G_j
        for ln in range(nl):
            q00, q01, q02 = rot[q, 0, ln], rot[q, 1, ln], rot[q, 2, ln]
            q10, q11, q12 = rot[q, 3, ln], rot[q, 4, ln], rot[q, 5, ln]
            q20, q21, q22 = rot[q, 6, ln], rot[q, 7, ln], rot[q, 8, ln]
            b00, b01, b02, b10, b11, b12, b20, b21, b22 = mul33(
                q00, q01, q02, q10, q11, q12, q20, q21, q22, m00, m01, m02, m10, m11, m12,
                m20, m21, m22)
            rot[j, 0, ln], rot[j, 1, ln], rot[j, 2, ln] = b00, b01, b02
            rot[j, 3, ln], rot[j, 4, ln], rot[j, 5, ln] = b10, b11, b12
            rot[j, 6, ln], rot[j, 7, ln], rot[j, 8, ln] = b20, b21, b22
        # each rotation about world axis a mixes two columns of A'_j (x: 1, 2; y: 2, 0;
        # z: 0, 1), in place, as the scalar kernel does
        for e in range(3):
            a = elem_axis[j, e]
            if a >= 0:
                i = elem_index[j, e]
                u = 1 if a == 0 else (2 if a == 1 else 0)
                w = 2 if a == 0 else (0 if a == 1 else 1)
                for ln in range(nl):
                    c = cs[i, ln]
                    s = sn[i, ln]
                    u0, w0 = rot[j, u, ln], rot[j, w, ln]
                    u1, w1 = rot[j, 3 + u, ln], rot[j, 3 + w, ln]
                    u2, w2 = rot[j, 6 + u, ln], rot[j, 6 + w, ln]
                    rot[j, u, ln] = c * u0 + s * w0
                    rot[j, w, ln] = c * w0 - s * u0
                    rot[j, 3 + u, ln] = c * u1 + s * w1
                    rot[j, 3 + w, ln] = c * w1 - s * u1
                    rot[j, 6 + u, ln] = c * u2 + s * w2
                    rot[j, 6 + w, ln] = c * w2 - s * u2
        # p_j = p_parent + A'_parent · g_j + A'_j · h_j; a root: its position, moved by the
        # state's translation entries if it is free
        g0, g1, g2 = pre_trans[j, 0], pre_trans[j, 1], pre_trans[j, 2]
        h0, h1, h2 = post_trans[j, 0], post_trans[j, 1], post_trans[j, 2]
        if p >= 0:
            for ln in range(nl):
                px = pos[p, 0, ln] + rot[p, 0, ln] * g0 + rot[p, 1, ln] * g1 + rot[p, 2, ln] * g2
                py = pos[p, 1, ln] + rot[p, 3, ln] * g0 + rot[p, 4, ln] * g1 + rot[p, 5, ln] * g2
                pz = pos[p, 2, ln] + rot[p, 6, ln] * g0 + rot[p, 7, ln] * g1 + rot[p, 8, ln] * g2
                px = px + (rot[j, 0, ln] * h0 + rot[j, 1, ln] * h1 + rot[j, 2, ln] * h2)
                py = py + (rot[j, 3, ln] * h0 + rot[j, 4, ln] * h1 + rot[j, 5, ln] * h2)
                pz = pz + (rot[j, 6, ln] * h0 + rot[j, 7, ln] * h1 + rot[j, 8, ln] * h2)
                pos[j, 0, ln] = px
                pos[j, 1, ln] = py
                pos[j, 2, ln] = pz
        elif joint_flags[j] & ROOT_POSE:
            k = slide_index[j]
            for ln in range(nl):
                px = pos[q, 0, ln] + vals[k, ln]
                py = pos[q, 1, ln] + vals[k + 1, ln]
                pz = pos[q, 2, ln] + vals[k + 2, ln]
                px = px + (rot[j, 0, ln] * h0 + rot[j, 1, ln] * h1 + rot[j, 2, ln] * h2)
                py = py + (rot[j, 3, ln] * h0 + rot[j, 4, ln] * h1 + rot[j, 5, ln] * h2)
                pz = pz + (rot[j, 6, ln] * h0 + rot[j, 7, ln] * h1 + rot[j, 8, ln] * h2)
                pos[j, 0, ln] = px
                pos[j, 1, ln] = py
                pos[j, 2, ln] = pz
        else:
            for ln in range(nl):
                px = pos[q, 0, ln] + (rot[j, 0, ln] * h0 + rot[j, 1, ln] * h1 + rot[j, 2, ln] * h2)
                py = pos[q, 1, ln] + (rot[j, 3, ln] * h0 + rot[j, 4, ln] * h1 + rot[j, 5, ln] * h2)
                pz = pos[q, 2, ln] + (rot[j, 6, ln] * h0 + rot[j, 7, ln] * h1 + rot[j, 8, ln] * h2)
                pos[j, 0, ln] = px
                pos[j, 1, ln] = py
                pos[j, 2, ln] = pz
    nv = kind.shape[0]
    for m in range(marker_joint.shape[0]):
        j = marker_joint[m]
        a0, a1, a2 = marker_local[m, 0], marker_local[m, 1], marker_local[m, 2]
        for ln in range(nl):
            x = pos[j, 0, ln] + rot[j, 0, ln] * a0 + rot[j, 1, ln] * a1 + rot[j, 2, ln] * a2
            y = pos[j, 1, ln] + rot[j, 3, ln] * a0 + rot[j, 4, ln] * a1 + rot[j, 5, ln] * a2
            z = pos[j, 2, ln] + rot[j, 6, ln] * a0 + rot[j, 7, ln] * a1 + rot[j, 8, ln] * a2
            mk[m, 0, ln] = x
            mk[m, 1, ln] = y
            mk[m, 2, ln] = z
        for v in range(nv):
            if kind[v] == ORTHOGRAPHIC:
                p00, p01, p02, p03 = P[v, 0, 0], P[v, 0, 1], P[v, 0, 2], P[v, 0, 3]
                p10, p11, p12, p13 = P[v, 1, 0], P[v, 1, 1], P[v, 1, 2], P[v, 1, 3]
                for ln in range(nl):
                    x, y, z = mk[m, 0, ln], mk[m, 1, ln], mk[m, 2, ln]
                    proj[v, m, 0, ln] = p00 * x + p01 * y + p02 * z + p03
                    proj[v, m, 1, ln] = p10 * x + p11 * y + p12 * z + p13
            else:
                _pinhole_lanes(K, dist, R, t, v, mk, m, proj)


@njit(inline="always", **LANE_OPTS)
def _pinhole_lanes(K, dist, R, t, v, mk, m, proj):
    """``project_point`` of a pinhole camera for every lane (NaN behind the camera)."""
    nl = mk.shape[2]
    r00, r01, r02 = R[v, 0, 0], R[v, 0, 1], R[v, 0, 2]
    r10, r11, r12 = R[v, 1, 0], R[v, 1, 1], R[v, 1, 2]
    r20, r21, r22 = R[v, 2, 0], R[v, 2, 1], R[v, 2, 2]
    t0, t1, t2 = t[v, 0], t[v, 1], t[v, 2]
    k1, k2, p1, p2 = dist[v, 0], dist[v, 1], dist[v, 2], dist[v, 3]
    k3, k4, k5, k6 = dist[v, 4], dist[v, 5], dist[v, 6], dist[v, 7]
    fx, cx, fy, cy = K[v, 0, 0], K[v, 0, 2], K[v, 1, 1], K[v, 1, 2]
    for ln in range(nl):
        x, y, z = mk[m, 0, ln], mk[m, 1, ln], mk[m, 2, ln]
        xc = r00 * x + r01 * y + r02 * z + t0
        yc = r10 * x + r11 * y + r12 * z + t1
        zc = r20 * x + r21 * y + r22 * z + t2
        xn = xc / zc
        yn = yc / zc
        r2 = xn * xn + yn * yn
        radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = xn * radial + 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn)
        yd = yn * radial + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn
        front = zc > 0.0  # also false for NaN
        proj[v, m, 0, ln] = fx * xd + cx if front else np.nan
        proj[v, m, 1, ln] = fy * yd + cy if front else np.nan


# -- Eq. 5 and its variants for all lanes ----------------------------------------------------
@njit(inline="always", **LANE_OPTS)
def error_lanes(proj, dx, dy, ndet, cmax, bidirectional, weight, cap, penalty_cap, nearest,
                ev, best, arg, matched, near, out):
    """E of every lane (the scalar ``projection_error``, same operations in the same order)
    into ``out`` (L,). ``nearest`` (nm, L) int64, ``ev``, ``best`` (L,), ``arg`` (L,) int64,
    ``matched`` (4, L) bool and ``near`` (4, L) are scratch (allocating them here would cost
    more than the arithmetic)."""
    nv = proj.shape[0]
    nm = proj.shape[1]
    missing = cap if cap < np.inf else NAN_MARKER_COST
    nl = out.shape[0]
    for ln in range(nl):
        out[ln] = 0.0
    for v in range(nv):
        for ln in range(nl):
            ev[ln] = 0.0
        cm = cmax[v]
        if cm > 0:
            for i in range(nm):
                for ln in range(nl):
                    best[ln] = np.inf
                    arg[ln] = -1
                c = 0
                while c + 4 <= cm:  # four detections per loop: a fourth of the loop entries
                    for ln in range(nl):
                        px = proj[v, i, 0, ln]
                        py = proj[v, i, 1, ln]
                        b = best[ln]
                        k = arg[ln]
                        for cc in range(c, c + 4):  # unrolled; strict <: the first minimum
                            ex = px - dx[v, cc, ln]
                            ey = py - dy[v, cc, ln]
                            d2 = ex * ex + ey * ey
                            closer = d2 < b
                            b = d2 if closer else b
                            k = cc if closer else k
                        best[ln] = b
                        arg[ln] = k
                    c += 4
                while c < cm:
                    for ln in range(nl):
                        ex = proj[v, i, 0, ln] - dx[v, c, ln]
                        ey = proj[v, i, 1, ln] - dy[v, c, ln]
                        d2 = ex * ex + ey * ey
                        closer = d2 < best[ln]
                        best[ln] = d2 if closer else best[ln]
                        arg[ln] = c if closer else arg[ln]
                    c += 1
                for ln in range(nl):
                    nearest[i, ln] = arg[ln]
                    d = np.sqrt(best[ln]) if arg[ln] >= 0 else missing
                    ev[ln] += min(d, cap)
            if bidirectional:
                c = 0
                while c < cm:
                    # four detections per loop where four are left (a constant count, so the
                    # loop over them unrolls and the loop over lanes vectorises), else one
                    nb = 4 if c + 4 <= cm else 1
                    for ln in range(nl):
                        for q in range(4):
                            matched[q, ln] = False
                            near[q, ln] = np.inf
                    for i in range(nm):
                        if nb == 4:
                            for ln in range(nl):
                                px = proj[v, i, 0, ln]
                                py = proj[v, i, 1, ln]
                                k = nearest[i, ln]
                                for q in range(4):
                                    matched[q, ln] = matched[q, ln] | (k == c + q)
                                    ex = px - dx[v, c + q, ln]
                                    ey = py - dy[v, c + q, ln]
                                    near[q, ln] = min(near[q, ln], ex * ex + ey * ey)
                        else:
                            for ln in range(nl):
                                matched[0, ln] = matched[0, ln] | (nearest[i, ln] == c)
                                ex = proj[v, i, 0, ln] - dx[v, c, ln]
                                ey = proj[v, i, 1, ln] - dy[v, c, ln]
                                near[0, ln] = min(near[0, ln], ex * ex + ey * ey)
                    for ln in range(nl):
                        acc = ev[ln]
                        for q in range(4):
                            d = np.sqrt(near[q, ln]) if near[q, ln] < np.inf else missing
                            add = (q < nb) & (not matched[q, ln]) & (c + q < ndet[v, ln])
                            acc = acc + weight * min(d, penalty_cap) if add else acc
                        ev[ln] = acc
                    c += nb
        for ln in range(nl):
            out[ln] += ev[ln] if ndet[v, ln] > 0 else 0.0


@njit(inline="always", **LANE_OPTS)
def labelled_lanes(proj, dx, dy, dw, ndet, cap, ev, out):
    """Labelled E of every lane (the scalar ``labelled_error``, same operations in the same
    order) into ``out``: model marker i of view v against its own keypoint ``dx, dy [v, i]``
    of weight ``dw [v, i]``; a view's keypoints are the model markers in order, or none
    (``ndet``); a keypoint not finite or of weight <= 0 costs nothing. ``ev`` is scratch."""
    nv = proj.shape[0]
    nm = proj.shape[1]
    missing = cap if cap < np.inf else NAN_MARKER_COST
    nl = out.shape[0]
    for ln in range(nl):
        out[ln] = 0.0
    for v in range(nv):
        for ln in range(nl):
            ev[ln] = 0.0
        for i in range(nm):
            for ln in range(nl):
                w = dw[v, i, ln]
                kx = dx[v, i, ln]
                ky = dy[v, i, ln]
                ex = proj[v, i, 0, ln] - kx
                ey = proj[v, i, 1, ln] - ky
                d = np.sqrt(ex * ex + ey * ey)
                add = w * min(d if np.isfinite(d) else missing, cap)
                use = (ndet[v, ln] == nm) & (w > 0.0) & np.isfinite(kx) & np.isfinite(ky)
                ev[ln] = ev[ln] + (add if use else 0.0)  # + 0.0 leaves a sum >= 0 as it is
        for ln in range(nl):
            out[ln] += ev[ln]


@njit(inline="always", **LANE_OPTS)
def points3d_lanes(mk, o3, cap, out):
    """3D-point E of every lane (the scalar ``points3d_error``, same operations in the same
    order) into ``out``: marker i against its own point ``o3[i, :3]`` of weight
    ``o3[i, 3]``; a point not finite or of weight <= 0 costs nothing."""
    nl = out.shape[0]
    for ln in range(nl):
        out[ln] = 0.0
    for i in range(mk.shape[0]):
        for ln in range(nl):
            w = o3[i, 3, ln]
            ox = o3[i, 0, ln]
            oy = o3[i, 1, ln]
            oz = o3[i, 2, ln]
            ex = mk[i, 0, ln] - ox
            ey = mk[i, 1, ln] - oy
            ez = mk[i, 2, ln] - oz
            add = w * min(np.sqrt(ex * ex + ey * ey + ez * ez), cap)
            use = (w > 0.0) & np.isfinite(ox) & np.isfinite(oy) & np.isfinite(oz)
            out[ln] = out[ln] + (add if use else 0.0)  # + 0.0 leaves a sum >= 0 as it is


# -- the annealing iterations of all lanes ---------------------------------------------------
#: A histogram whose bins above the threshold form at most this many runs is tested by
#: comparing the bin with the runs' ends (vectorised) instead of looking the bin up (a
#: gather, which LLVM leaves scalar: 5 ns of the paper protocol's 36 ns per iteration).
MAX_RUNS = 4


@njit(**LANE_OPTS)
def allowed_runs(hist, nbins, th):
    """The runs of bins with ``hist[i, bin] >= th`` per axis: ``runs`` (n_axes, MAX_RUNS, 2)
    of [first, end) bins (as floats, to compare with a draw's bin), and their count per axis
    (-1 for more than MAX_RUNS)."""
    na = hist.shape[0]
    runs = np.zeros((na, MAX_RUNS, 2))
    n_runs = np.zeros(na, np.int64)
    for i in range(na):
        inside = False
        for k in range(nbins[i] + 1):
            good = k < nbins[i] and hist[i, k] >= th
            if good and not inside:
                if n_runs[i] == MAX_RUNS:
                    n_runs[i] = -1
                    break
                runs[i, n_runs[i], 0] = k
            elif inside and not good:
                runs[i, n_runs[i], 1] = k
                n_runs[i] += 1
            inside = good
    return runs, n_runs


class LaneState(NamedTuple):
    """Each lane's annealing state (a column per lane): whether it runs, its random stream,
    iterations, temperature, step length, countdowns, current and best E, and the state's
    current, candidate and best values with their cosines and sines (n_state, n_lanes)."""

    active: np.ndarray
    rs: np.ndarray
    it: np.ndarray
    tau: np.ndarray
    length: np.ndarray
    to_tau: np.ndarray
    to_l: np.ndarray
    e_cur: np.ndarray
    e_best: np.ndarray
    cur: np.ndarray
    cand: np.ndarray
    best: np.ndarray
    cs: np.ndarray
    sn: np.ndarray


class LaneObs(NamedTuple):
    """Each lane's detections: ``dx``, ``dy`` (n_views, c_cap, n_lanes) padded, their count
    ``ndet`` (n_views, n_lanes) and most ``cmax`` (n_views,); keypoint weights ``dw``; 3D
    points ``o3`` (n_markers, 4, n_lanes)."""

    dx: np.ndarray
    dy: np.ndarray
    ndet: np.ndarray
    cmax: np.ndarray
    dw: np.ndarray
    o3: np.ndarray


class LaneFrames(NamedTuple):
    """Each lane's posture scratch: joint frames ``rot``, ``pos``, markers ``mk``, their
    projections ``proj``, ``nearest`` and the candidates' E ``e`` (n_lanes,)."""

    rot: np.ndarray
    pos: np.ndarray
    mk: np.ndarray
    proj: np.ndarray
    nearest: np.ndarray
    e: np.ndarray


@njit(**LANE_OPTS)
def iterate_lanes(n_iter, n_hist, runs, n_runs, dofs, schedule, lanes, body, cams, lobs, error,
                  frames, fused, use_fused, single, labelled, points3d):
    """Anneal every lane (scalar ``anneal_chain``'s iteration, per lane) until an active lane
    has finished (``it >= n_end`` or best E below ``eps``) or ``n_iter`` iterations passed.
    Inactive lanes compute but change nothing that is read back. ``lanes``: LaneState;
    ``lobs``: LaneObs; ``frames``: LaneFrames; ``dofs``, ``schedule``, ``error``: the scalar
    kernel's records. With ``use_fused`` the
    candidates' E comes from ``fused``, a kernel generated for the body
    (:mod:`kinematics._kernels.lane_codegen`), instead of the general loops; ``single``: that
    kernel computes in float32 and reads the detections' float32 copies. ``labelled``:
    the detections are labelled keypoints of weights ``lobs.dw`` (:func:`labelled_lanes`);
    ``points3d``: E is against each lane's 3D points ``lobs.o3`` (:func:`points3d_lanes`)."""
    # the records unpacked once: the loops read plain arrays
    free_idx, step, hist, nbins = dofs.free_idx, dofs.step, dofs.hist, dofs.nbins
    lo, hi = dofs.lo, dofs.hi
    th, max_redraws, eps = schedule.th, schedule.max_redraws, schedule.eps
    n_end, n_l, n_tau = schedule.n_end, schedule.n_l, schedule.n_tau
    c_l, c_tau = schedule.c_l, schedule.c_tau
    active, rs, it, tau, length = lanes.active, lanes.rs, lanes.it, lanes.tau, lanes.length
    to_tau, to_l, e_cur, e_best = lanes.to_tau, lanes.to_l, lanes.e_cur, lanes.e_best
    cur, cand, best, cs, sn = lanes.cur, lanes.cand, lanes.best, lanes.cs, lanes.sn
    dx, dy, ndet, cmax, dw, o3 = lobs.dx, lobs.dy, lobs.ndet, lobs.cmax, lobs.dw, lobs.o3
    bidirectional, weight, cap, penalty_cap = (error.bidirectional, error.weight, error.cap,
                                               error.penalty_cap)
    rot, pos, mk, proj, nearest, e = (frames.rot, frames.pos, frames.mk, frames.proj,
                                      frames.nearest, frames.e)
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body  # project_lanes' arguments, in order
    kind, P, K, dist, R, t = cams
    n_free = free_idx.shape[0]
    nl = e.shape[0]
    e_acc = np.empty(nl)
    ev = np.empty(nl)
    dmin = np.empty(nl)
    arg = np.empty(nl, np.int64)
    matched = np.empty((4, nl), np.bool_)
    near = np.empty((4, nl))
    xs = np.empty(nl)
    ok = np.empty(-(-nl // 8) * 8, np.bool_)
    ok_words = ok.view(np.uint64)
    accept = np.empty(nl, np.bool_)
    better = np.empty(nl, np.bool_)
    bin_of = np.empty(nl)
    xs_bits = xs.view(np.uint64)  # the same memory: taking a draw copies its bits
    cur_bits = cur.view(np.uint64)
    cand_bits = cand.view(np.uint64)
    best_bits = best.view(np.uint64)
    # the detections in float32, for a float32 kernel: they change only between calls
    convert = use_fused and single
    dx32 = np.empty(dx.shape if convert else (0, 0, 0), np.float32)
    dy32 = np.empty(dx32.shape, np.float32)
    if convert:
        dx32[:] = dx
        dy32[:] = dy
    done = False
    n = 0
    while n < n_iter and not done:
        for ln in range(nl):
            rs[ln], u = next_uniform(rs[ln])
            e_acc[ln] = e_cur[ln] + tau[ln] * -log_unit(u)
        for q in range(n_free):
            i = free_idx[q]
            use_hist = q < n_hist
            nb = nbins[i]
            nf = float(nb)
            s_i = step[i]
            lo_i = lo[i]
            hi_i = hi[i]
            # every lane's first draw, then its test: with the histogram's lookup (a gather)
            # in the loop that draws, LLVM kept the whole draw scalar and branchy
            for ln in range(nl):
                st, u = next_uniform(rs[ln])
                x = cur[i, ln] + (length[ln] * s_i) * (2.0 * u - 1.0)
                rs[ln] = st
                xs[ln] = x
                # hist_at without a branch: the bin index wrapped by a float modulo
                kf = np.floor(x * (nf * (0.5 / np.pi)) + 0.5 * nf)
                inside = (kf >= 0.0) & (kf < nf)
                kf = kf if inside else kf - nf * np.floor(kf / nf)
                bin_of[ln] = kf
                ok[ln] = (lo_i <= x) & (x <= hi_i)
            if use_hist and n_runs[i] >= 0:  # (allowed_runs)
                for ln in range(nl):
                    ok[ln] = False
                for r in range(n_runs[i]):
                    first, end = runs[i, r, 0], runs[i, r, 1]
                    for ln in range(nl):
                        ok[ln] = ok[ln] | ((bin_of[ln] >= first) & (bin_of[ln] < end))
            elif use_hist:
                for ln in range(nl):
                    ok[ln] = hist[i, int(bin_of[ln])] >= th
            # the lanes whose first draw was refused redraw as the scalar kernel does, one
            # lane at a time: they are few, and a loop over all lanes per redraw (while any
            # lane waited) cost every lane as many rounds as its unluckiest neighbour
            ln = 0
            while ln < nl:
                if ln & 7 == 0 and ln + 8 <= nl and ok_words[ln >> 3] == _ALL_OK:
                    ln += 8  # eight lanes at once, as one word of their bools
                    continue
                if not ok[ln]:
                    st = rs[ln]
                    x = xs[ln]
                    good = False
                    tries = 1
                    while not good and tries <= max_redraws:
                        st, u = next_uniform(st)
                        x = cur[i, ln] + (length[ln] * s_i) * (2.0 * u - 1.0)
                        good = hist_at(hist, nbins, i, x) >= th if use_hist else \
                            (lo_i <= x) & (x <= hi_i)
                        tries += 1
                    rs[ln] = st
                    xs[ln] = x
                    ok[ln] = good
                ln += 1
            for ln in range(nl):
                m = np.uint64(0) - np.uint64(ok[ln])
                cand_bits[i, ln] = cur_bits[i, ln] ^ ((cur_bits[i, ln] ^ xs_bits[ln]) & m)
            if not use_fused:  # the generated kernel takes its sines and cosines itself
                for ln in range(nl):
                    sn[i, ln], cs[i, ln] = sincos(cand[i, ln])
        if use_fused:
            fused(cand, rot, pos, dx, dy, dx32, dy32, dw, o3, ndet, e)
        else:
            project_lanes(cand, cs, sn, parent, chain, pre_rot, pre_trans, post_trans,
                          elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                          slide_index, kind, P, K, dist, R, t, rot, pos, mk, proj)
            if points3d:
                points3d_lanes(mk, o3, cap, e)
            elif labelled:
                labelled_lanes(proj, dx, dy, dw, ndet, cap, ev, e)
            else:
                error_lanes(proj, dx, dy, ndet, cmax, bidirectional, weight, cap,
                            penalty_cap, nearest, ev, dmin, arg, matched, near, e)
        for ln in range(nl):
            acc = (e[ln] <= e_cur[ln]) | (e[ln] < e_acc[ln])
            accept[ln] = acc
            e_cur[ln] = e[ln] if acc else e_cur[ln]
            better[ln] = e[ln] < e_best[ln]
            e_best[ln] = e[ln] if better[ln] else e_best[ln]
        for q in range(n_free):
            i = free_idx[q]
            for ln in range(nl):
                x = cand_bits[i, ln]
                m = np.uint64(0) - np.uint64(accept[ln])
                cur_bits[i, ln] = cur_bits[i, ln] ^ ((cur_bits[i, ln] ^ x) & m)
                m = np.uint64(0) - np.uint64(better[ln])
                best_bits[i, ln] = best_bits[i, ln] ^ ((best_bits[i, ln] ^ x) & m)
        for ln in range(nl):
            it[ln] += 1
            to_tau[ln] -= 1
            cool = to_tau[ln] == 0
            tau[ln] = tau[ln] * c_tau if cool else tau[ln]
            to_tau[ln] = n_tau if cool else to_tau[ln]
            to_l[ln] -= 1
            shrink = to_l[ln] == 0
            length[ln] = length[ln] * c_l if shrink else length[ln]
            to_l[ln] = n_l if shrink else to_l[ln]
            done = done | (active[ln] & ((it[ln] >= n_end) | (e_best[ln] < eps)))
        n += 1
    return n
