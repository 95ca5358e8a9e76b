"""numba lane kernels: many annealing runs at once, one per SIMD lane (private; the public
entry is :class:`kinematics.fit.Fitter` with ``backend = "lanes"``).

One annealing run is latency-bound: each iteration waits for the previous acceptance. Runs
of different frames (and the candidate runs of one frame) are independent, so this module
anneals ``LANES`` of them together: every per-run quantity has a last axis of ``LANES``
entries, and every loop over that axis is straight-line code that LLVM turns into packed
vector instructions. Decisions that differ between runs (acceptance, redraws, the nearest
detection) are selects, not branches. What LLVM vectorises under numba, found by measuring
(bench/bench_lanes.py, docs/benchmarks.md "Lanes"):

* the lane count must be a run-time value (``for ln in range(nl)``, ``nl`` from an array's
  shape): a compile-time 8 is fully unrolled, and numba leaves SLP vectorisation off;
* a loop over lanes must be the innermost loop: an inner loop with a run-time count (even of
  1 to 4) keeps it scalar, a constant one is unrolled and fine;
* no branch around a load (invariant choices go outside the loop, as separate loops), at
  most about nine stores, and loads before stores;
* no array views (``rot[j]``) in the iteration: each costs atomic reference counts;
* several small loops beat one fused loop that does more per lane (the redraw loops fused
  into one were 1.5x slower);
* an indirect load (the histogram's bin, a gather) keeps the loop that holds it scalar, and
  branchy: it goes in a loop of its own;
* ``a[k] = b[k] if c else a[k]`` is turned by LLVM into a load from a selected address,
  which it does not vectorise: copying a value under a condition is done on its bits, under
  a mask (``view(np.uint64)``), which is exact.

Found with ``perf record`` on a running fit and ``gdb`` on the hot addresses (scalar ``vmulsd``
against packed ``zmm``), and LLVM's ``-pass-remarks-missed=loop-vectorize`` through
``llvmlite.binding.set_option`` (with ``NUMBA_DEBUGINFO=1`` for line numbers).

The readable twin and test oracle is the scalar kernel :func:`kinematics._kernels.frames.
fit_frames`: each run here performs exactly the scalar kernel's arithmetic in the same order
on the same random stream (splitmix64 per seed, frame and run), so the outputs agree to the
last bit — whatever the number of lanes or threads. What a lane cannot do cheaply (loading a
run, its starting E, refinement, deciding on re-runs) calls the scalar kernels.

A group's last runs, once no run waits, are moved into fewer lanes (:func:`_kept_lanes`).
Where a kernel was generated for the body (:mod:`kinematics._kernels.lane_codegen`), it computes the
candidates' E instead of :func:`project_lanes` and :func:`error_lanes`, with the same result.

Layout (``L = LANES``): state ``cur``, ``cand``, ``best``, ``cs``, ``sn`` (n_state, L);
``rot`` (nj + n_chains, 9, L) row-major A'_j and the roots' seed rotations; ``pos``
(nj + n_chains, 3, L); ``mk`` (nm, 3, L); ``proj``
(nv, nm, 2, L); detections ``dx``, ``dy`` (nv, c_max, L), padded with :data:`PAD` beyond the
lane's own ``ndet`` (nv, L); for labelled keypoints row i is marker i's keypoint, of weight
``dw`` (nv, c_max, L); 3D points ``o3`` (nm, 4, L). The supported problems are those
``Fitter._backend`` accepts (unlabelled points, labelled 2D keypoints or 3D points, one
partition, independent frames); the scalar kernel does the rest.
"""

from __future__ import annotations

import numpy as np
from numba import cfunc, njit, prange, types

from kinematics._kernels.anneal import hist_at
from kinematics._kernels.camera import ORTHOGRAPHIC
from kinematics._kernels.codes import NAN_MARKER_COST, OBJ_LABELLED, OBJ_POINTS3D, ROOT_POSE
from kinematics._kernels.fastmath import log_unit, next_uniform, sincos, stream_state
from kinematics._kernels.frames import clear_frame, finish_run, take_runs, wants_run, write_frame
from kinematics._kernels.objective import evaluate, observed
from kinematics._kernels.posture import mul33, project_posture

