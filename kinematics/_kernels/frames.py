"""The per-frame procedure: annealing runs, the re-analysis runs a frame's E asks for,
refinement and the kept run, over many frames in parallel (:func:`fit_frames`). The lane
kernel and the CUDA rounds share its steps (:func:`clear_frame`, :func:`finish_run`,
:func:`write_frame`)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from kinematics._kernels.anneal import anneal_chain, anneal_partitions
from kinematics._kernels.codes import OBJ_CLOUD, OBJ_NEAREST
from kinematics._kernels.error2d import count_unexplained
from kinematics._kernels.error3d import count_unexplained_cloud
from kinematics._kernels.fastmath import stream_state
from kinematics._kernels.objective import evaluate, observed
from kinematics._kernels.posture import drawn_views, project_posture
from kinematics._kernels.records import frame_obs, new_scratch
from kinematics._kernels.refine import refine_posture


# -- the per-frame procedure, shared by fit_frames and the lane kernel ---------------------
@njit(cache=True, nogil=True)
def clear_frame(out, f):
    """Frame ``f``'s outputs before it is fitted: NaN, no runs (a frame without observations
    keeps them)."""
    out.runs[f] = 0
    out.iterations[f] = 0
    out.pairs[f] = 0
    out.error[f] = np.nan
    out.angles[f, :] = np.nan
    out.view_error[f, :] = np.nan
    out.run_angles[f, :, :] = np.nan
    out.run_error[f, :] = np.nan


@njit(cache=True, nogil=True, inline="always")
def wants_run(run, min_runs, max_runs, e_keep, u_keep, threshold, max_unexplained):
    """Whether a frame gets run ``run``: the first ``min_runs`` always (candidates), then
    while the kept run is above the re-analysis threshold or leaves too many detections
    unexplained, ``max_runs`` at most."""
    u_limit = max_unexplained if max_unexplained >= 0 else 1 << 30
    return run < max_runs and (run < min_runs or not (e_keep <= threshold
                                                      and u_keep <= u_limit))


@njit(cache=True, nogil=True, inline="always")
def keeps(e, u, e_keep, u_keep, max_unexplained):
    """Whether a run (E ``e``, ``u`` unexplained detections) replaces the kept one: lower E,
    or with ``max_unexplained`` in use fewer unexplained detections first; ties keep the
    earlier run."""
    if max_unexplained < 0:
        return e < e_keep
    return u < u_keep or (u == u_keep and e < e_keep)


@njit(cache=True, nogil=True)
def take_runs(out, f, issued, run_u, run_pairs, max_unexplained):
    """Frame ``f``'s first ``issued`` runs taken in run order, as :func:`fit_frames` takes
    them after each (``run_u``, ``run_pairs``: each run's unexplained detections and
    refinement pairs): the kept run's (E, unexplained, index); its pairs go into
    ``out.pairs[f]``. For the backends that finish a frame's runs out of order."""
    e_keep, u_keep, kept = np.inf, 1 << 30, 0
    for r in range(issued):
        if keeps(out.run_error[f, r], run_u[r], e_keep, u_keep, max_unexplained):
            e_keep, u_keep, kept = out.run_error[f, r], run_u[r], r
            out.pairs[f] = run_pairs[r]
    return e_keep, u_keep, kept


@njit(cache=True, nogil=True, inline="always")
def same_markers(a, b, tol):
    """Whether every marker of ``a`` (n, 3) lies within ``tol`` of its place in ``b``."""
    same = True
    for i in range(a.shape[0]):
        dx = a[i, 0] - b[i, 0]
        dy = a[i, 1] - b[i, 1]
        dz = a[i, 2] - b[i, 2]
        same = same and dx * dx + dy * dy + dz * dz <= tol * tol
    return same


