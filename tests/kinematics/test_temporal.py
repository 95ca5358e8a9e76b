"""Candidate postures per frame and the path through time (kinematics.fit.temporal, and the
Fitter's use of them with ``candidates`` > 1)."""

from __future__ import annotations

import itertools
import threading
from dataclasses import replace

import numba
import numpy as np
import pytest

from kinematics._kernels.temporal import path_dp
from kinematics.cameras import OrthographicCamera
from kinematics.fit import AnnealParams, Candidate, Fitter
from kinematics.fit.temporal import (
    BREAK_COST,
    JUMP_CAP,
    WRONG_STRETCH,
    _path_numpy,
    choose_path,
    cuts,
    distinct,
    kinks,
    solve_path,
    transition_costs,
    transitions,
)
from kinematics.fit.tuning import TUNING
from kinematics.model import Body, Chain, Marker, Root, Segment
from kinematics.model.fk import forward_kinematics
from tests.fixtures.bodies import hinge, leg, three_legs
from tests.fixtures.cameras import top_and_side


# -- merging -----------------------------------------------------------------------------------
def test_distinct_merges_near_postures_keeping_the_lower_error():
    postures = np.array([[0.0, 0.0], [1.0, 1.0], [30.0, 0.0], [np.nan, np.nan], [359.0, 2.0]])
    errors = np.array([1.0, 0.5, 2.0, np.nan, 0.1])
    # 359° is 1° from 0° (angles compared modulo 360): one posture with 0/1/359
    keep = distinct(postures, errors, np.array([5.0, 5.0]), 2, keep=3)
    np.testing.assert_array_equal(keep, [4, 2])
    assert list(distinct(postures, errors, np.array([5.0, 5.0]), 2, keep=1)) == [4]
    # a root coordinate (not an angle) is not wrapped
    keep = distinct(np.array([[0.0, 0.0], [0.0, 359.0]]), np.array([0.0, 1.0]),
                    np.array([5.0, 5.0]), 1, keep=3)
    np.testing.assert_array_equal(keep, [0, 1])


def test_transition_cost_in_spreads():
    prev = np.array([[0.0, 0.0]])
    cur = np.array([[10.0, 0.0], [0.0, 5.0], [np.nan, 0.0]])
    cost = transition_costs(prev, cur, np.array([10.0, 5.0]), 1)
    np.testing.assert_allclose(cost, [[1.0, 1.0, np.inf]])


def test_transitions_of_a_sequence_are_its_transition_costs_frame_by_frame():
    rng = np.random.default_rng(4)
    postures = rng.uniform(-200.0, 200.0, (7, 3, 4))
    postures[2, 1] = np.nan  # a run not made
    scale = np.array([2.0, 3.0, 5.0, 0.5])
    both = transitions(postures, scale, 3)
    assert both.shape == (6, 3, 3)
    for t in range(1, 7):
        np.testing.assert_array_equal(
            both[t - 1], transition_costs(postures[t - 1], postures[t], scale, 3))


# -- the path ----------------------------------------------------------------------------------
def two_branches(n=12, wrong=5, lead=0.3):
    """A planted sequence: candidate 0 follows the movement (1° per frame), candidate 1 is a
    flip 40° away; at frame ``wrong`` the flip has the lower E by ``lead``."""
    post = np.zeros((n, 2, 1))
    post[:, 0, 0] = np.arange(n)
    post[:, 1, 0] = np.arange(n) + 40.0
    unary = np.zeros((n, 2))
    unary[:, 1] = 0.5
    unary[wrong] = [lead, 0.0]
    return unary, post


def test_path_takes_the_branch_that_continues_the_movement():
    unary, post = two_branches()
    assert (choose_path(unary, post, np.array([10.0]), 1) == 0).all()
    # without continuity every frame keeps its lowest E: the flip wins at frame 5
    greedy = choose_path(unary, post, np.array([10.0]), 1, weight=0.0)
    assert greedy[5] == 1 and (np.delete(greedy, 5) == 0).all()


def test_path_restarts_at_breaks_and_cuts():
    unary, post = two_branches()
    # after a break frame 6 is chosen on its own: the flip branch has the lower E from there
    unary[6:] = [0.5, 0.0]
    unary[5] = [0.0, 0.5]
    breaks = np.zeros(12, bool)
    breaks[6] = True
    chosen = choose_path(unary, post, np.array([10.0]), 1, breaks=breaks)
    assert (chosen[:6] == 0).all() and (chosen[6:] == 1).all()
    # without the break, one 40° jump (16) costs more than the later frames' lead (6 x 0.4):
    # the path stays on branch 0 ...
    unary[6:] = [0.4, 0.0]
    assert (choose_path(unary, post, np.array([10.0]), 1) == 0).all()
    # ... and a jump no pair of candidates explains (> BREAK_COST) is a cut by itself
    post[6:] += 100.0
    assert BREAK_COST < 100.0 ** 2 / 100.0
    chosen = choose_path(unary, post, np.array([10.0]), 1)
    assert (chosen[:6] == 0).all() and (chosen[6:] == 1).all()


def test_path_skips_frames_without_candidates_and_honours_an_anchor():
    unary, post = two_branches(n=6, wrong=0, lead=0.3)
    unary[3] = np.inf
    chosen = choose_path(unary, post, np.array([10.0]), 1)
    assert chosen[3] == -1 and (chosen[:3] == 0).all() and (chosen[4:] == 0).all()
    # a window whose left end chose the flip branch continues it
    chosen = choose_path(unary, post, np.array([10.0]), 1, anchor=np.array([41.0]))
    assert (chosen[:3] == 1).all() and (chosen[4:] == 0).all()


def brute_force_costs(unary, post, scale, weight, anchor=None):
    """Every path of a small problem: its cost, and per (frame, candidate) the least cost of
    a path through it."""
    n, k = unary.shape
    best = np.full((n, k), np.inf)
    for path in itertools.product(range(k), repeat=n):
        c = sum(unary[t, j] for t, j in enumerate(path))
        for t in range(1, n):
            c += weight * min(JUMP_CAP, transition_costs(post[t - 1, [path[t - 1]]],
                                                         post[t, [path[t]]], scale, 1)[0, 0])
        if anchor is not None:
            c += weight * min(JUMP_CAP, transition_costs(anchor[None], post[0, [path[0]]],
                                                         scale, 1)[0, 0])
        for t, j in enumerate(path):
            best[t, j] = min(best[t, j], c)
    return best


@pytest.mark.parametrize("seed", range(6))
def test_solve_path_costs_are_the_least_cost_through_each_candidate(seed):
    rng = np.random.default_rng(seed)
    n, k = 6, 3
    unary = rng.uniform(0, 2, (n, k))
    post = rng.normal(0, 12, (n, k, 1)) + np.arange(n)[:, None, None]
    scale = np.array([10.0])
    anchor = np.array([rng.normal(0, 12)]) if seed % 2 else None
    choice, cost = solve_path(unary, post, scale, 1, weight=0.7, anchor=anchor)
    want = brute_force_costs(unary, post, scale, 0.7, anchor)
    np.testing.assert_allclose(cost, want, rtol=1e-12)
    # the chosen candidates lie on the cheapest path: each is its frame's least cost
    np.testing.assert_allclose(cost[np.arange(n), choice], want.min())
    np.testing.assert_array_equal(choice, choose_path(unary, post, scale, 1, 0.7,
                                                      anchor=anchor))