#: Runs annealed together per thread: eight 512-bit registers of float64. More lanes spread
#: each loop's fixed cost (bench/bench_lanes.py: 32 and 128 were slower); fewer than 16
#: leave LLVM's vector loop unused.
LANES = 64

#: Backend 'auto' anneals a block in lanes from this many runs per numba thread (64 filled
#: them): half-empty lanes still beat the scalar kernel (the locust, single runs, 2 threads,
#: scalar / lanes time with the generated kernel: 2 runs per thread 1.15, 4: 2.2, 8: 4.2,
#: 16: 5.4, 32: 6.3, 64: 6.8; with the general loops 16: 1.0, 32: 2.1). Fewer runs stay
#: scalar: each new body and detection count compiles a kernel (~2 s, once per machine),
#: which a few frames (a GUI fit) should not wait for. 32 lets the 64 single runs that
#: measure the 'auto' threshold run in lanes on 2 threads.
MIN_RUNS_PER_THREAD = 32

_ALL_OK = np.uint64(0x0101010101010101)  # eight True bools read as one word

#: Coordinate of a padding detection: farther than any real one, finite when squared.
PAD = 1.0e30

_OPTS = {"cache": True, "nogil": True, "error_model": "numpy"}

#: A kernel generated for one body (:mod:`kinematics._kernels.lane_codegen`): every lane's E of its
#: candidate, ``evaluate(cand, rot, pos, dx, dy, dx32, dy32, dw, o3, ndet, e)`` (``dx32``,
#: ``dy32``: the detections in float32, for a float32 kernel; ``dw``: labelled keypoints'
#: weights; ``o3``: 3D points). Called through a function pointer, so the lane loops are
#: compiled once for every generated kernel.
FUSED_SIGNATURE = types.void(types.float64[:, ::1], types.float64[:, :, ::1],
                             types.float64[:, :, ::1], types.float64[:, :, ::1],
                             types.float64[:, :, ::1], types.float32[:, :, ::1],
                             types.float32[:, :, ::1], types.float64[:, :, ::1],
                             types.float64[:, :, ::1], types.int64[:, ::1],
                             types.float64[::1])


@cfunc(FUSED_SIGNATURE, cache=True, nopython=True)
def no_fused(cand, rot, pos, dx, dy, dx32, dy32, dw, o3, ndet, e):
    """The ``fused`` argument where no kernel was generated (never called)."""


@njit(**_OPTS)
def call_fused(fused, cand, rot, pos, dx, dy, dx32, dy32, dw, o3, ndet, e):
    """Run a generated kernel's machine code (for tests: calling a numba ``cfunc`` from
    Python runs its Python source instead)."""
    fused(cand, rot, pos, dx, dy, dx32, dy32, dw, o3, ndet, e)


@njit(**_OPTS)
def sincos_lanes(x, s, c):
    """Fill ``s``, ``c`` with the kernels' ``sincos`` of ``x`` in a loop as the lanes run it
    (for tests)."""
    for k in range(x.shape[0]):
        s[k], c[k] = sincos(x[k])


# -- forward kinematics and projection of all lanes ----------------------------------------
@njit(inline="always", **_OPTS)
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


@njit(inline="always", **_OPTS)
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
@njit(inline="always", **_OPTS)
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


@njit(inline="always", **_OPTS)
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


@njit(inline="always", **_OPTS)
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


@njit(**_OPTS)
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


