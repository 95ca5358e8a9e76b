"""The annealing loop of Eq. 6 (one chain over a state's free entries), the beam start
search, and the annealing of a partitioned body part by part. Twin:
:func:`kinematics.fit.anneal_reference` on the same random stream."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from kinematics._kernels.codes import DOF_HISTOGRAM, OBJ_CLOUD, OBJ_NEAREST
from kinematics._kernels.error2d import claim_detections, paper_error
from kinematics._kernels.error3d import claim_cloud, cloud_error_once, unclaimed_cloud
from kinematics._kernels.fastmath import GOLDEN, log_unit, mix64, next_uniform, sincos
from kinematics._kernels.objective import evaluate, partition_error
from kinematics._kernels.posture import (
    drawn_views,
    has_pinhole,
    posture_frames,
    posture_markers,
    project_posture,
)
from kinematics._kernels.records import FrameObs
from kinematics._kernels.refine import refine_posture


# -- histogram lookup ---------------------------------------------------------------------
@njit(cache=True, nogil=True, inline="always")
def hist_at(hist, nbins, i, x):
    """H_i(x) for x in radians: the value of the bin holding x (wraps), as
    :meth:`kinematics.model.histograms.Histogram.at`; no floating modulo in the common case."""
    n = nbins[i]
    nf = float(n)
    # floor((x_deg + 180) / (360 / n)) with multiplications only (a division per lookup
    # was a measurable part of the loop).
    k = int(math.floor(x * (nf * (0.5 / np.pi)) + 0.5 * nf))  # noqa: RUF046 (a float on CUDA)
    if k < 0 or k >= n:
        k = k % n
    return hist[i, k]


# -- simulated annealing (Sect. 2.3, Eq. 6) ----------------------------------------------
@njit(cache=True, nogil=True)
def anneal_chain(start, free_idx, counts, state, root_pos, root_rot, body, cams, dofs,
                 schedule, error, obs, span, claimed, scratch, d2):
    """One annealing run from ``start``; the best posture seen is left in ``scratch.best``.

    Each iteration draws ``j' = j + l·v`` with ``v_i = s(H_i)·r_i``, ``r_i ~ U[-1, 1]``
    (Eq. 6) for the free axes ``free_idx`` in order (histogram entries first, then range
    entries); ``r_i`` is redrawn while
    ``H_i(j'_i) < th`` (for entries of ``dof_kind`` DOF_RANGE: while outside
    ``[lo_i, hi_i]``), at most ``max_redraws`` times, after which axis i stays where it is
    for this iteration. A draw ``u`` made first in each iteration decides acceptance by the
    Metropolis criterion at temperature τ: always if E does not grow, else if
    ``ΔE < -τ·log(u)``, i.e. ``u < exp(-ΔE/τ)``. τ is multiplied by ``c_tau`` every ``n_tau``
    iterations and l by ``c_l`` every ``n_l``. Stops after ``n_end`` iterations or once the
    best ``E < eps``.

    Parameters
    ----------
    start : (n_axes,) radians; locked axes hold their value and are never changed.
    free_idx : (n_free,) int64, the entries moved (``dofs.free_idx`` or a partition's).
    counts : (n_end, n_l, n_tau), the schedule's counts for this run (a partition's share).
    state : uint64 start state of the random stream (:func:`stream_state`).
    root_pos, root_rot : the frame's root positions and seed rotations.
    body : FoldedBody; cams : CameraArrays; dofs : DofArrays (step, histogram tables, kinds,
        ranges); schedule : Schedule (th, max_redraws, tau0, l0, c_l, c_tau, eps); error :
        ErrorArgs; obs : FrameObs (:mod:`kinematics._kernels.records`).
    span : (j0, j1, m0, m1), the joints and markers the moved entries reach (a partition's
        subtree; ``0, nj, 0, nm`` for the whole body). With a partition, E is
        :func:`partition_error` of its markers ``m0:m1`` (detections ``claimed`` by other
        partitions excluded), and ``scratch.rot``, ``.pos``, ``.mk``, ``.proj`` must hold
        the current posture of the rest.
    scratch : Scratch; d2 (n_markers + cloud rows,) float scratch of
        :func:`cloud_error_once` for a cloud (shorter, e.g. empty: :func:`cloud_error`).

    Returns
    -------
    best_error : float
    iterations : int
    """
    # the records unpacked once: the loop passes plain arrays
    n_end, n_l, n_tau = counts
    j0, j1, m0, m1 = span
    step, hist, nbins, lo, hi = dofs.step, dofs.hist, dofs.nbins, dofs.lo, dofs.hi
    dof_kind = dofs.dof_kind
    th, max_redraws, eps = schedule.th, schedule.max_redraws, schedule.eps
    tau0, l0, c_l, c_tau = schedule.tau0, schedule.l0, schedule.c_l, schedule.c_tau
    bidirectional, weight, cap = error.bidirectional, error.weight, error.cap
    penalty_cap, one = error.penalty_cap, error.one_to_one
    objective, points, conf, view_off, obs3 = (obs.objective, obs.points, obs.conf,
                                               obs.view_off, obs.obs3)
    cur, cand, best, cs, sn = scratch.cur, scratch.cand, scratch.best, scratch.cs, scratch.sn
    rot, pos, mk, proj = scratch.rot, scratch.pos, scratch.mk, scratch.proj
    per_view, nearest = scratch.per_view, scratch.nearest
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body  # the loop's arrays (records: refcounts)
    P, K, dist, R, t = cams.P, cams.K, cams.dist, cams.R, cams.t
    n_free = free_idx.shape[0]
    n_hist = 0  # free_idx holds the DOF_HISTOGRAM entries first
    while n_hist < n_free and dof_kind[free_idx[n_hist]] == DOF_HISTOGRAM:
        n_hist += 1
    views = drawn_views(cams.kind, objective)
    any_pinhole = has_pinhole(views)
    marks = obs3  # hidden marks not projected (3D objectives read no projection)
    rs = np.uint64(state)  # the stream state; int64 arithmetic with uint64 would be float
    for k in range(start.shape[0]):
        cur[k] = start[k]
        cand[k] = start[k]
        best[k] = start[k]
        sn[k], cs[k] = sincos(start[k])
    whole = j0 == 0 and j1 == body.parent.shape[0] and m0 == 0 and \
        m1 == body.marker_joint.shape[0]
    unexplained = weight if bidirectional else 0.0  # the partition's unexplained-blob weight
    # a cloud with nothing claimed (a partition's comes without the claimed points): each
    # distance computed once (cloud_error_once), the same E
    once = objective == OBJ_CLOUD and not one and (whole or claimed.shape[0] == 0) and \
        d2.shape[0] >= mk.shape[0] + obs3.shape[0]
    marker_d2 = d2[:mk.shape[0]]
    point_d2 = d2[mk.shape[0]:]
    posture_frames(cand, cs, sn, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                   post_trans, elem_axis, elem_index, joint_flags, slide_index, rot,
                   pos, j0, j1)
    posture_markers(marker_joint, marker_local, rot, pos, mk, proj, views, P, K, dist,
                    R, t, any_pinhole, m0, m1, marks)
    if not whole:
        e_cur = partition_error(objective, proj, mk, points, conf, view_off, obs3, cap, m0,
                                m1, claimed, unexplained, penalty_cap, one, nearest)
    else:
        e_cur = evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional,
                         weight, cap, penalty_cap, one, per_view, nearest)
    e_best = e_cur
    tau = tau0
    length = l0
    to_tau = n_tau  # countdowns: two integer modulos per iteration cost more than these
    to_l = n_l
    it = 0
    done = e_best < eps
    while it < n_end and not done:
        # Metropolis (Kirkpatrick et al. 1983): accept if u < exp(-ΔE/τ), i.e. if
        # ΔE < τ·(-log u). The draw and its logarithm come first, off the iteration's
        # critical path (candidate -> kinematics -> E -> acceptance).
        rs, u = next_uniform(rs)
        e_accept = e_cur + tau * -log_unit(u)
        # Histogram-checked angles first, then range-checked entries (free_idx lists them
        # in that order): two loops keep the kind test out of the redraw loop.
        for q in range(n_hist):
            i = free_idx[q]
            scale = length * step[i]
            ok = False
            tries = 0
            x = cur[i]
            while not ok and tries <= max_redraws:
                rs, u = next_uniform(rs)
                x = cur[i] + scale * (2.0 * u - 1.0)
                ok = hist_at(hist, nbins, i, x) >= th
                tries += 1
            x = x if ok else cur[i]
            cand[i] = x
            sn[i], cs[i] = sincos(x)
        for q in range(n_hist, n_free):
            i = free_idx[q]
            scale = length * step[i]
            ok = False
            tries = 0
            x = cur[i]
            while not ok and tries <= max_redraws:
                rs, u = next_uniform(rs)
                x = cur[i] + scale * (2.0 * u - 1.0)
                ok = lo[i] <= x and x <= hi[i]
                tries += 1
            x = x if ok else cur[i]
            cand[i] = x
            sn[i], cs[i] = sincos(x)
        posture_frames(cand, cs, sn, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                       post_trans, elem_axis, elem_index, joint_flags, slide_index, rot,
                       pos, j0, j1)
        posture_markers(marker_joint, marker_local, rot, pos, mk, proj, views, P, K, dist,
                        R, t, any_pinhole, m0, m1, marks)
        if once:
            e = cloud_error_once(mk, obs3, m0, m1, unexplained, cap, penalty_cap, nearest,
                                 marker_d2, point_d2)
        elif not whole:
            e = partition_error(objective, proj, mk, points, conf, view_off, obs3, cap, m0,
                                m1, claimed, unexplained, penalty_cap, one, nearest)
        elif objective == OBJ_NEAREST and not bidirectional and not one and \
                obs3.shape[0] == 0:  # the paper's case: no marker marked hidden
            e = paper_error(proj, points, view_off, cap)
        else:
            e = evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional,
                         weight, cap, penalty_cap, one, per_view, nearest)
        if e <= e_cur or e < e_accept:
            e_cur = e
            for q in range(n_free):
                cur[free_idx[q]] = cand[free_idx[q]]
            if e < e_best:
                e_best = e
                for q in range(n_free):
                    best[free_idx[q]] = cand[free_idx[q]]
        it += 1
        to_tau -= 1
        if to_tau == 0:
            tau *= c_tau
            to_tau = n_tau
        to_l -= 1
        if to_l == 0:
            length *= c_l
            to_l = n_l
        done = e_best < eps
    return e_best, it


#: Postures the start search keeps from one stage to the next (its beam width).
BEAM = 32


@njit(cache=True, nogil=True)
def beam_start(work, s0, s1, parts, state, rp, rr, body, cams, dofs, schedule, error, obs,
               span, claimed, scratch):
    """A partition's start posture by a beam search along its joints, into ``work``.

    Stage ``s`` (``s0:s1`` of ``parts``' stages, one joint's entries, root first) draws
    ``BEAM · parts.samples`` values for its entries, spread over the postures kept so far —
    each entry uniform in ``[lo, hi]``, a histogram angle redrawn (at most 16 times) while
    implausible — and keeps the ``BEAM`` postures with the lowest :func:`partition_error` of
    the markers the stage places (``m0:stage_mark[s]``, at most ``m1`` of ``span``;
    detections ``claimed`` by other partitions left out), each kept posture's undrawn
    values counting too. Joint by joint the search follows the limb outward along its own
    markers, so annealing starts in the right basin where the start posture lies nearer
    another limb's markers. ``scratch``'s ``rot`` … ``proj`` must hold the current posture
    of the rest of the body. With ``schedule.refine_steps`` the best posture is polished by
    Levenberg-Marquardt at the end. Returns the E of the partition's markers at the best
    posture before that polish."""
    j0, j1, m0, m1 = span
    stage_dof_off, stage_dofs = parts.stage_dof_off, parts.stage_dofs
    stage_mark, stage_joint, n_samples = parts.stage_mark, parts.stage_joint, parts.samples
    hist, nbins, dof_kind, lo, hi = dofs.hist, dofs.nbins, dofs.dof_kind, dofs.lo, dofs.hi
    th = schedule.th
    cap, penalty_cap, one = error.cap, error.penalty_cap, error.one_to_one
    objective, points, conf, view_off, obs3 = (obs.objective, obs.points, obs.conf,
                                               obs.view_off, obs.obs3)
    cs, sn, rot, pos, mk = scratch.cs, scratch.sn, scratch.rot, scratch.pos, scratch.mk
    proj, nearest = scratch.proj, scratch.nearest
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body  # the loop's arrays (records: refcounts)
    P, K, dist, R, t = cams.P, cams.K, cams.dist, cams.R, cams.t
    ns = work.shape[0]
    e_first = np.inf
    views = drawn_views(cams.kind, objective)
    any_pinhole = has_pinhole(views)
    marks = obs3  # hidden marks not projected (3D objectives read no projection)
    cloud, free = obs3, claimed  # what the draws are scored against
    if objective == OBJ_CLOUD:
        cloud, free = unclaimed_cloud(obs3, claimed)
    rs = state
    beams = np.empty((BEAM, ns))
    beams[0, :] = work
    nb = 1
    most = BEAM * (n_samples + 1) * 2
    cands = np.empty((most, ns))
    cand_e = np.empty(most)
    for st in range(s0, s1):
        d0 = stage_dof_off[st]
        d1 = stage_dof_off[st + 1]
        m_end = min(stage_mark[st], m1)
        # A stage's entries move no marker before its first (stages are grouped so), and
        # nothing before its first joint: a draw recomputes only those joints and markers
        # and adds their E to the beam's, which is computed once per beam. With one-to-one
        # the markers' costs are not separable, so every draw scores them all.
        ms = m0 if (st == s0 or one) else min(stage_mark[st - 1], m_end)
        jf = j0 if one else stage_joint[st]
        je = jf  # one past the last joint that carries a marker the stage places
        for m in range(ms, m_end):
            je = max(je, marker_joint[m] + 1)
        draws = (BEAM * n_samples) // nb
        nc = 0
        for b in range(nb):
            for k in range(ns):
                sn[k], cs[k] = sincos(beams[b, k])
            # The beam's posture (the joints before the stage's first stay so for its
            # draws) and the E of the markers earlier stages placed
            posture_frames(beams[b], cs, sn, rp, rr, parent, chain, pre_rot, pre_trans,
                           post_trans, elem_axis, elem_index, joint_flags, slide_index, rot,
                           pos, j0, j1)
            posture_markers(marker_joint, marker_local, rot, pos, mk, proj, views, P, K, dist,
                            R, t, any_pinhole, m0, ms, marks)
            e_beam = 0.0
            if ms > m0:
                e_beam = partition_error(objective, proj, mk, points, conf, view_off, cloud,
                                         cap, m0, ms, free, 0.0, penalty_cap, one, nearest)
            for smp in range(draws + 1):
                cands[nc, :] = beams[b]
                if smp > 0:  # draw 0 keeps the beam's own values
                    for q in range(d0, d1):
                        i = stage_dofs[q]
                        ok = False
                        tries = 0
                        x = beams[b, i]
                        while not ok and tries < 16:
                            rs, u = next_uniform(rs)
                            x = lo[i] + (hi[i] - lo[i]) * u
                            ok = dof_kind[i] != DOF_HISTOGRAM or hist_at(hist, nbins, i, x) >= th
                            tries += 1
                        cands[nc, i] = x
                for q in range(d0, d1):
                    i = stage_dofs[q]
                    sn[i], cs[i] = sincos(cands[nc, i])
                posture_frames(cands[nc], cs, sn, rp, rr, parent, chain, pre_rot, pre_trans,
                               post_trans, elem_axis, elem_index, joint_flags, slide_index, rot,
                               pos, jf, je)
                posture_markers(marker_joint, marker_local, rot, pos, mk, proj, views, P, K, dist,
                                R, t, any_pinhole, ms, m_end, marks)
                cand_e[nc] = e_beam + partition_error(objective, proj, mk, points, conf,
                                                      view_off, cloud, cap, ms, m_end, free,
                                                      0.0, penalty_cap, one, nearest)
                nc += 1
        # Keep the best BEAM. Keeping at most 4 per distinct match (which point each placed
        # marker takes) starved the stages whose entries the placed markers do not fix (a
        # coxa's roll about its own axis, then the femur's): the fly's runs agreed in 44 %
        # against 73 % (docs/benchmarks.md, "The start search keeps its best").
        order = np.argsort(cand_e[:nc])
        e_first = cand_e[order[0]]
        nb = min(BEAM, nc)
        for b in range(nb):
            beams[b, :] = cands[order[b]]
    # Only the best is polished: polishing every kept posture after each stage (32 per joint)
    # was half of a fly run's cost besides annealing, and measured no better (docs/benchmarks.md)
    if schedule.refine_steps > 0 and s1 > s0:
        refine_posture(beams[0], stage_dofs[stage_dof_off[s0]:stage_dof_off[s1]], dofs,
                       schedule.refine_steps, schedule.refine_gate, rp, rr, body, cams,
                       views, obs)
    work[:] = beams[0]
    return e_first


@njit(cache=True, nogil=True)
def anneal_partitions(origin, state, rp, rr, body, cams, dofs, schedule, error, obs, parts,
                      claimed, work, scratch):
    """One annealing run over partitions, each in turn (partitioned sampling): partition p
    moves only its own entries, with its share of ``schedule`` (N_end, N_l and N_tau times
    its share of the free entries, at least 1: a round anneals about N_end), scored by
    :func:`partition_error` of the markers it reaches (in the first round a trunk by its own
    markers only: its limbs are not fitted yet). The first round fits every partition
    against all detections; later rounds (``rounds`` > 1) exclude the detections that the
    other partitions' markers explain (:func:`claim_detections` within ``claim_gate`` px),
    so limbs do not share or take each other's markers. With ``samples`` > 0 each partition
    of the first round starts from a beam search along its joints (:func:`beam_start`) and
    may not use the detections that the partitions fitted before it explain. Leaves the
    result in ``scratch.best``.

    Returns
    -------
    error : float, E of the whole posture (:func:`evaluate`)
    iterations : int, summed over partitions and rounds
    """
    n_end, n_l, n_tau = schedule.n_end, schedule.n_l, schedule.n_tau
    bounds, part_off, part_dofs = parts.bounds, parts.dof_off, parts.dofs
    rounds, claim_gate, samples, stage_off = (parts.rounds, parts.claim_gate, parts.samples,
                                              parts.stage_off)
    objective, points, view_off, obs3 = obs.objective, obs.points, obs.view_off, obs.obs3
    cur, best, rot, pos, mk, proj = (scratch.cur, scratch.best, scratch.rot, scratch.pos,
                                     scratch.mk, scratch.proj)
    cs, sn = scratch.cs, scratch.sn
    cap, penalty_cap, one = error.cap, error.penalty_cap, error.one_to_one
    marker_joint = body.marker_joint
    work[:] = origin
    its = 0
    rs = np.uint64(state)
    claimers = np.zeros(marker_joint.shape[0], np.bool_)
    n_parts = bounds.shape[0]
    order = np.arange(n_parts)
    limbs_only = n_parts > 1
    for p in range(n_parts):
        limbs_only = limbs_only and bounds[p, 4] >= bounds[p, 3]
    ordered = samples > 0 and limbs_only
    found = np.empty((n_parts if ordered else 0, work.shape[0]))  # each limb's own search
    unclaimed = np.zeros(claimed.shape[0] if ordered else 0, np.bool_)
    if ordered:
        # Limbs on roots of their own (no trunk to fit first): each searches its start
        # without claims, and the clearest (lowest E per marker) go first and claim their
        # points, so a limb that happens to come first cannot take a clearer one's.
        project_posture(work, rp, rr, body, cams, cs, sn, rot, pos, mk, proj)
        claimed[:] = False
        clear = np.empty(n_parts)
        for p in range(n_parts):
            cur[:] = work
            rs, _ = next_uniform(rs)
            clear[p] = beam_start(
                cur, stage_off[p], stage_off[p + 1], parts, mix64(rs ^ GOLDEN), rp, rr, body,
                cams, dofs, schedule, error, obs,
                (bounds[p, 0], bounds[p, 1], bounds[p, 2], bounds[p, 3]), claimed,
                scratch) / max(1, bounds[p, 3] - bounds[p, 2])
            found[p, :] = cur
        order = np.argsort(clear)
    for r in range(rounds):
        for k in range(n_parts):
            p = order[k] if r == 0 else k
            project_posture(work, rp, rr, body, cams, cs, sn, rot, pos, mk, proj)
            j0, j1, m0, m1 = bounds[p, 0], bounds[p, 1], bounds[p, 2], bounds[p, 3]
            if r == 0 and bounds[p, 4] > m0:
                m1 = bounds[p, 4]  # a trunk before its limbs are fitted: its own markers
            claimers[:] = False
            if r > 0:  # every other partition claims
                claimers[:] = True
                claimers[m0:m1] = False
            elif samples > 0:  # the partitions fitted before this one claim
                for q in order[:k]:
                    claimers[bounds[q, 2]:bounds[q, 4]] = True
            if objective == OBJ_NEAREST:
                claim_detections(proj, points, view_off, obs3, claimers, claim_gate,
                                 claimed)
            elif objective == OBJ_CLOUD:
                claim_cloud(mk, obs3, claimers, claim_gate, claimed)
            else:
                claimed[:] = False
            rs, _ = next_uniform(rs)  # a stream of its own for each partition and round
            dofs_p = part_dofs[part_off[p]:part_off[p + 1]]
            searched = False
            if r == 0 and ordered:
                # the limb's own search stands unless a clearer limb claimed its points
                for q in range(dofs_p.shape[0]):
                    work[dofs_p[q]] = found[p, dofs_p[q]]
                project_posture(work, rp, rr, body, cams, cs, sn, rot, pos, mk, proj)
                searched = partition_error(
                    objective, proj, mk, points, obs.conf, view_off, obs3, cap, m0, m1,
                    claimed, 0.0, penalty_cap, one, scratch.nearest) == partition_error(
                    objective, proj, mk, points, obs.conf, view_off, obs3, cap, m0, m1,
                    unclaimed, 0.0, penalty_cap, one, scratch.nearest)
            if r == 0 and samples > 0 and not searched:
                beam_start(work, stage_off[p], stage_off[p + 1], parts, mix64(rs ^ GOLDEN), rp,
                           rr, body, cams, dofs, schedule, error, obs, (j0, j1, m0, m1),
                           claimed, scratch)
            cloud, free = obs3, claimed
            if objective == OBJ_CLOUD:  # the same E, without the claimed points
                cloud, free = unclaimed_cloud(obs3, claimed)
            # the run's schedule shared by axes: a round anneals about N_end in all
            share = dofs_p.shape[0] / max(1, part_dofs.shape[0])
            counts = (max(1, round(n_end * share)), max(1, round(n_l * share)),
                      max(1, round(n_tau * share)))
            _, n = anneal_chain(work, dofs_p, counts, mix64(rs), rp, rr, body, cams, dofs,
                                schedule, error, FrameObs(objective, points, obs.conf,
                                                          view_off, cloud),
                                (j0, j1, m0, m1), free, scratch,
                                np.empty(mk.shape[0] + cloud.shape[0]))
            its += n
            work[:] = best
    project_posture(work, rp, rr, body, cams, cs, sn, rot, pos, mk, proj)
    best[:] = work
    return evaluate(objective, proj, mk, points, obs.conf, view_off, obs3, error.bidirectional,
                    error.weight, cap, penalty_cap, one, scratch.per_view, scratch.nearest), its