def test_solve_path_costs_say_how_surely_the_movement_rules_a_candidate_out():
    unary, post = two_branches()
    choice, cost = solve_path(unary, post, np.array([10.0]), 1)
    # frame 5's flip fits better by 0.3, but taking it costs two 40° jumps (capped at 4
    # each) or the flip branch's worse E (0.5) in the 11 other frames
    assert choice[5] == 0
    assert cost[5, 1] - cost[5, 0] == pytest.approx(min(2 * JUMP_CAP, 11 * 0.5) - 0.3)
    # a mirror branch as smooth as the true one: nothing rules it out
    unary[:] = 0.0
    _, cost = solve_path(unary, post, np.array([10.0]), 1)
    np.testing.assert_allclose(cost[:, 1], cost[:, 0])


def test_cuts_see_past_a_wrong_best_candidate_and_into_decided_frames():
    # a still movement that jumps by 50° at frame 6 (a new sequence)
    n = 12
    post = np.full((n, 2, 1), np.nan)
    post[:, 0, 0] = np.where(np.arange(n) < 6, 0.0, 50.0) + 0.1 * np.arange(n)
    scale = np.array([10.0])
    assert np.flatnonzero(cuts(post[:, 0], scale, 1)).tolist() == [6]
    # frame 8's best candidate is wrong, its second right: the cut is still found
    wrong = post.copy()
    wrong[8] = [[90.0], [50.8]]
    assert np.flatnonzero(cuts(wrong[:, 0], scale, 1)).tolist() == []
    assert np.flatnonzero(cuts(wrong, scale, 1)).tolist() == [6]
    # a window starting one frame before the jump: with two decided frames before it the
    # cut at its second frame is found, and the context frames are not returned
    window = post[5:]
    assert not cuts(window, scale, 1).any()
    found = cuts(post[3:], scale, 1, before=2)
    assert found.shape == (n - 5,) and np.flatnonzero(found).tolist() == [1]


def test_a_wrong_stretch_that_the_movement_outlives_is_no_cut():
    # a steady movement (1° per frame), and a new sequence 50° away from frame 8 on: a cut
    n = 30
    scale = np.array([10.0])
    post = np.full((n, 2, 1), np.nan)
    post[:, 0, 0] = np.where(np.arange(n) < 8, 0.0, 50.0) + np.arange(n)
    assert np.flatnonzero(cuts(post, scale, 1)).tolist() == [8]
    # frames 8-12 50° away and the movement found again from frame 13 where it was heading:
    # a wrong stretch, neither of its ends a cut
    post[13:, 0, 0] -= 50.0
    assert not cuts(post, scale, 1).any()
    # ... also when, for a while, the right posture is only the frames' second candidate
    post[13:16, 1, 0] = post[13:16, 0, 0]
    post[13:16, 0, 0] += 50.0
    assert not cuts(post, scale, 1).any()
    # a stretch longer than WRONG_STRETCH is taken for two sequences
    post = np.full((n + 20, 1, 1), np.nan)
    post[:, 0, 0] = np.arange(n + 20, dtype=float)
    post[8:8 + WRONG_STRETCH + 4, 0, 0] += 50.0
    assert np.flatnonzero(cuts(post, scale, 1)).tolist() == [8, 8 + WRONG_STRETCH + 4]


def test_kinks_find_wrong_frames_but_not_their_neighbours():
    scale = np.array([10.0, 10.0])
    t = np.arange(40, dtype=float)
    smooth = np.c_[20 * np.sin(t / 7), 0.5 * t]
    assert not kinks(smooth, scale, 1).any()
    one = smooth.copy()
    one[10, 0] += 6.0  # a 6° slip on one frame, less than the movement's 2.9° per frame x 2
    assert np.flatnonzero(kinks(one, scale, 1)).tolist() == [10]
    # a run of three wrong frames kinks where it starts and ends, and takes its middle along
    run = smooth.copy()
    run[20:23, 0] += 8.0
    found = np.flatnonzero(kinks(run, scale, 1)).tolist()
    assert {20, 21, 22} <= set(found) and set(found) <= {19, 20, 21, 22, 23}
    # no kink across a break
    breaks = np.zeros(40, bool)
    breaks[10] = True
    assert not kinks(one, scale, 1, breaks)[[9, 10]].any()


# -- the fitter ------------------------------------------------------------------------------
def mirror_arm() -> tuple[Body, dict]:
    """A hinge seen from the side, along its own plane: +θ and -θ project identically."""
    seg = Segment("arm", 50.0, markers=(Marker("M0", (-25.0, 0.0, 0.0)), Marker("M1")))
    body = Body("arm", (Chain("arm", hinge("J", "theta", -70, 70, seg), Root("fixed")),),
                units="px")
    cam = OrthographicCamera.from_axes("side", 2.0, ("x", "z"), (100.0, 100.0),
                                       size=(300, 200))
    return body, {"side": cam}