@njit(**_OPTS)
def iterate_lanes(n_iter, free_idx, n_hist, step, hist, nbins, th, runs, n_runs, dof_kind, lo, hi,
                  max_redraws, n_end, n_l, n_tau, c_l, c_tau, eps, active, rs, it, tau,
                  length, to_tau, to_l, e_cur, e_best, cur, cand, best, cs, sn, body, cams, dx,
                  dy, ndet, cmax, bidirectional, weight, cap, penalty_cap, rot, pos, mk, proj,
                  nearest, e, fused, use_fused, single, labelled, dw, points3d, o3):
    """Anneal every lane (scalar ``anneal_chain``'s iteration, per lane) until an active lane
    has finished (``it >= n_end`` or best E below ``eps``) or ``n_iter`` iterations passed.
    Inactive lanes compute but change nothing that is read back. With ``use_fused`` the
    candidates' E comes from ``fused``, a kernel generated for the body
    (:mod:`kinematics._kernels.lane_codegen`), instead of the general loops; ``single``: that
    kernel computes in float32 and reads the detections' float32 copies. ``labelled``:
    the detections are labelled keypoints of weights ``dw`` (:func:`labelled_lanes`);
    ``points3d``: E is against each lane's 3D points ``o3`` (:func:`points3d_lanes`)."""
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body
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


# -- shrinking the lanes at the end of a group ----------------------------------------------
#: Once the queue is empty and at most half the lanes are busy, the busy runs move into
#: fewer lanes (as many as are busy, at least this many): every lane loop costs its full
#: width whether a lane is busy or not, so a group's last runs (re-analyses) ran at a
#: fraction of the rate. Measured (bench_lanes.py, one run each): the Table 1 row with
#: re-analysis 1.24x -> 1.46x the scalar kernel, the defaults 2.35x -> 2.68x; shrinking
#: from three quarters busy was no better.
MIN_LANES = 8


@njit(**_OPTS)
def _take1(a, idx):
    out = np.empty(idx.shape[0], a.dtype)
    for k in range(idx.shape[0]):
        out[k] = a[idx[k]]
    return out


@njit(**_OPTS)
def _take2(a, idx):
    out = np.empty((a.shape[0], idx.shape[0]), a.dtype)
    for r in range(a.shape[0]):
        for k in range(idx.shape[0]):
            out[r, k] = a[r, idx[k]]
    return out


@njit(**_OPTS)
def _take3(a, idx):
    out = np.empty((a.shape[0], a.shape[1], idx.shape[0]), a.dtype)
    for r in range(a.shape[0]):
        for q in range(a.shape[1]):
            for k in range(idx.shape[0]):
                out[r, q, k] = a[r, q, idx[k]]
    return out


@njit(**_OPTS)
def _take4(a, idx):
    out = np.empty((a.shape[0], a.shape[1], a.shape[2], idx.shape[0]), a.dtype)
    for r in range(a.shape[0]):
        for q in range(a.shape[1]):
            for w in range(a.shape[2]):
                for k in range(idx.shape[0]):
                    out[r, q, w, k] = a[r, q, w, idx[k]]
    return out


@njit(**_OPTS)
def _kept_lanes(active, queue_empty):
    """The lanes to keep when the lanes should shrink (the queue is empty, there are more
    than MIN_LANES lanes and at most half of them are busy): the busy ones, padded with idle
    ones to MIN_LANES; an empty array when they should not."""
    nl = active.shape[0]
    busy = 0
    for ln in range(nl):
        busy += 1 if active[ln] else 0
    if not queue_empty or nl <= MIN_LANES or busy == 0 or 2 * busy > nl:
        return np.empty(0, np.int64)
    keep = np.empty(max(busy, MIN_LANES), np.int64)
    k = 0
    for ln in range(nl):
        if active[ln]:
            keep[k] = ln
            k += 1
    for ln in range(nl):
        if k < keep.shape[0] and not active[ln]:
            keep[k] = ln
            k += 1
    return keep