@njit(cache=True, nogil=True)
def finish_run(best, e, rp, rr, body, cams, dofs, schedule, error, obs, claim_gate, annealed,
               scratch):
    """After a run's annealing (best posture ``best``, its E ``e``): refinement, kept only if
    E did not grow, and the count of unexplained detections (``obs``: the frame's FrameObs;
    ``scratch``: a Scratch whose ``cs`` … ``nearest`` it uses). Updates ``best`` in place;
    returns (E, refinement pairs, unexplained)."""
    objective, obs3 = obs.objective, obs.obs3
    cs, sn, rot, pos = scratch.cs, scratch.sn, scratch.rot, scratch.pos
    mk, proj = scratch.mk, scratch.proj
    max_unexplained = schedule.max_unexplained
    pairs = 0
    if schedule.refine_steps > 0:
        # Refinement minimises squared pair residuals, not E: keep its result only if E
        # did not grow (it never makes a fit worse).
        annealed[:] = best
        _, pairs = refine_posture(best, dofs.free_idx, dofs, schedule.refine_steps,
                                  schedule.refine_gate, rp, rr, body, cams,
                                  drawn_views(cams.kind, objective), obs)
        project_posture(best, rp, rr, body, cams, cs, sn, rot, pos, mk, proj)
        e_refined = evaluate(objective, proj, mk, obs.points, obs.conf, obs.view_off, obs3,
                             error.bidirectional, error.weight, error.cap, error.penalty_cap,
                             error.one_to_one, scratch.per_view, scratch.nearest)
        if e_refined <= e:
            e = e_refined
        else:
            best[:] = annealed
            pairs = 0
    u = 0
    if max_unexplained >= 0 and objective == OBJ_NEAREST:
        # Detections far from every model marker: a limb on another's blobs leaves its own
        # unexplained, a fused blob does not.
        project_posture(best, rp, rr, body, cams, cs, sn, rot, pos, mk, proj)
        u = count_unexplained(proj, obs.points, obs.view_off, obs3, claim_gate)
    elif max_unexplained >= 0 and objective == OBJ_CLOUD:
        project_posture(best, rp, rr, body, cams, cs, sn, rot, pos, mk, proj)
        u = count_unexplained_cloud(mk, obs3, claim_gate)
    return e, pairs, u


@njit(cache=True, nogil=True)
def write_frame(out, f, keep, runs, rp, rr, body, cams, error, obs, scratch):
    """Frame ``f``'s outputs from its kept posture ``keep`` after ``runs`` runs (``obs``: the
    frame's FrameObs; ``scratch``: a Scratch)."""
    project_posture(keep, rp, rr, body, cams, scratch.cs, scratch.sn, scratch.rot,
                    scratch.pos, scratch.mk, scratch.proj)
    out.error[f] = evaluate(obs.objective, scratch.proj, scratch.mk, obs.points, obs.conf,
                            obs.view_off, obs.obs3, error.bidirectional, error.weight,
                            error.cap, error.penalty_cap, error.one_to_one, scratch.per_view,
                            scratch.nearest)
    out.view_error[f, :] = scratch.per_view
    out.angles[f, :] = keep
    out.runs[f] = runs