def frames_of(body, cams, thetas, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for t in thetas:
        mk = forward_kinematics(body, np.array([0.0, 0.0, t])).markers
        out.append([cam.project(mk) + rng.normal(0, 0.05, (len(mk), 2))
                    for cam in cams.values()])
    return out


FAST = dict(refine=True, n_end=3000, n_l=300, n_tau=130, threshold_mode="absolute",
            reanalysis_threshold=50.0, error=AnnealParams.paper().error)


def test_a_mirror_posture_is_flagged_ambiguous_with_its_alternative():
    body, cams = mirror_arm()
    res = Fitter(body, cams, AnnealParams(candidates=6, **FAST)).fit_frame(
        frames_of(body, cams, [30.0])[0])
    # fit_frame decides a frame alone: candidates are kept, no path
    thetas = sorted(round(c.angles_deg[2]) for c in res.candidates)
    assert thetas == [-30, 30]
    (seq,) = Fitter(body, cams, AnnealParams(candidates=6, **FAST)).fit(
        frames_of(body, cams, [30.0]))
    assert seq.status == "ambiguous"
    assert {round(c.angles_deg[2]) for c in seq.candidates} == {-30, 30}
    assert abs(seq.candidates[0].angles_deg[2] - seq.angles_deg[2]) < 1e-9
    # the spread says which axis the frame is unsure about: θ, by the mirror's 60°
    assert seq.spread_deg[2] == pytest.approx(60.0, abs=1.0)
    assert seq.spread_deg[[0, 1]].tolist() == [0.0, 0.0]


def test_the_path_keeps_one_branch_through_a_mirror_ambiguity():
    body, cams = mirror_arm()
    truth = np.linspace(20.0, 50.0, 16)
    res = Fitter(body, cams, AnnealParams(candidates=4, **FAST)).fit(
        frames_of(body, cams, truth))
    fitted = np.array([r.angles_deg[2] for r in res])
    sign = np.sign(fitted)
    assert (sign == sign[0]).all(), fitted  # no flip in the middle of the movement
    np.testing.assert_allclose(np.abs(fitted), truth, atol=1.0)
    # with one answer per frame the branch is random frame by frame
    single = Fitter(body, cams, AnnealParams(candidates=1, **FAST)).fit(
        frames_of(body, cams, truth))
    assert len({np.sign(r.angles_deg[2]) for r in single}) == 2


def test_neighbour_seeded_refit_finds_a_posture_the_frame_missed():
    body, cams = mirror_arm()
    truth = np.linspace(20.0, 50.0, 12)
    fitter = Fitter(body, cams, AnnealParams(candidates=2, **FAST))
    obs = fitter.observations(frames_of(body, cams, truth))
    neighbour = fitter.fit(obs)[3].candidates[0]
    again = fitter._refit_from(obs, 4, neighbour, fitter.params)
    # started from frame 3's posture, the cold local fit lands on frame 4's same branch
    assert np.sign(again.angles_deg[2]) == np.sign(neighbour.angles_deg[2])
    assert abs(abs(again.angles_deg[2]) - truth[4]) < 1.0


def test_a_neighbour_posture_refined_in_place_keeps_its_basin():
    """A tip marker occluded for a few frames and a ghost where the tip of a posture 40° on
    would be: that wrong posture has the lower E; refining the right neighbour's posture in
    place keeps the right one (what lets the re-fits carry the movement through such a
    stretch, where a cold anneal can fall into the ghost's posture)."""
    seg = Segment("arm", 50.0, markers=(Marker("M0", (-45.0, 0.0, 0.0)), Marker("M1")))
    body = Body("arm", (Chain("arm", hinge("J", "theta", -70, 70, seg), Root("fixed")),),
                units="px")
    cam = OrthographicCamera.from_axes("side", 2.0, ("x", "y"), (150.0, 150.0),
                                       size=(300, 300))
    truth = np.linspace(0.0, 30.0, 24)
    frames = frames_of(body, {"side": cam}, truth)
    for k in range(8, 13):
        ghost = cam.project(forward_kinematics(body, np.array([0.0, 0.0, truth[k] + 40]))
                            .markers)[1]
        frames[k] = [np.array([frames[k][0][0], ghost])]
    fitter = Fitter(body, {"side": cam}, AnnealParams(candidates=2, n_end=3000, n_l=300,
                                                      n_tau=130, seed=1))
    obs = fitter.observations(frames)
    res = fitter.fit(obs)
    assert abs(res[10].angles_deg[2] - truth[10]) > 30  # the ghost's posture, lower E
    right = res[7].candidates[0]
    assert abs(right.angles_deg[2] - truth[7]) < 0.5
    kept = fitter._refit_from(obs, 8, right, fitter.params, polish=True)
    assert abs(kept.angles_deg[2] - truth[8]) < 0.5
    assert kept.error > res[8].error  # refined where it is, not drawn to the lower E
    # the same for one frame through the public API (the GUI's re-fit forward, F9)
    one = fitter.refine_frame(frames[8], 8, right.angles_deg)
    assert one.frame == 8 and one.runs == 1
    assert one.status == ("ok" if one.error <= fitter.params.reanalysis_threshold else "failed")
    np.testing.assert_allclose(one.angles_deg, kept.angles_deg, atol=1e-9)
    assert one.error == pytest.approx(fitter.error(one.angles_deg, frames[8])[0], rel=1e-9)


def test_the_re_fits_carry_the_movement_through_a_stretch_a_ghost_holds(monkeypatch):
    """The tip occluded for 5 frames and a ghost where the tip of a posture 40° on would be:
    every run of those frames ends in the ghost's posture (lower E), and only the
    neighbour's posture refined in place and carried frame by frame finds the truth."""
    seg = Segment("arm", 50.0, markers=(Marker("M0", (-43.0, 0.0, 0.0)), Marker("M1")))
    body = Body("arm", (Chain("arm", hinge("J", "theta", -70, 70, seg), Root("fixed")),),
                units="px")
    cams = {"side": OrthographicCamera.from_axes("side", 2.0, ("x", "y"), (150.0, 150.0),
                                                 size=(300, 300))}
    truth = np.linspace(0.0, 30.0, 24)
    frames = frames_of(body, cams, truth)
    for k in range(8, 13):
        ghost = cams["side"].project(forward_kinematics(
            body, np.array([0.0, 0.0, truth[k] + 40])).markers)[1]
        frames[k] = [np.array([frames[k][0][0], ghost])]
    params = AnnealParams(candidates=2, n_end=3000, n_l=300, n_tau=130, seed=1)

    def fitted():
        return np.array([r.angles_deg[2] for r in Fitter(body, cams, params).fit(frames)])

    np.testing.assert_allclose(fitted(), truth, atol=1.0)
    # without the carried postures the stretch stays on the ghost
    refit = Fitter._refit_from
    monkeypatch.setattr(Fitter, "_refit_from", lambda self, obs, position, nb, p,
                        polish=False: None if polish else refit(self, obs, position, nb, p))
    assert (np.abs(fitted()[8:13] - truth[8:13]) > 30).all()


def test_a_frame_off_its_neighbours_line_is_flagged_though_it_fits():
    """Detections of one frame put the arm 12° off the movement (as a ghost taking a
    marker would): the fit follows them, E is as good as anywhere, and the frame is
    flagged for its kink; its neighbours are not."""
    body, _ = mirror_arm()
    cams = {"front": OrthographicCamera.from_axes("front", 2.0, ("x", "y"), (150.0, 150.0),
                                                  size=(300, 300))}
    truth = np.linspace(20.0, 50.0, 24)
    shown = truth.copy()
    shown[12] += 12.0
    res = Fitter(body, cams, AnnealParams(candidates=2, **FAST)).fit(
        frames_of(body, cams, shown))
    assert abs(res[12].angles_deg[2] - shown[12]) < 1.0
    flagged = [k for k, r in enumerate(res) if r.status == "ambiguous"]
    assert 12 in flagged and 11 not in flagged and 13 not in flagged, flagged


def legs_walking(n: int, step_deg: float, seed=0):
    """The three-legged body (tests/fixtures/bodies.py) moving every free axis by
    ``step_deg`` per frame, seen from the top and the side (markers in order): body, cameras,
    the true angles (n, n_axes) and each frame's detections."""
    body, cams = three_legs(), top_and_side()
    lo, hi = body.ranges_deg().T
    t = np.arange(n)[:, None]
    width = np.maximum(hi - lo - 16.0, 1e-9)
    # each free axis sweeps its range back and forth at step_deg per frame
    u = (np.random.default_rng(seed).uniform(0, 2, len(lo)) * width + t * step_deg) % (
        2 * width)
    angles = np.where(body.locked_mask(), 0.0, lo + 8.0 + width - np.abs(u - width))
    rng = np.random.default_rng(seed + 1)
    frames = [[c.project(forward_kinematics(body, a).markers) + rng.normal(0, 0.05, (8, 2))
               for c in cams.values()] for a in angles]
    return body, cams, angles, frames


def count_refits(monkeypatch, threads: set | None = None) -> list:
    """The frames ``Fitter._refit_from`` is called for, in call order (and, into
    ``threads``, the ids of the threads that made the calls)."""
    calls = []
    refit = Fitter._refit_from

    def counted(self, obs, position, neighbour, p, polish=False):
        calls.append(position)
        if threads is not None:
            threads.add(threading.get_ident())
        return refit(self, obs, position, neighbour, p, polish)
    monkeypatch.setattr(Fitter, "_refit_from", counted)
    return calls


def test_limbs_moving_at_once_are_no_jump(monkeypatch):
    """Each of a body's partitions may change by up to TUNING.redo_jump squared spreads per frame
    before the frame is re-fitted from its neighbours: three legs each moving about 0.4
    squared spreads per frame (1.5 together) are no jump. Measured on a fly: its six legs at
    330 Hz change by ~10 per frame, so the whole clip was re-fitted, at 0.08 frames/s."""
    body, cams, angles, frames = legs_walking(12, 9.0)
    fitter = Fitter(body, cams, AnnealParams(candidates=2, **FAST))
    post = np.array([fitter._posture_vector(Candidate(a, np.zeros((1, 3)), 0.0, None,
                                                      None, None)) for a in angles])
    steps = transition_costs(post[:-1, None], post[1:, None], fitter._posture_scale(),
                             fitter._n_wrapped)[:, 0, 0]
    assert np.median(steps) > 1.0 and (steps < 4.0).all(), steps  # > 1: one partition's cap
    calls = count_refits(monkeypatch)
    res = fitter.fit(frames)
    assert calls == []
    err = np.abs(np.array([r.angles_deg for r in res]) - angles).max()
    assert err < 2.0


def redundant_arm() -> tuple[Body, dict]:
    """An arm turned by two coaxial hinges, seen from above: only the sum of their angles
    moves a marker (as a fly's coxa roll is nearly undone by its other axes)."""
    arm = Segment("arm", 50.0, markers=(Marker("M0", (-25.0, 0.0, 0.0)), Marker("M1")))
    hub = Segment("hub", 0.0, joints=(hinge("J2", "b", -60, 60, arm),))
    body = Body("arm", (Chain("arm", hinge("J1", "a", -60, 60, hub), Root("fixed")),),
                units="px")
    cam = OrthographicCamera.from_axes("top", 2.0, ("x", "y"), (150.0, 100.0),
                                       size=(300, 200))
    return body, {"top": cam}


@pytest.mark.parametrize("seen_ratio", [0.0, TUNING.jump_seen_ratio])
def test_a_jump_the_markers_do_not_show_is_not_flagged(monkeypatch, seen_ratio):
    """In frames 10-13 the arm's turn is split 30° differently between its two hinges and
    no re-fit finds a posture that continues the angles: the chosen path jumps into that
    stretch and out, but no marker moves more than the movement does, so no frame is flagged
    (on the fly such jumps of the coxa roll made 142 of 660 frames ambiguous, 7 of them off).
    Counting every jump and kink (``seen_ratio`` 0, as before) flags the stretch, and not the
    frames beside it, whose kinks the stretch between the two jumps explains."""
    from kinematics.fit import tuning

    monkeypatch.setattr(tuning, "TUNING", replace(tuning.TUNING, jump_seen_ratio=seen_ratio))
    body, cams = redundant_arm()
    turn = np.linspace(0.0, 23.0, 24)  # 1° per frame
    rng = np.random.default_rng(0)
    frames = [[cams["top"].project(forward_kinematics(
        body, np.array([0, 0, t / 2, 0, 0, t / 2])).markers) + rng.normal(0, 0.05, (2, 2))]
        for t in turn]
    split = np.zeros(6)
    split[[2, 5]] = 30.0, -30.0
    fit_block = Fitter._fit_block

    def planted(self, obs, sel, *args, **kwargs):
        """The fit's results, every candidate's turn split at a/2 - 15, b/2 + 15 (an own
        split of each run would make the path jump every frame); in frames 10-13 at
        a/2 + 15, b/2 - 45."""
        out = []
        for r in fit_block(self, obs, sel, *args, **kwargs):
            def plant(a, r=r):
                total = a[2] + a[5]
                new = np.array(a, float)
                new[2], new[5] = total / 2 - 15.0, total / 2 + 15.0
                return new + (split if 10 <= r.frame < 14 else 0.0)
            cands = tuple(c._replace(angles_deg=plant(c.angles_deg)) for c in r.candidates)
            out.append(replace(r, angles_deg=plant(r.angles_deg), candidates=cands))
        return out
    monkeypatch.setattr(Fitter, "_fit_block", planted)
    monkeypatch.setattr(Fitter, "_refit_from", lambda *a, **k: None)
    res = Fitter(body, cams, AnnealParams(candidates=2, **FAST)).fit(frames)
    a = np.array([r.angles_deg for r in res])
    np.testing.assert_allclose(a[:, 2] + a[:, 5], turn, atol=0.5)
    assert (np.abs(np.diff(a[:, 2]))[[9, 13]] > 25.0).all()  # the premise: jumps
    flagged = [r.frame for r in res if r.status != "ok"]
    assert flagged == ([] if seen_ratio else list(range(10, 14)))


def swinging_arm():
    """A 50-px arm on one hinge (0-90°, a spread of 26°) seen from above, and its frames: 1°
    per frame, a new sequence 58° away from frame 8 on (a cut: more than one spread)."""
    arm = Segment("arm", 50.0, markers=(Marker("M0", (-25.0, 0.0, 0.0)), Marker("M1")))
    body = Body("arm", (Chain("arm", hinge("J1", "a", 0, 90, arm), Root("fixed")),),
                units="px")
    cam = OrthographicCamera.from_axes("top", 2.0, ("x", "y"), (150.0, 100.0),
                                       size=(300, 200))
    t = np.arange(16, dtype=float)
    truth = np.where(t < 8, 5.0, 70.0) + t
    rng = np.random.default_rng(0)
    frames = [[cam.project(forward_kinematics(body, np.array([0, 0, a])).markers)
               + rng.normal(0, 0.05, (2, 2))] for a in truth]
    return body, {"top": cam}, truth, frames


def plant_fits(monkeypatch, wrong: dict[int, float]) -> None:
    """Every candidate of frame k fitted ``wrong[k]`` degrees off (E as fitted)."""
    fit_block = Fitter._fit_block

    def planted(self, obs, sel, *args, **kwargs):
        out = []
        for r in fit_block(self, obs, sel, *args, **kwargs):
            off = np.array([0.0, 0.0, wrong.get(r.frame, 0.0)])
            cands = tuple(c._replace(angles_deg=c.angles_deg + off) for c in r.candidates)
            out.append(replace(r, angles_deg=r.angles_deg + off, candidates=cands))
        return out
    monkeypatch.setattr(Fitter, "_fit_block", planted)


@pytest.mark.parametrize("start", [0, 8])
def test_a_wrong_stretch_where_a_sequence_starts_is_flagged_whole(monkeypatch, start):
    """The first three frames of a sequence (frame 0, or the start given at 8) fitted 20°
    off in the same way (a marker occluded there, a ghost in its place) and no re-fit finding
    better: the path jumps only where they end. The stretch is flagged, not the frame after
    the jump (until session 25: the two frames around the jump, one of them right, and the
    first frames not; the locust's misses)."""
    body, cams, truth, frames = swinging_arm()
    plant_fits(monkeypatch, {start + k: 20.0 for k in range(3)})
    monkeypatch.setattr(Fitter, "_refit_from", lambda *a, **k: None)
    res = Fitter(body, cams, AnnealParams(candidates=2, **FAST)).fit(
        frames, sequence_starts=[8])
    err = np.abs(np.array([r.angles_deg[2] for r in res]) - truth)
    assert (err[start:start + 3] > 15.0).all() and (np.delete(err, range(start, start + 3))
                                                    < 1.0).all()  # the premise
    assert [r.frame for r in res if r.status != "ok"] == [start, start + 1, start + 2]


def test_a_cut_the_re_fits_reveal_flags_nothing(monkeypatch):
    """Frame 8 starts a new sequence that no one told the fitter about, and its own runs
    found only a posture between the two sequences, so no cut is seen there at first. The
    re-fit from its neighbour finds the right posture; the cut is then found, and the jump
    into the new sequence flags nothing (until session 25 frames 7 and 8)."""
    body, cams, truth, frames = swinging_arm()
    plant_fits(monkeypatch, {8: -33.0})
    refit = Fitter._refit_from

    def from_truth(self, obs, position, neighbour, p, polish=False, **kw):
        if position != 8:
            return None
        right = neighbour._replace(angles_deg=np.array([0.0, 0.0, truth[8]]))
        return refit(self, obs, position, right, p, polish=True)
    monkeypatch.setattr(Fitter, "_refit_from", from_truth)
    res = Fitter(body, cams, AnnealParams(candidates=2, **FAST)).fit(frames)
    err = np.abs(np.array([r.angles_deg[2] for r in res]) - truth)
    assert (err < 1.0).all()
    assert [r.frame for r in res if r.status != "ok"] == []


def test_a_cut_just_after_a_wrong_frame_is_found():
    """A cut whose frame before is wrong (it jumps there and back): the cut dwarfs that
    return, so it is still found; the wrong frame alone is no cut."""
    n = 14
    scale = np.array([10.0])
    post = (np.where(np.arange(n) < 8, 0.0, 50.0) + 0.1 * np.arange(n))[:, None]
    post[7] += 5.0
    assert np.flatnonzero(cuts(post, scale, 1)).tolist() == [8]
    post[8:] -= 50.0
    assert not cuts(post, scale, 1).any()


def test_re_fits_keep_a_bounded_number_of_candidates(monkeypatch):
    """Postures 5° apart on any axis are distinct, so on a body of many axes almost every
    re-fit is a new candidate, and each seeds the next frame's re-fits: a fly's 20-frame
    window grew from 40 to 3 627 candidates. Here every re-fit returns a new posture that
    fits as well as the frame's best; the candidates and the re-fits must stay bounded."""
    from kinematics.fit.tuning import TUNING

    body, cams, angles, frames = legs_walking(12, 40.0, seed=3)  # jumps every frame
    p = AnnealParams(candidates=2, **FAST)
    fitter = Fitter(body, cams, p)
    obs = fitter.observations(frames)
    best = [r.error for r in fitter.fit(obs)]
    calls = []

    def distinct_refit(self, obs, position, neighbour, p, polish=False):
        calls.append(position)
        # keyed by the call, as the real re-fits are: they may run on several threads
        rng = np.random.default_rng([position, int(polish), *np.round(
            np.abs(neighbour.angles_deg) * 1e3).astype(np.int64)])
        moved = neighbour.angles_deg + np.where(body.locked_mask(), 0.0,
                                                rng.uniform(-20, 20, len(angles[0])))
        state, pos, rot = self.problem.state(moved, neighbour.root_positions)
        return Candidate(moved, neighbour.root_positions, best[position], state, pos, rot)
    monkeypatch.setattr(Fitter, "_refit_from", distinct_refit)
    res = fitter.fit(obs)
    assert len(calls) > 0
    assert max(len(r.candidates) for r in res) == p.candidates + TUNING.refit_candidates
    assert len(calls) <= 2 * len(frames) * 2 * (p.candidates + TUNING.refit_candidates) * (
        1 + WRONG_STRETCH)


def test_re_fits_on_several_threads_give_the_same_results(monkeypatch):
    """The re-fits of a frame from its neighbours' candidates run on every thread at once;
    each is keyed by its frame, so the results equal those made one after the other."""
    import numba

    from kinematics.fit import candidates

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one numba thread: nothing runs at once")
    body, cams, _, frames = legs_walking(12, 40.0, seed=3)  # jumps every frame
    p = AnnealParams(candidates=2, **FAST)
    workers: set = set()
    calls = count_refits(monkeypatch, workers)
    threads = numba.get_num_threads()
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    try:
        together = Fitter(body, cams, p).fit(frames)
    finally:
        numba.set_num_threads(threads)
    assert len(calls) > 10
    assert len(workers) >= 2  # the re-fits really ran on several threads
    monkeypatch.setattr(candidates, "concurrent_fits", lambda: False)
    alone = Fitter(body, cams, p).fit(frames)
    for a, b in zip(together, alone, strict=True):
        np.testing.assert_array_equal(a.angles_deg, b.angles_deg)
        assert [c.error for c in a.candidates] == [c.error for c in b.candidates]
        assert a.status == b.status


@pytest.mark.parametrize("profile", ["best", "paper"])
def test_profiles(profile):
    p = AnnealParams.profile(profile)
    assert (p.candidates > 1) == (profile == "best")
    assert p.refine == (profile == "best")
    assert AnnealParams.paper(seed=3).seed == 3


def plane_arm() -> tuple[Body, dict]:
    """The mirror arm seen square on: every angle projects differently (no mirror)."""
    body, _ = mirror_arm()
    return body, {"side": OrthographicCamera.from_axes("side", 2.0, ("x", "y"),
                                                       (150.0, 150.0), size=(300, 300))}


def test_track_follows_the_movement_with_one_short_cold_run_per_frame():
    """start="track": each segment's first frame is fitted in full, every other frame by one
    cold anneal of TUNING.track_share of the schedule from the previous result; the same results
    whatever the number of threads (segments are independent)."""
    from kinematics.fit.tuning import TUNING

    body, cams = plane_arm()
    truth = np.linspace(-40.0, 40.0, 40)
    frames = frames_of(body, cams, truth)
    p = AnnealParams(start="track", segment_length=16, **FAST)
    res = Fitter(body, cams, p).fit(frames)
    theta = np.array([r.angles_deg[2] for r in res])
    np.testing.assert_allclose(theta, truth, atol=1.0)
    short = max(1, int(p.n_end * TUNING.track_share))
    for k, r in enumerate(res):
        if k % 16 == 0:  # a segment's first frame: the full fit (runs until two agree)
            assert r.runs >= 2
        else:
            assert r.runs == 1 and 0 < r.iterations <= short and r.status == "ok"
    one = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        again = Fitter(body, cams, p).fit(frames)
    finally:
        numba.set_num_threads(one)
    assert [r.angles_deg.tolist() for r in again] == [r.angles_deg.tolist() for r in res]


def test_track_lost_by_a_jump_is_found_by_a_full_fit(monkeypatch):
    """The arm jumps 60° between two frames: a cold run from the previous posture (here a
    very short one, so that it surely cannot follow) leaves E jumping, and that frame is
    fitted in full (reanalysed); tracking goes on from it. With threshold_mode auto the
    threshold is measured on the tracked frames."""
    from kinematics.fit import tuning

    monkeypatch.setattr(tuning, "TUNING", replace(tuning.TUNING, track_share=0.002))
    body, cams = plane_arm()
    truth = np.r_[np.linspace(-40.0, -30.0, 12), np.linspace(30.0, 40.0, 12)]
    frames = frames_of(body, cams, truth)
    p = AnnealParams(start="track", segment_length=32,
                     **{**FAST, "threshold_mode": "auto"})
    res = Fitter(body, cams, p).fit(frames)
    np.testing.assert_allclose([r.angles_deg[2] for r in res], truth, atol=1.0)
    assert res[12].status == "reanalysed" and res[12].runs >= 2
    assert [r.status for r in res[13:]] == ["ok"] * 11
    thresholds = {r.threshold for r in res}
    assert len(thresholds) == 1 and np.isfinite(thresholds.pop())


def _bent(fitter, obs, r, p, axis: str, deg: float):
    """Result ``r`` with one axis turned by ``deg`` (E and residuals made again)."""
    a = np.array(r.angles_deg, float)
    a[fitter.body.axis_labels.index(axis)] += deg
    state, pos, rot = fitter.problem.state(a, r.root_positions)
    return fitter._frame_result(obs, r.frame, r.frame, state, pos, rot, p, runs=r.runs,
                                iterations=r.iterations, pairs=0)


def test_a_merge_takes_each_limb_from_the_fit_that_explains_its_markers():
    """A track that lost leg a and a full fit that lost leg b merge into a posture with
    both right; where the other fit explains no limb better, there is no merge."""
    body, cams, angles, frames = legs_walking(1, 0.0)
    p = AnnealParams(**FAST)
    fitter = Fitter(body, cams, p)
    obs = fitter.observations(frames)
    right = fitter.refine_frame(frames[0], 0, angles[0])
    lost_a = _bent(fitter, obs, right, p, "a_knee.flex", 35.0)
    lost_b = _bent(fitter, obs, right, p, "b_knee.flex", -35.0)
    merged = fitter._merged(obs, 0, lost_a, lost_b, p)
    assert merged.error < min(lost_a.error, lost_b.error)
    np.testing.assert_allclose(merged.angles_deg, angles[0], atol=1.0)
    assert fitter._merged(obs, 0, right, lost_b, p) is None
    assert fitter._merged(obs, 0, lost_a, right, p) is not None


def test_track_mends_a_segment_start_from_the_segment_before(monkeypatch):
    """A segment's first frame is fitted alone; where that fit lost a leg, the previous
    segment's track, one step on, explains it better and takes it over."""
    from kinematics.fit import tuning

    # frame 13 would track it back too
    monkeypatch.setattr(tuning, "TUNING", replace(tuning.TUNING, track_drop=0.0))
    body, cams, angles, frames = legs_walking(24, 1.0)
    p = AnnealParams(start="track", segment_length=12, **FAST)
    full = Fitter._fit_full

    def lost_at_12(self, obs, idx, roots, rots, i, q):
        r = full(self, obs, idx, roots, rots, i, q)
        return _bent(self, obs, r, q, "b_knee.flex", 35.0) if i == 12 else r
    fitter = Fitter(body, cams, p)
    threads = numba.get_num_threads()
    with pytest.MonkeyPatch.context() as m:
        m.setattr(Fitter, "_fit_full", lost_at_12)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        try:
            res = fitter.fit(frames)
            numba.set_num_threads(1)  # segments one after the other: mended the same
            alone = fitter.fit(frames)
        finally:
            numba.set_num_threads(threads)
        m.setattr(Fitter, "_mend", lambda *a: None)
        unmended = fitter.fit(frames)
    knee = body.axis_labels.index("b_knee.flex")
    assert abs(unmended[12].angles_deg[knee] - angles[12, knee]) > 30  # what it mends
    np.testing.assert_allclose(res[12].angles_deg, angles[12], atol=1.5)
    assert res[12].status == "reanalysed"
    assert [r.angles_deg.tolist() for r in alone] == [r.angles_deg.tolist() for r in res]


def _creep(monkeypatch, first: int, last: int, deg) -> None:
    """``Fitter._step`` made to creep off: a step forward to a frame ``first``..``last``
    bends leg b's knee by ``deg(frame)`` after it."""
    step = Fitter._step

    def creeping(self, obs, position, prev, q):
        r = step(self, obs, position, prev, q)
        if r is not None and position == prev.frame + 1 and first <= position <= last:
            return _bent(self, obs, r, q, "b_knee.flex", deg(position))
        return r
    monkeypatch.setattr(Fitter, "_step", creeping)


def test_track_cut_by_a_full_fit_mends_the_frames_that_led_to_it(monkeypatch):
    """A track that crept off a leg over frames 5-8 (below the threshold) until frame 9
    was fitted in full: the frames before it are tracked back from the full fit."""
    from kinematics.fit import tuning

    # only the threshold cuts here
    monkeypatch.setattr(tuning, "TUNING", replace(tuning.TUNING, track_jump=1e9))
    body, cams, angles, frames = legs_walking(16, 1.0)
    # E: ~1 px right, 8-9 px with the leg 8° off, 46 px 60° off
    p = AnnealParams(start="track", segment_length=32,
                     **{**FAST, "reanalysis_threshold": 20.0})
    _creep(monkeypatch, 5, 9, lambda position: 8.0 if position < 9 else 60.0)
    fitter = Fitter(body, cams, p)
    res = fitter.fit(frames)
    monkeypatch.setattr(Fitter, "_retrack", lambda *a: None)
    unmended = fitter.fit(frames)
    knee = body.axis_labels.index("b_knee.flex")
    assert all(abs(unmended[k].angles_deg[knee] - angles[k, knee]) > 5 for k in range(5, 9))
    assert [r.status for r in res[5:10]] == ["reanalysed"] * 5
    np.testing.assert_allclose([r.angles_deg for r in res], angles, atol=2.0)


def _planted_retrack(monkeypatch, wrong_e, alt_e, n_wrong, merged_e=None):
    """:meth:`Fitter._retrack` of results 1..11 of a three-legged walk from result 0, the
    first ``n_wrong`` with leg b's knee 35° off and E ``wrong_e``, the rest right; the step
    to frame k returns the right posture with E ``alt_e(k)``; its merge with the result
    there is the wrong posture with E ``merged_e(k)`` (None: no merges). Returns the results after
    it, the right results and the frames the steps were asked for."""

    body, cams, angles, frames = legs_walking(12, 1.0)
    fitter = Fitter(body, cams, AnnealParams(**FAST))
    obs = fitter.observations(frames)
    right = [fitter.refine_frame(frames[k], k, angles[k]) for k in range(12)]
    results = [replace(_bent(fitter, obs, right[k], fitter.params, "b_knee.flex", 35.0),
                       error=wrong_e) if k <= n_wrong else right[k] for k in range(1, 12)]
    asked = []

    def step(self, obs, position, prev, p):
        asked.append(position)
        return replace(right[position], error=alt_e(position))
    monkeypatch.setattr(Fitter, "_step", step)
    def merged(self, obs, position, base, other, p):
        return None if merged_e is None else replace(results[position - 1],
                                                     error=merged_e(position))
    monkeypatch.setattr(Fitter, "_merged", merged)
    out = list(results)
    fitter._retrack(obs, fitter.params, out, right[0])
    assert TUNING.track_window == 8 and TUNING.track_prefer == 0.9  # the cases below
    return out, right, asked


def _is_right(r, right) -> bool:
    return np.abs(r.angles_deg - right[r.frame].angles_deg).max() < 1e-9


def test_a_retrack_takes_a_stretch_that_fits_better_over_several_frames(monkeypatch):
    """Each step only 3 % better than a wrong result (one frame's E is noise): the stretch
    is taken once its summed E is 10 % lower, then frame by frame; the re-track stops where
    it meets the right results (fly, 3 cameras, frames 224-253: the first frame's E was
    4 % lower, the next ones 10-20 %)."""
    # frame 1 at 9.7, the next at 8.5: 18.2 / 20 for frames 1-2, 26.7 / 30 for 1-3
    out, right, asked = _planted_retrack(monkeypatch, 10.0, lambda k: 9.7 if k == 1 else 8.5,
                                         8)
    assert all(_is_right(r, right) and r.status == "reanalysed" for r in out[:8])
    assert asked == list(range(1, 10))  # frame 9 met the right result: stop
    assert all(r is q for r, q in zip(out[8:], right[9:], strict=True))
    # every step 3 % better: never taken, given up after TUNING.track_window frames
    out, right, asked = _planted_retrack(monkeypatch, 10.0, lambda k: 9.7, 8)
    assert not any(_is_right(r, right) for r in out[:8]) and asked == list(range(1, 9))


def test_a_retrack_that_meets_the_results_need_only_fit_better(monkeypatch):
    """Frames 1-4 wrong, 5 on right: a re-track from frame 0 that joins them at frame 5
    takes 1-4 where its summed E is lower at all (5 % here), not 10 %; where it is higher,
    nothing. A re-track that never meets the results gives up after TUNING.track_window frames."""
    out, right, asked = _planted_retrack(monkeypatch, 10.0, lambda k: 9.5, 4)
    assert all(_is_right(r, right) for r in out[:4]) and asked == [1, 2, 3, 4, 5]
    out, right, asked = _planted_retrack(monkeypatch, 10.0, lambda k: 10.5, 4)
    assert not any(_is_right(r, right) for r in out[:4]) and asked == [1, 2, 3, 4, 5]
    out, right, asked = _planted_retrack(monkeypatch, 10.0, lambda k: 9.5, 11)
    assert not any(_is_right(r, right) for r in out) and asked == list(range(1, 9))


def test_a_retrack_takes_a_merge_only_where_it_fits_clearly_better(monkeypatch):
    """The step continues the movement; its merge with a wrong result (the wrong leg kept)
    replaces it only below TUNING.track_prefer times its E, as a full fit replaces the track (fly,
    3 cameras, frame 224: a merge 0.5 % below the step kept a leg 2 mm off)."""
    out, right, _ = _planted_retrack(monkeypatch, 10.0, lambda k: 8.0, 4,
                                     merged_e=lambda k: 7.9)
    assert all(_is_right(r, right) for r in out[:4])
    out, right, _ = _planted_retrack(monkeypatch, 10.0, lambda k: 8.0, 4,
                                     merged_e=lambda k: 7.0)
    assert not any(_is_right(r, right) for r in out[:4])


def test_a_track_that_finds_a_lost_leg_again_mends_the_frames_before(monkeypatch):
    """A track that crept off a leg over frames 3-8 without E jumping (nor reaching the
    threshold) finds it again at frame 9, where E falls below the median of the frames
    before (TUNING.track_drop): frames 3-8 are tracked back from it."""
    from kinematics.fit import tuning

    monkeypatch.setattr(tuning, "TUNING", replace(tuning.TUNING, track_jump=1e9))
    body, cams, angles, frames = legs_walking(16, 1.0)
    p = AnnealParams(start="track", segment_length=32,
                     **{**FAST, "reanalysis_threshold": 1e9})
    _creep(monkeypatch, 3, 8, lambda position: 8.0)
    fitter = Fitter(body, cams, p)
    res = fitter.fit(frames)
    fitter.tuning = replace(fitter.tuning, track_drop=0.0)  # never tracked back
    unmended = fitter.fit(frames)
    knee = body.axis_labels.index("b_knee.flex")
    assert all(abs(unmended[k].angles_deg[knee] - angles[k, knee]) > 5 for k in range(3, 9))
    assert [r.status for r in res[3:9]] == ["reanalysed"] * 6
    np.testing.assert_allclose([r.angles_deg for r in res], angles, atol=2.0)


def test_a_tracked_frame_whose_e_spikes_above_its_neighbours_is_ambiguous():
    """A tracked frame has no candidates to compare: one whose E stands out from the frames
    around it is flagged; noise on a clean video is not."""
    from dataclasses import replace

    from kinematics.fit import flag_e_spikes
    from kinematics.fit.tuning import TUNING

    body, cams = plane_arm()
    truth = np.linspace(-40.0, 40.0, 30)
    res = Fitter(body, cams, AnnealParams(start="track", segment_length=32, **FAST)).fit(
        frames_of(body, cams, truth))
    assert not [r.frame for r in res if r.status == "ambiguous"]
    bar = (TUNING.track_spike * np.median([r.error for r in res])
           + TUNING.track_jump_px * np.isfinite(res[0].marker_residuals).sum())
    spiked = [replace(r, error=2 * bar) if k in (0, 12, 29) else
              replace(r, error=0.9 * bar) if k == 20 else r for k, r in enumerate(res)]
    out = list(flag_e_spikes(spiked))
    assert [r.frame for r in out] == [r.frame for r in res]
    assert [k for k, r in enumerate(out) if r.status == "ambiguous"] == [0, 12, 29]
    # a gap after frame 19, then a run of 5 frames, a spike in its middle: compared with
    # its own run only, too short to tell
    gapped = res[:20] + [replace(r, frame=r.frame + 3, error=2 * bar if k == 2 else r.error)
                         for k, r in enumerate(res[20:25])]
    assert not [r.frame for r in flag_e_spikes(gapped) if r.status == "ambiguous"]


def test_a_cancelled_track_yields_every_frame_it_fitted():
    """Cancelled between groups of segments, the track still yields the segment it held
    back for mending."""
    body, cams = plane_arm()
    frames = frames_of(body, cams, np.linspace(-40.0, 40.0, 40))
    fitter = Fitter(body, cams, AnnealParams(start="track", segment_length=8, **FAST))
    asked = []
    res = list(fitter.iter_fit(frames, cancel=lambda: asked.append(1) or len(asked) > 1))
    n = 8 * min(numba.get_num_threads(), 5)
    assert [r.frame for r in res] == list(range(n))


def test_a_free_body_tracked_is_right_or_flagged():
    """Three legs on a freely turning and moving body, tracked: the trunk (a free root) is
    never swapped between fits, and every frame the track gets wrong (here a posture that
    fits the two views about as well) is flagged. Before the merge, the mending and the
    flag: 18 of 40 frames wrong, 3 of them flagged; after, 10, all flagged."""
    from kinematics.model import Axis, Body, Chain, Joint, Marker, Root, Segment

    legs = (leg("a", (4.0, 0, 6.0), 45.0), leg("b", (0.0, 0, 8.0), 90.0),
            leg("c", (-4.0, 0, 6.0), 135.0))
    thorax = Segment("thorax", 0.0, markers=(Marker("head", (8.0, 1.0, 0.0)),
                                             Marker("tail", (-8.0, 1.0, 0.0))), joints=legs)
    trunk = Joint("body", (Axis.free("turn", "y", -20, 20), Axis.free("rx", "x", -10, 10),
                           Axis.free("rz", "z", -10, 10)), segments=(thorax,))
    body, cams = Body("tripod", (Chain("c", trunk, Root("free")),), "px"), top_and_side()
    lo, hi = body.ranges_deg().T
    t = np.arange(40)[:, None]
    angles = np.where(body.locked_mask(), 0.0,
                      (lo + hi) / 2 + 10 * np.sin(t / 8.0 + np.arange(len(lo))))
    rng = np.random.default_rng(1)
    frames = [[c.project(forward_kinematics(body, a).markers) + rng.normal(0, 0.05, (8, 2))
               for c in cams.values()] for a in angles]
    res = Fitter(body, cams, AnnealParams(start="track", segment_length=16, **FAST)).fit(
        frames)
    wrong = [k for k, (r, a) in enumerate(zip(res, angles, strict=True))
             if np.abs(r.angles_deg - a).max() > 3.0]
    assert len(wrong) <= 12
    assert all(res[k].status in ("ambiguous", "failed") for k in wrong), wrong


@pytest.mark.parametrize("seed", range(6))
def test_path_kernel_equals_its_numpy_twin(seed):
    """Frames without candidates, ties (integer costs), cuts and an anchor's start costs."""
    rng = np.random.default_rng(seed)
    n, k = int(rng.integers(1, 40)), int(rng.integers(1, 5))
    unary = rng.integers(0, 4, (n, k)).astype(float)
    unary[rng.random((n, k)) < 0.25] = np.inf
    unary[rng.random(n) < 0.1] = np.inf  # whole frames without a candidate
    trans = rng.integers(0, 5, (n, k, k)).astype(float)
    cut = rng.random(n) < 0.15
    cut[0] = True
    bounds = np.r_[np.flatnonzero(cut), n].astype(np.int64)
    start0, use = rng.integers(0, 3, k).astype(float), bool(seed % 2)
    got = (np.full(n, -1, np.int64), np.full((n, k), np.inf))
    want = (np.full(n, -1, np.int64), np.full((n, k), np.inf))
    path_dp(unary, trans, bounds, start0, use, *got)
    _path_numpy(unary, trans, bounds, start0, use, *want)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])


