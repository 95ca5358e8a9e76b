"""Partitioned annealing: partitions of a body, the partition cost against the twin, limbs
that may not share a detection, and a three-legged body fitted limb by limb."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinematics._kernels import codes as _codes
from kinematics._kernels import error2d as _error2d
from kinematics._kernels import objective as _objective
from kinematics.errors import KinematicsError
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.partitions import partitions_of
from kinematics.fit.problem import FitProblem
from kinematics.model import Body
from kinematics.model.chain_xml import load_body
from tests.fixtures.bodies import three_legs
from tests.fixtures.cameras import top_and_side
from tests.fixtures.paths import CHAINS
from tests.fixtures.planted import marker_errors, planted_postures
from videotrack.synth.paper_setup import locust_cameras


def test_partitions_trunk_first_then_each_limb():
    body = three_legs()
    pr = FitProblem.build(body, top_and_side())
    parts = partitions_of(pr)
    assert parts.bounds.shape == (4, 5)
    names = body.joint_names
    tops = [names[j] for j in parts.bounds[:, 0]]
    assert tops == ["body", "a_hip", "b_hip", "c_hip"]
    nm = len(body.marker_names)
    np.testing.assert_array_equal(parts.bounds[0], [0, len(names), 0, nm, 2])  # trunk: all,
    # scored by its own markers (head, tail) before the legs are fitted
    labels = body.axis_labels
    first = [labels[i] for i in parts.dofs[parts.dof_off[0]: parts.dof_off[1]]]
    assert first == ["body.turn"]
    second = [labels[i] for i in parts.dofs[parts.dof_off[1]: parts.dof_off[2]]]
    assert second == ["a_hip.yaw", "a_hip.lift", "a_knee.flex"]
    assert sorted(parts.dofs.tolist()) == sorted(pr.free_idx.tolist())
    assert partitions_of(pr, "none").bounds.shape == (1, 5)


def test_single_chains_are_one_partition_and_the_fly_is_six():
    locust = load_body(CHAINS / "locust_hindleg.xml")
    assert partitions_of(FitProblem.build(locust, locust_cameras())).bounds.shape == (1, 5)
    fly = load_body(CHAINS / "fly_six_legs.xml")
    parts = partitions_of(FitProblem.build(fly, locust_cameras()))
    assert parts.bounds.shape == (6, 5)
    assert (np.diff(parts.bounds[:, 2]) > 0).all()  # each leg's markers, in order


def test_partition_cost_equals_the_twin_on_its_markers():
    """No claims: the partition's E is Eq. 5 (capped) summed over its own markers only."""
    rng = np.random.default_rng(0)
    nv, nm = 2, 7
    proj = rng.uniform(0, 100, (nv, nm, 2))
    counts = [9, 5]
    pts = rng.uniform(0, 100, (sum(counts), 2))
    off = np.r_[0, np.cumsum(counts)].astype(np.int64)
    for cap in (np.inf, 6.0):
        for m0, m1 in ((0, 7), (2, 5), (6, 7)):
            got = _objective.partition_error(0, proj, np.zeros((nm, 3)), pts, np.ones(len(pts)),
                                             off,
                                     np.zeros((nm, 4)), cap, m0, m1,
                                     np.zeros(len(pts), np.bool_), 0.0, 3.0, False,
                                     np.empty(nm, np.int64))
            want = 0.0
            for v in range(nv):
                d = np.linalg.norm(proj[v, m0:m1, None] - pts[off[v]:off[v + 1]][None], axis=2)
                want += np.minimum(d.min(axis=1), cap).sum()
            assert got == pytest.approx(want, rel=1e-12, abs=1e-9)