# -- the frame procedure (fit_frames' runs, re-analysis and candidates) ----------------------
@njit(parallel=True, **_OPTS)
def fit_frames_lanes(group_off, frame_ids, root_pos, root_rot, start, body, cams, dofs,
                     schedule, error, obs, claim_gate, n_lanes, fused, n_fused, single, out):
    """Fit many frames, their runs packed into lanes: the scalar ``fit_frames`` for
    independent frames (``start_previous`` false, one partition, unlabelled points, labelled
    2D keypoints or 3D points), with the same outputs to the last bit. Frames
    ``group_off[g]:group_off[g + 1]`` are fitted by one thread (``prange`` over groups) with
    ``n_lanes`` lanes; ``claim_gate`` is the partitions' (detections farther from every
    marker are unexplained); every other argument is ``fit_frames``'. ``fused`` is the body's
    generated kernel (:func:`iterate_lanes`) and ``n_fused`` the detections per view it scans
    (at least every frame's; 1 for labelled keypoints, whose rows are the markers'), or
    ``no_fused`` and 0 for the general loops; ``single``: the kernel is float32."""
    for g in prange(group_off.shape[0] - 1):
        _fit_group(group_off[g], group_off[g + 1], frame_ids, root_pos, root_rot, start, body,
                   cams, dofs, schedule, error, obs, claim_gate, n_lanes, fused, n_fused, single,
                   out)