def scored(worst: list[float], left: list[int]) -> list:
    """Fitted frames' results with these worst marker residuals and unexplained counts."""
    from kinematics.fit import FrameResult

    return [FrameResult(frame=k, angles_deg=np.zeros(3), error=1.0,
                        error_per_view=np.zeros(1), runs=2, iterations=1, seed=0, status="ok",
                        root_positions=np.zeros((1, 3)), worst_px=w, unexplained=u)
            for k, (w, u) in enumerate(zip(worst, left, strict=True))]


def test_a_marker_off_its_point_with_a_detection_left_over_is_misplaced():
    """A marker far off every detection flags a frame only when the frame also leaves more
    detections unexplained than its neighbours do: a limb on another limb's points leaves
    its own over; an occluded marker leaves nothing, ghosts are unexplained in every
    frame."""
    from kinematics.fit import misplaced

    rng = np.random.default_rng(1)
    worst = list(8.0 + rng.normal(0, 1.0, 40))  # a fly: residuals of ~8 px, no ghosts
    left = [0] * 40
    worst[5], left[5] = 30.0, 2  # a leg on another's points, its own left over
    worst[9], left[9] = 30.0, 0  # an occluded marker
    worst[13], left[13] = 9.0, 3  # detections left over, every marker on one
    left[20] = 1
    assert np.flatnonzero(misplaced(scored(worst, left), gate=10.0)).tolist() == [5]
    # with ghosts: 4-6 unexplained in every frame (one flickers), an occluded marker in
    # frames with 6, a frame that leaves a real detection over on top of them
    ghosts = [4 + int(k % 2) + int(k % 3 == 0) for k in range(40)]
    worst = [0.5] * 40
    for k in (6, 12, 18):
        worst[k] = 40.0
    worst[25], ghosts[25] = 40.0, 9
    assert np.flatnonzero(misplaced(scored(worst, ghosts), gate=10.0)).tolist() == [25]
    # within the gate a marker is on a point, however the others fit
    assert not misplaced(scored([0.1] * 39 + [9.0], [0] * 39 + [3]), gate=10.0).any()