def test_claimed_detections_are_not_shared():
    """Leg B's marker sits nearer leg A's blob than its own: with the blob claimed by A's
    marker, B must use its own detection."""
    proj = np.array([[[10.0, 10.0], [11.0, 10.0]]])  # marker 0 of A, marker 1 of B
    pts = np.array([[10.0, 10.0], [16.0, 10.0]])
    off = np.array([0, 2], np.int64)
    claimed = np.zeros(2, np.bool_)
    A = np.array([True, False])  # the claimers: A's marker
    # markers outside B claim
    _error2d.claim_detections(proj, pts, off, _codes.NO_HIDDEN, A, 3.0, claimed)
    assert claimed.tolist() == [True, False]
    e = _objective.partition_error(0, proj, np.zeros((2, 3)), pts, np.ones(2), off,
                                   np.zeros((2, 4)),
                           np.inf, 1, 2, claimed, 0.0, 3.0, False, np.empty(2, np.int64))
    assert e == pytest.approx(5.0)
    _error2d.claim_detections(proj, pts, off, _codes.NO_HIDDEN, A, 0.5, claimed)
    assert claimed.tolist() == [True, False]
    far = np.array([[[40.0, 40.0], [11.0, 10.0]]])  # A's marker is far from every blob
    _error2d.claim_detections(far, pts, off, _codes.NO_HIDDEN, A, 3.0, claimed)
    assert claimed.tolist() == [False, False]


def test_three_legs_fitted_limb_by_limb():
    body = three_legs()
    cams = top_and_side()
    angles, frames = planted_postures(body, cams, 12, seed=4)
    params = AnnealParams.paper(refine=True, reanalysis_threshold=2.0, partitions="auto"
                          ).with_schedule(4000)
    res = Fitter(body, cams, params).fit(frames)
    err = marker_errors(body, res, angles)
    assert np.median(err) < 0.1, err
    assert (err < 1.0).mean() >= 0.9, err


def test_auto_threshold_is_measured_on_the_video():
    """threshold_mode 'auto': the threshold follows the recording's own E per marker image,
    so good frames are 'ok' and a frame whose markers were swapped is flagged."""
    body = three_legs()
    cams = top_and_side()
    _, frames = planted_postures(body, cams, 30, seed=6)
    # frame 7: one leg's tip drawn 15 px away in the top view (a wrong detection)
    frames[7][0] = frames[7][0].copy()
    frames[7][0][4] += (15.0, 0.0)
    params = AnnealParams.paper(refine=True, threshold_mode="auto", max_runs=2).with_schedule(3000)
    res = Fitter(body, cams, params).fit(frames)
    status = [r.status for r in res]
    assert status[7] == "failed"
    assert sum(s == "failed" for s in status) <= 2, status


def test_partition_pays_for_blobs_it_leaves_unexplained():
    """Bidirectional modes: an unclaimed detection none of the partition's markers takes
    costs penalty · min(distance, penalty_cap); a claimed one costs nothing."""
    proj = np.array([[[0.0, 0.0], [10.0, 0.0], [50.0, 0.0]]])  # partition = markers 0, 1
    pts = np.array([[0.0, 0.0], [12.0, 0.0], [14.0, 0.0], [50.0, 0.0]])
    off = np.array([0, 4], np.int64)
    claimed = np.zeros(4, np.bool_)
    claimers = np.array([False, False, True])  # marker 2 claims (50, 0)
    _error2d.claim_detections(proj, pts, off, _codes.NO_HIDDEN, claimers, 3.0, claimed)
    args = (0, proj, np.zeros((3, 3)), pts, np.ones(4), off, np.zeros((3, 4)), np.inf, 0, 2,
            claimed)
    plain = _objective.partition_error(*args, 0.0, 3.0, False, np.empty(3, np.int64))
    assert plain == pytest.approx(0.0 + 2.0)
    bounded = _objective.partition_error(*args, 2.0, 3.0, False, np.empty(3, np.int64))
    assert bounded == pytest.approx(2.0 + 2.0 * min(4.0, 3.0))  # (14, 0) is left over