@njit(**_OPTS)
def _fit_group(f0, f1, frame_ids, root_pos, root_rot, start, body, cams, dofs, schedule,
               error, obs, claim_gate, nl, fused, n_fused, single, out):
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body
    kind, P, K, dist, R, t = cams
    free_idx, step, hist, nbins, dof_kind, lo, hi = dofs
    (th, max_redraws, n_end, n_l, n_tau, tau0, l0, c_l, c_tau, eps, seed,
     reanalysis_threshold, max_runs, _, _, _, max_unexplained, min_runs) = schedule
    bidirectional, weight, cap, penalty_cap, one = error
    objective, det_points, det_conf, det_off, obs3 = obs
    nv = kind.shape[0]
    nj = parent.shape[0]
    nm = marker_joint.shape[0]
    na = start.shape[0]
    nc = root_pos.shape[1]
    n = f1 - f0
    n_hist = 0
    while n_hist < free_idx.shape[0] and dof_kind[free_idx[n_hist]] == 0:
        n_hist += 1
    runs, n_runs = allowed_runs(hist, nbins, th)
    labelled = objective == OBJ_LABELLED
    points3d = objective == OBJ_POINTS3D
    c_cap = max(1, n_fused, nm if labelled else 0)  # labelled: keypoint i is marker i's
    for f in range(f0, f1):
        for v in range(nv):
            c_cap = max(c_cap, det_off[f * nv + v + 1] - det_off[f * nv + v])
    # lane state
    cur = np.empty((na, nl))
    cand = np.empty((na, nl))
    best = np.empty((na, nl))
    cs = np.empty((na, nl))
    sn = np.empty((na, nl))
    rot = np.zeros((nj + nc, 9, nl))  # rows nj + c: chain c's root (project_lanes)
    pos = np.zeros((nj + nc, 3, nl))
    mk = np.empty((nm, 3, nl))
    proj = np.empty((nv, nm, 2, nl))
    nearest = np.empty((nm, nl), np.int64)
    e = np.empty(nl)
    dx = np.full((nv, c_cap, nl), PAD)
    dy = np.full((nv, c_cap, nl), PAD)
    dw = np.zeros((nv, c_cap, nl) if labelled else (nv, 0, nl))  # keypoints' weights
    o3 = np.zeros((nm if points3d else 0, 4, nl))  # 3D points (x, y, z, weight)
    ndet = np.zeros((nv, nl), np.int64)
    cmax = np.zeros(nv, np.int64)
    active = np.zeros(nl, np.bool_)
    rs = np.zeros(nl, np.uint64)
    it = np.zeros(nl, np.int64)
    tau = np.ones(nl)
    length = np.ones(nl)
    to_tau = np.ones(nl, np.int64)
    to_l = np.ones(nl, np.int64)
    e_cur = np.zeros(nl)
    e_best = np.zeros(nl)
    lane_frame = np.zeros(nl, np.int64)
    lane_run = np.zeros(nl, np.int64)
    for ln in range(nl):
        for k in range(na):
            cur[k, ln] = start[k]
            cand[k, ln] = start[k]
            best[k, ln] = start[k]
    # scalar scratch (loading, refinement, scoring)
    s_state = np.empty(na)
    s_annealed = np.empty(na)
    s_cs = np.empty(na)
    s_sn = np.empty(na)
    s_rot = np.empty((nj, 3, 3))
    s_pos = np.empty((nj, 3))
    s_mk = np.empty((nm, 3))
    s_proj = np.empty((nv, nm, 2))
    s_view = np.empty(nv)
    s_near = np.empty(nm, np.int64)
    # per-frame bookkeeping (local index f - f0)
    issued = np.zeros(n, np.int64)
    finished = np.zeros(n, np.int64)
    e_keep = np.full(n, np.inf)
    u_keep = np.full(n, 1 << 30)
    keep_run = np.zeros(n, np.int64)
    run_u = np.zeros((n, max_runs), np.int64)
    run_pairs = np.zeros((n, max_runs), np.int64)
    queue = np.empty(n * max_runs, np.int64)  # tasks: local frame * max_runs + run
    head = 0
    tail = 0
    first_runs = min(max(min_runs, 1), max_runs)
    for f in range(f0, f1):
        clear_frame(out, f)
        if observed(objective, det_off[f * nv: f * nv + nv + 1], obs3[f]):
            for r in range(first_runs):
                queue[tail] = (f - f0) * max_runs + r
                tail += 1
            issued[f - f0] = first_runs
    while True:
        # load idle lanes with waiting runs
        for ln in range(nl):
            if not active[ln] and head < tail:
                task = queue[head]
                head += 1
                fl = task // max_runs
                f = f0 + fl
                run = task - fl * max_runs
                vo = det_off[f * nv: f * nv + nv + 1]
                for v in range(nv):
                    a = vo[v]
                    b = vo[v + 1]
                    ndet[v, ln] = b - a
                    for c in range(c_cap):
                        dx[v, c, ln] = det_points[a + c, 0] if c < b - a else PAD
                        dy[v, c, ln] = det_points[a + c, 1] if c < b - a else PAD
                    if labelled:
                        for c in range(c_cap):
                            dw[v, c, ln] = det_conf[a + c] if c < b - a else 0.0
                if points3d:
                    for i in range(nm):
                        for k in range(4):
                            o3[i, k, ln] = obs3[f, i, k]
                for j in range(nj):  # the roots' slots (project_lanes)
                    if parent[j] < 0:
                        c = chain[j]
                        seeded = joint_flags[j] & ROOT_POSE
                        for k in range(3):
                            pos[nj + c, k, ln] = root_pos[f, c, k]
                            for k2 in range(3):
                                q = root_rot[f, c, k, k2] if seeded else (1.0 if k == k2 else 0.0)
                                rot[nj + c, 3 * k + k2, ln] = q
                for k in range(na):
                    cur[k, ln] = start[k]
                    cand[k, ln] = start[k]
                    best[k, ln] = start[k]
                    sn[k, ln], cs[k, ln] = sincos(start[k])
                project_posture(start, root_pos[f], root_rot[f], parent, chain, pre_rot,
                                pre_trans, post_trans, elem_axis, elem_index, joint_flags,
                                marker_joint, marker_local, slide_index, kind, P, K, dist, R,
                                t, s_cs, s_sn, s_rot, s_pos, s_mk, s_proj)
                e0 = evaluate(objective, s_proj, s_mk, det_points, det_conf, vo, obs3[f],
                              bidirectional, weight, cap, penalty_cap, one, s_view, s_near)
                e_cur[ln] = e0
                e_best[ln] = e0
                tau[ln] = tau0
                length[ln] = l0
                to_tau[ln] = n_tau
                to_l[ln] = n_l
                it[ln] = 0
                rs[ln] = stream_state(seed, frame_ids[f], run)
                lane_frame[ln] = f
                lane_run[ln] = run
                active[ln] = True
        any_active = False
        for ln in range(nl):
            any_active = any_active or active[ln]
        if not any_active:
            break
        for v in range(nv):
            cm = 0
            for ln in range(nl):
                cm = max(cm, ndet[v, ln] if active[ln] else 0)
            cmax[v] = cm
        # finish the runs that are done; anneal the others until the next one is
        any_done = False
        for ln in range(nl):
            if active[ln] and (it[ln] >= n_end or e_best[ln] < eps):
                any_done = True
                active[ln] = False
                f = lane_frame[ln]
                fl = f - f0
                run = lane_run[ln]
                vo = det_off[f * nv: f * nv + nv + 1]
                for k in range(na):
                    s_state[k] = best[k, ln]
                out.iterations[f] += it[ln]
                e_run, pairs, u = finish_run(s_state, e_best[ln], root_pos[f], root_rot[f],
                                             body, cams, dofs, schedule, error, objective,
                                             det_points, det_conf, vo, obs3[f], claim_gate,
                                             s_annealed, s_cs, s_sn, s_rot, s_pos, s_mk,
                                             s_proj, s_view, s_near)
                out.run_angles[f, run, :] = s_state
                out.run_error[f, run] = e_run
                run_u[fl, run] = u
                run_pairs[fl, run] = pairs
                finished[fl] += 1
                if finished[fl] == issued[fl]:
                    # the frame's runs so far are all done: take them in run order, as the
                    # scalar kernel does after each
                    e_keep[fl], u_keep[fl], keep_run[fl] = take_runs(
                        out, f, issued[fl], run_u[fl], run_pairs[fl], max_unexplained)
                    nxt = issued[fl]
                    if wants_run(nxt, min_runs, max_runs, e_keep[fl], u_keep[fl],
                                 reanalysis_threshold, max_unexplained):
                        queue[tail] = fl * max_runs + nxt
                        tail += 1
                        issued[fl] = nxt + 1
                    else:
                        s_state[:] = out.run_angles[f, keep_run[fl], :]
                        write_frame(out, f, s_state, issued[fl], root_pos[f], root_rot[f],
                                    body, cams, error, objective, det_points, det_conf, vo,
                                    obs3[f], s_cs, s_sn, s_rot, s_pos, s_mk, s_proj, s_view,
                                    s_near)
        if any_done:
            continue  # refill the freed lanes first
        keep = _kept_lanes(active, head == tail)
        if keep.shape[0]:  # the group's last runs: anneal them in fewer lanes
            cur, cand, best = _take2(cur, keep), _take2(cand, keep), _take2(best, keep)
            cs, sn, nearest = _take2(cs, keep), _take2(sn, keep), _take2(nearest, keep)
            rot, pos, mk = _take3(rot, keep), _take3(pos, keep), _take3(mk, keep)
            proj = _take4(proj, keep)
            dx, dy, ndet = _take3(dx, keep), _take3(dy, keep), _take2(ndet, keep)
            dw, o3 = _take3(dw, keep), _take3(o3, keep)
            e, active, rs, it = _take1(e, keep), _take1(active, keep), _take1(rs, keep), \
                _take1(it, keep)
            tau, length = _take1(tau, keep), _take1(length, keep)
            to_tau, to_l = _take1(to_tau, keep), _take1(to_l, keep)
            e_cur, e_best = _take1(e_cur, keep), _take1(e_best, keep)
            lane_frame, lane_run = _take1(lane_frame, keep), _take1(lane_run, keep)
            nl = keep.shape[0]
        iterate_lanes(1 << 30, free_idx, n_hist, step, hist, nbins, th, runs, n_runs, dof_kind,
                      lo, hi, max_redraws, n_end, n_l, n_tau, c_l, c_tau, eps, active, rs, it, tau,
                      length, to_tau, to_l, e_cur, e_best, cur, cand, best, cs, sn, body,
                      cams, dx, dy, ndet, cmax, bidirectional, weight, cap,
                      penalty_cap, rot, pos, mk, proj, nearest, e, fused, n_fused > 0, single,
                      labelled, dw, points3d, o3)