@njit(cache=True, nogil=True, parallel=True)
def fit_frames(seg_off, frame_ids, root_pos, root_rot, start, body, cams, dofs, schedule,
               error, obs, parts, out):
    """Fit many frames in parallel (``prange`` over segments of consecutive frames).

    Frames ``seg_off[s]:seg_off[s + 1]`` form segment ``s``, fitted in order by one thread;
    segments are independent. With ``start_previous`` a frame's first run starts from the
    previous frame's result in its segment (the segment's first frame from ``start``);
    otherwise every run starts from ``start``. Re-runs always start from ``start``. With
    ``refine_steps > 0`` each run's best posture is polished by
    :func:`kinematics._kernels.refine.refine_posture` (pairs within ``refine_gate`` pixels,
    axis ranges ``lo``, ``hi`` in radians) before it is scored. A frame whose error exceeds
    ``reanalysis_threshold`` is fitted again on the random stream of the next run index
    (Table 1 note), ``max_runs`` runs at most; the run with the lowest error is kept.

    Parameters (the namedtuples are defined in :mod:`kinematics.fit.problem`)
    ----------
    seg_off : (n_segments + 1,) int64; frame_ids : (n,) int64 frame numbers (seed streams).
    root_pos : (n, n_chains, 3); root_rot : (n, n_chains, 3, 3) seed rotations of free roots
        (identity otherwise); start : (n_state,) radians (lengths for translation entries).
    body : FoldedBody; cams : CameraArrays.
    dofs : DofArrays (free_idx, step, hist, nbins, dof_kind, lo, hi).
    schedule : Schedule (Table 1 and the fitter's own settings, ``start_previous``).
    error : ErrorArgs (bidirectional, weight, cap, penalty_cap).
    obs : ObservationArrays (objective: OBJ_NEAREST, OBJ_LABELLED or OBJ_POINTS3D; points
        (n_points, 2); conf (n_points,) weights of labelled keypoints; offsets (n * n_views +
        1,) frame-major; points3d (n, n_markers or 0, 4)).
    parts : Partitions (bounds (n_parts, 5): joints j0:j1 and markers m0:m1 each partition
        reaches, m0:m_own its own markers; dof_off/dofs its free entries; rounds;
        claim_gate): one partition anneals the whole body at once (the paper); more are
        annealed in turn
        (:func:`anneal_partitions`).
    out : FitOutputs: angles (n, n_state), NaN for frames without any observation; error
        (n,); view_error (n, n_views); runs, iterations (n,) int64 (iterations summed over
        runs); pairs (n,) int64 refinement pairs of the kept run (0 without); run_angles
        (n, R, n_state) and run_error (n, R) every run's result and E (NaN for runs not
        made; R >= max_runs), the candidate postures of :mod:`kinematics.fit.temporal`. At least
        ``min_runs`` runs are made on frames with observations.
    """
    free_idx = dofs.free_idx
    seed, reanalysis_threshold = schedule.seed, schedule.reanalysis_threshold
    max_runs, min_runs = schedule.max_runs, schedule.min_runs
    start_previous, max_unexplained = schedule.start_previous, schedule.max_unexplained
    counts = (schedule.n_end, schedule.n_l, schedule.n_tau)
    claim_gate, confirm = parts.claim_gate, parts.confirm
    partitioned = parts.bounds.shape[0] > 1 or parts.samples > 0
    objective, det_points, obs3 = obs.objective, obs.points, obs.points3d
    out_iterations, out_pairs = out.iterations, out.pairs
    out_run_angles, out_run_error = out.run_angles, out.run_error
    nv = cams.kind.shape[0]
    nj = body.parent.shape[0]
    nm = body.marker_joint.shape[0]
    na = start.shape[0]
    whole = (0, nj, 0, nm)
    for s in prange(seg_off.shape[0] - 1):
        scratch = new_scratch(na, nj, nm, nv)
        mk = scratch.mk
        best = scratch.best
        claimed = np.zeros(max(det_points.shape[0], obs3.shape[1]), np.bool_)
        d2 = np.empty(nm + obs3.shape[1] if objective == OBJ_CLOUD else 0)
        work = np.empty(na)
        keep = np.empty(na)
        keep_mk = np.empty((nm, 3))
        annealed = np.empty(na)
        first = start.copy()
        for f in range(seg_off[s], seg_off[s + 1]):
            fo = frame_obs(obs, f, nv)
            rp = root_pos[f]
            rr = root_rot[f]
            clear_frame(out, f)
            if observed(objective, fo.view_off, fo.obs3):  # else nothing to fit
                e_keep = np.inf
                run = 0
                u_keep = 1 << 30  # with max_unexplained < 0 only E decides (u stays 0)
                confirmed = confirm <= 0.0
                while wants_run(run, min_runs, max_runs, e_keep, u_keep, reanalysis_threshold,
                                max_unexplained) or (run < max_runs and not confirmed):
                    state = stream_state(seed, frame_ids[f], run)
                    origin = first if run == 0 else start
                    if partitioned:
                        e, its = anneal_partitions(origin, state, rp, rr, body, cams, dofs,
                                                   schedule, error, fo, parts, claimed, work,
                                                   scratch)
                    else:
                        e, its = anneal_chain(origin, free_idx, counts, state, rp, rr, body,
                                              cams, dofs, schedule, error, fo, whole, claimed,
                                              scratch, d2)
                    out_iterations[f] += its
                    e, pairs, u = finish_run(best, e, rp, rr, body, cams, dofs, schedule,
                                             error, fo, claim_gate, annealed, scratch)
                    out_run_angles[f, run, :] = best
                    out_run_error[f, run] = e
                    better = keeps(e, u, e_keep, u_keep, max_unexplained)
                    if confirm > 0.0:
                        project_posture(best, rp, rr, body, cams, scratch.cs, scratch.sn,
                                        scratch.rot, scratch.pos, mk, scratch.proj)
                        if run > 0 and same_markers(mk, keep_mk, confirm):
                            confirmed = True  # the best run and this one agree
                        elif better:
                            confirmed = False  # a new best, found once
                        if better:
                            keep_mk[:] = mk
                    if better:
                        e_keep = e
                        u_keep = u
                        keep[:] = best
                        out_pairs[f] = pairs
                    run += 1
                write_frame(out, f, keep, run, rp, rr, body, cams, error, fo, scratch)
                if start_previous:
                    first[:] = keep