def test_unexplained_detections_trigger_reanalysis_and_the_flag():
    """max_unexplained: a fit that leaves a detection far from every marker is re-run, and
    flagged if it still does; a detection every fit must leave (a ghost) flags the frame."""
    body = three_legs()
    cams = top_and_side()
    _, frames = planted_postures(body, cams, 6, seed=8)
    frames[2][0] = np.vstack([frames[2][0], [[5.0, 5.0]]])  # a ghost far from the body
    params = AnnealParams.paper(refine=True, max_unexplained=0, reanalysis_threshold=2.0
                          ).with_schedule(3000)
    res = Fitter(body, cams, params).fit(frames)
    assert res[2].unexplained == 1 and res[2].status == "failed" and res[2].runs == 5
    assert all(r.unexplained == 0 for k, r in enumerate(res) if k != 2)
    off = Fitter(body, cams, replace(params, max_unexplained=None)).fit(frames)
    assert off[2].status != "failed" and off[2].unexplained == 1
    with pytest.raises(KinematicsError, match="max_unexplained"):
        AnnealParams.paper(max_unexplained=-2)


def test_block_residuals_equal_the_per_frame_ones(monkeypatch):
    """A block's marker residuals and unexplained counts, computed in one kernel call, are
    the per-frame ones: with a ghost, an empty view and a frame without detections."""
    body = three_legs()
    cams = top_and_side()
    _, frames = planted_postures(body, cams, 6, seed=8)
    frames[2][0] = np.vstack([frames[2][0], [[5.0, 5.0]]])  # a ghost far from the body
    frames[3][1] = np.empty((0, 2))
    frames[4] = [np.empty((0, 2)), np.empty((0, 2))]
    params = AnnealParams.paper(refine=True, max_unexplained=0, reanalysis_threshold=2.0
                                ).with_schedule(500)
    fitter = Fitter(body, cams, params)
    batched = []
    block_residuals = Fitter._block_residuals

    def spy(self, *args):
        out = block_residuals(self, *args)
        batched.append(out is not None)
        return out

    monkeypatch.setattr(Fitter, "_block_residuals", spy)
    together = fitter.fit(frames)
    assert batched and all(batched)
    monkeypatch.setattr(Fitter, "_block_residuals", lambda *args: None)
    alone = fitter.fit(frames)
    assert together[4].runs == 0 and together[2].unexplained == 1
    for a, b in zip(together, alone, strict=True):
        np.testing.assert_array_equal(a.angles_deg, b.angles_deg)
        np.testing.assert_array_equal(a.marker_residuals, b.marker_residuals)
        assert (a.unexplained, a.matched, a.status) == (b.unexplained, b.matched, b.status)
        np.testing.assert_array_equal(a.worst_px, b.worst_px)


def test_start_search_stages_follow_each_leg_outward():
    """The start search draws a fly leg's axes joint by joint, each stage scored by the
    markers those axes place (the thorax-coxa joint's three axes place the coxa's end)."""
    fly = load_body(CHAINS / "fly_six_legs.xml")
    parts = partitions_of(FitProblem.build(fly, locust_cameras()), samples=8)
    assert parts.samples == 8
    first = parts.stage_off[1]  # the first leg's stages
    labels = fly.axis_labels
    stages = [[labels[i] for i in parts.stage_dofs[parts.stage_dof_off[s]:
                                                   parts.stage_dof_off[s + 1]]]
              for s in range(first)]
    assert [s[0].split(".")[0] for s in stages] == ["LF_ThC", "LF_CTr", "LF_FTi", "LF_TiTa"]
    assert len(stages[0]) == 3
    assert parts.stage_mark[:first].tolist() == [2, 3, 4, 5]  # markers placed so far
    assert sorted(parts.stage_dofs.tolist()) == sorted(parts.dofs.tolist())


def test_start_search_finds_limbs_the_start_posture_misses():
    """start_samples: each limb starts from a search along its joints, so a short schedule
    that leaves limbs where the mean posture put them still finds every planted posture."""
    body = three_legs()
    cams = top_and_side()
    angles, frames = planted_postures(body, cams, 12, seed=4)
    base = AnnealParams.paper(refine=True, reanalysis_threshold=2.0, max_runs=1
                              ).with_schedule(300)
    plain = marker_errors(body, Fitter(body, cams, base).fit(frames), angles)
    searched = marker_errors(body, Fitter(body, cams, replace(base, start_samples=32)
                                          ).fit(frames), angles)
    assert (searched < 1.0).sum() > (plain < 1.0).sum(), (plain, searched)
    assert (searched < 1.0).mean() >= 0.9, searched


