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

from kinematics._kernels.codes import OBJ_LABELLED, OBJ_POINTS3D, ROOT_POSE
from kinematics._kernels.fastmath import sincos, stream_state
from kinematics._kernels.frames import clear_frame, finish_run, take_runs, wants_run, write_frame
from kinematics._kernels.lane_iterations import (
    LANE_OPTS,
    LaneFrames,
    LaneObs,
    LaneState,
    allowed_runs,
    iterate_lanes,
)
from kinematics._kernels.objective import evaluate, observed
from kinematics._kernels.posture import project_posture
from kinematics._kernels.records import frame_obs, new_scratch

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

#: Coordinate of a padding detection: farther than any real one, finite when squared.
PAD = 1.0e30

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


@njit(**LANE_OPTS)
def call_fused(fused, cand, rot, pos, dx, dy, dx32, dy32, dw, o3, ndet, e):
    """Run a generated kernel's machine code (for tests: calling a numba ``cfunc`` from
    Python runs its Python source instead)."""
    fused(cand, rot, pos, dx, dy, dx32, dy32, dw, o3, ndet, e)


# -- shrinking the lanes at the end of a group ----------------------------------------------
#: Once the queue is empty and at most half the lanes are busy, the busy runs move into
#: fewer lanes (as many as are busy, at least this many): every lane loop costs its full
#: width whether a lane is busy or not, so a group's last runs (re-analyses) ran at a
#: fraction of the rate. Measured (bench_lanes.py, one run each): the Table 1 row with
#: re-analysis 1.24x -> 1.46x the scalar kernel, the defaults 2.35x -> 2.68x; shrinking
#: from three quarters busy was no better.
MIN_LANES = 8


@njit(**LANE_OPTS)
def _take1(a, idx):
    out = np.empty(idx.shape[0], a.dtype)
    for k in range(idx.shape[0]):
        out[k] = a[idx[k]]
    return out


@njit(**LANE_OPTS)
def _take2(a, idx):
    out = np.empty((a.shape[0], idx.shape[0]), a.dtype)
    for r in range(a.shape[0]):
        for k in range(idx.shape[0]):
            out[r, k] = a[r, idx[k]]
    return out


@njit(**LANE_OPTS)
def _take3(a, idx):
    out = np.empty((a.shape[0], a.shape[1], idx.shape[0]), a.dtype)
    for r in range(a.shape[0]):
        for q in range(a.shape[1]):
            for k in range(idx.shape[0]):
                out[r, q, k] = a[r, q, idx[k]]
    return out


@njit(**LANE_OPTS)
def _take4(a, idx):
    out = np.empty((a.shape[0], a.shape[1], a.shape[2], idx.shape[0]), a.dtype)
    for r in range(a.shape[0]):
        for q in range(a.shape[1]):
            for w in range(a.shape[2]):
                for k in range(idx.shape[0]):
                    out[r, q, w, k] = a[r, q, w, idx[k]]
    return out


@njit(**LANE_OPTS)
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
@njit(parallel=True, **LANE_OPTS)
def fit_frames_lanes(group_off, frame_ids, root_pos, root_rot, start, body, cams, dofs,
                     schedule, error, obs, claim_gate, fused, setup, out):
    """Fit many frames, their runs packed into lanes: the scalar ``fit_frames`` for
    independent frames (``start_previous`` false, one partition, unlabelled points, labelled
    2D keypoints or 3D points), with the same outputs to the last bit. Frames
    ``group_off[g]:group_off[g + 1]`` are fitted by one thread (``prange`` over groups) with
    ``n_lanes`` lanes; ``claim_gate`` is the partitions' (detections farther from every
    marker are unexplained); every other argument is ``fit_frames``'. ``fused`` is the body's
    generated kernel (:func:`iterate_lanes`), or ``no_fused`` for the general loops;
    ``setup = (n_lanes, n_fused, single)``: ``n_fused`` the detections per view the kernel
    scans (at least every frame's; 1 for labelled keypoints, whose rows are the markers'; 0
    for the general loops), ``single``: the kernel is float32."""
    n_lanes, n_fused, single = setup
    for g in prange(group_off.shape[0] - 1):
        _fit_group(group_off[g], group_off[g + 1], frame_ids, root_pos, root_rot, start, body,
                   cams, dofs, schedule, error, obs, claim_gate, n_lanes, fused, n_fused, single,
                   out)


@njit(**LANE_OPTS)
def _fit_group(f0, f1, frame_ids, root_pos, root_rot, start, body, cams, dofs, schedule,
               error, obs, claim_gate, nl, fused, n_fused, single, out):
    parent, chain, joint_flags = body.parent, body.chain, body.joint_flags
    free_idx, hist, nbins, dof_kind = dofs.free_idx, dofs.hist, dofs.nbins, dofs.dof_kind
    th, n_end, n_l, n_tau = schedule.th, schedule.n_end, schedule.n_l, schedule.n_tau
    tau0, l0, eps, seed = schedule.tau0, schedule.l0, schedule.eps, schedule.seed
    reanalysis_threshold, max_runs = schedule.reanalysis_threshold, schedule.max_runs
    max_unexplained, min_runs = schedule.max_unexplained, schedule.min_runs
    objective, det_points, det_conf, det_off, obs3 = (obs.objective, obs.points, obs.conf,
                                                      obs.offsets, obs.points3d)
    nv = cams.kind.shape[0]
    nj = parent.shape[0]
    nm = body.marker_joint.shape[0]
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
    scratch = new_scratch(na, nj, nm, nv)
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
                fo = frame_obs(obs, f, nv)
                project_posture(start, root_pos[f], root_rot[f], body, cams, scratch.cs,
                                scratch.sn, scratch.rot, scratch.pos, scratch.mk, scratch.proj)
                e0 = evaluate(objective, scratch.proj, scratch.mk, det_points, det_conf, vo,
                              fo.obs3, error.bidirectional, error.weight, error.cap,
                              error.penalty_cap, error.one_to_one, scratch.per_view,
                              scratch.nearest)
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
                                             body, cams, dofs, schedule, error,
                                             frame_obs(obs, f, nv), claim_gate, s_annealed,
                                             scratch)
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
                                    body, cams, error, frame_obs(obs, f, nv), scratch)
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
        iterate_lanes(1 << 30, n_hist, runs, n_runs, dofs, schedule,
                      LaneState(active, rs, it, tau, length, to_tau, to_l, e_cur, e_best, cur,
                                cand, best, cs, sn), body, cams,
                      LaneObs(dx, dy, ndet, cmax, dw, o3), error,
                      LaneFrames(rot, pos, mk, proj, nearest, e), fused, n_fused > 0, single,
                      labelled, points3d)