def test_misplaced_frames_are_flagged_as_they_stream_and_when_resumed():
    """``flag_misplaced`` yields every result in order, judged among the results on either
    side; resumed with the results before it, it judges the rest as the whole stream did."""
    from kinematics.fit import flag_misplaced
    from kinematics.fit.tuning import TUNING

    rng = np.random.default_rng(2)
    n = 3 * TUNING.misplaced_half
    worst = 8.0 + rng.normal(0, 1.0, n)
    left = (rng.uniform(size=n) < 0.1).astype(int)
    for k in (3, 40, n - 2):
        worst[k], left[k] = 30.0, 2
    res = scored(list(worst), list(left))
    res[40] = replace(res[40], status="failed")  # a failed frame stays failed
    out = list(flag_misplaced(res, gate=10.0))
    assert [r.frame for r in out] == list(range(n))
    assert [r.frame for r in out if r.status == "ambiguous"] == [3, n - 2]
    assert out[40].status == "failed"
    for cut in (1, 20, 33):  # resumed with fewer or more results before than its half
        rest = list(flag_misplaced(res[cut:], gate=10.0, before=out[:cut]))
        assert [r.status for r in rest] == [r.status for r in out[cut:]], cut
    # after a gap in the frame numbers, a run of frames is judged among itself: 5 frames that
    # all fit worse than the frames before the gap are ordinary among themselves
    later = [replace(r, frame=r.frame + 100, worst_px=30.0, unexplained=2) for r in res[:5]]
    assert all(r.status == "ok" for r in list(flag_misplaced(res[:40] + later, 10.0))[40:])
    # ... and so is a new sequence (concatenated recordings, frame numbers continuing)
    joined = res[:40] + [replace(r, frame=40 + k) for k, r in enumerate(later[:2])]
    assert all(r.status == "ambiguous" for r in list(flag_misplaced(joined, 10.0))[40:])
    assert all(r.status == "ok" for r in list(flag_misplaced(joined, 10.0, starts=[40]))[40:])
    # from frame 50 on every marker fits worse (20 px): frame 50's 30 px stands out from the
    # frames after it alone, not from those on both sides
    cut = 50
    worst[cut:] += 12.0
    worst[cut] = 30.0
    left[cut] = 2
    res = scored(list(worst), list(left))
    out = list(flag_misplaced(res, gate=10.0))
    assert out[cut].status == "ok"
    rest = list(flag_misplaced(res[cut:], gate=10.0, before=out[:cut]))
    assert [r.status for r in rest] == [r.status for r in out[cut:]]
    assert next(flag_misplaced(res[cut:], gate=10.0)).status == "ambiguous"


def test_a_kink_the_markers_do_not_show_leaves_the_stretch_between_two_kinks_whole():
    """``seen`` drops a frame's own kink before the frames between two kinks are added: the
    middle of a short wrong stretch lies on the line through its (wrong) neighbours, so its
    markers show no kink of its own, yet it goes with the stretch."""
    postures = np.linspace(0.0, 20.0, 24)[:, None]
    postures[10:13] += 30.0  # a wrong stretch of 3 frames
    scale = np.ones(1)
    every = kinks(postures, scale, 0)
    assert np.flatnonzero(every).tolist() == [9, 10, 11, 12, 13]
    seen = np.ones(24, bool)
    seen[11] = False
    assert np.flatnonzero(kinks(postures, scale, 0, seen=seen)).tolist() == [9, 10, 11, 12, 13]
    seen[9] = False
    assert np.flatnonzero(kinks(postures, scale, 0, seen=seen)).tolist() == [10, 11, 12, 13]