def test_auto_threshold_survives_e_in_steps():
    """E per marker image in steps (a flickering ghost adds a fixed cost): the MAD of a
    sample mostly on one step is ~0, which would fail every frame on the next step."""
    from kinematics.fit import auto_threshold

    rng = np.random.default_rng(1)
    normal = 2.0 + 0.1 * rng.standard_normal(400)
    med = np.median(normal)
    mad = np.median(np.abs(normal - med))
    assert auto_threshold(normal, 6.0, 0.5) == pytest.approx(med + 6 * 1.4826 * mad)
    steps = np.r_[np.full(40, 1.880), 1.880 + 1e-3 * rng.random(20), np.full(30, 2.255),
                  np.full(10, 3.13)]
    med = np.median(steps)
    assert med + 6 * 1.4826 * np.median(np.abs(steps - med)) < 1.9  # the MAD alone
    assert auto_threshold(steps, 6.0, 0.5) > 2.255  # the next step is not a failure
    assert auto_threshold(np.full(10, 0.1), 6.0, 0.5) == 0.5  # the floor


def test_runs_confirm_each_other():
    """confirm_runs: a frame is re-run until two runs put every marker within ambiguous_move
    segment lengths of each other; it keeps the lowest E, never worse than without, its
    status stays 'ok' (confirming is no re-analysis), and 'auto' confirms bodies of several
    partitions and bodies whose markers are matched in 3D (a cloud)."""
    body = three_legs()
    cams = top_and_side()
    _, frames = planted_postures(body, cams, 10, seed=6)
    # (60 iterations fit few frames well: no noise model, whose set-up check would refuse)
    base = AnnealParams(candidates=1, threshold_mode="absolute", reanalysis_threshold=1e6,
                        max_runs=6, start_samples=0, ambiguous_move=0.02, confirm_runs="off",
                        noise_floor_px=None).with_schedule(60)
    plain = Fitter(body, cams, base).fit(frames)
    confirmed = Fitter(body, cams, replace(base, confirm_runs="on")).fit(frames)
    assert all(r.runs == 1 for r in plain)
    assert all(2 <= r.runs <= 6 for r in confirmed)
    assert any(r.runs > 2 for r in confirmed), [r.runs for r in confirmed]
    assert all(c.error <= p.error for c, p in zip(confirmed, plain, strict=True))
    assert all(r.status == "ok" for r in confirmed)
    assert Fitter(body, cams, base)._partitions(replace(base, confirm_runs="auto")).confirm > 0
    single = load_body(CHAINS / "fly_six_legs.xml").chains[:1]
    one = Fitter(Body("leg", single, "mm"), locust_cameras(), base)
    assert one._partitions(replace(base, confirm_runs="auto")).confirm == 0
    assert one._partitions(replace(base, confirm_runs="auto"), cloud=True).confirm > 0
    with pytest.raises(KinematicsError, match="confirm_runs"):
        AnnealParams(confirm_runs="maybe")


def test_partitions_share_the_schedule_by_axes():
    """A body in partitions anneals N_end iterations a round in all, shared by free axes:
    the three-legged body's trunk (1 free axis of 10) 1 of 10, each leg (3) 3 (an equal
    split would give each 2, the whole schedule each 10); one partition all of them, as the
    paper's."""
    body = three_legs()
    cams = top_and_side()
    _, frames = planted_postures(body, cams, 1, seed=3)
    params = AnnealParams(candidates=1, threshold_mode="absolute", reanalysis_threshold=1e9,
                          confirm_runs="off", refine=False, epsilon=0.0, partition_rounds=2,
                          start_samples=0).with_schedule(10)
    fitter = Fitter(body, cams, params)
    parts = fitter._partitions(params)
    counts = np.diff(parts.dof_off)
    assert sorted(counts.tolist()) == [1, 3, 3, 3]
    (r,) = fitter.fit(frames)
    assert r.runs == 1
    assert r.iterations == 2 * (1 + 3 + 3 + 3)
    whole = Fitter(body, cams, replace(params, partitions="none")).fit(frames)[0]
    assert whole.iterations == 10  # one partition: the whole schedule, one round
