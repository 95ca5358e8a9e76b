"""Matching in 3D (``match = "3d"``): the cloud objective's kernel against its NumPy twin,
partition claims on a cloud, the refinement pairs, and bodies fitted to triangulated markers
where matching per view lets limbs share blobs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinematics._kernels import anneal as ak
from kinematics._kernels import codes as _codes
from kinematics._kernels import error3d as _error3d
from kinematics._kernels import fastmath as _fastmath
from kinematics._kernels import objective as _objective
from kinematics._kernels import posture as _posture
from kinematics._kernels import refine as rk
from kinematics._kernels.records import FrameObs, new_scratch
from kinematics.errors import KinematicsError
from kinematics.fit import AnnealParams, Candidate, Fitter, FrameResult
from kinematics.fit.error_function import cloud_error
from kinematics.fit.polish import held_limb
from kinematics.fit.problem import ErrorArgs, Schedule
from kinematics.fit.settings import ErrorOptions
from kinematics.model.fk import forward_kinematics_reference
from kinematics.observe.observations import Observations
from tests.fixtures.bodies import three_legs
from tests.fixtures.cameras import ring
from tests.fixtures.planted import marker_errors, planted_postures, random_cloud

OPTIONS = [ErrorOptions(), ErrorOptions(cap_px=4.0), ErrorOptions(mode="bidirectional"),
           ErrorOptions(mode="bounded", cap_px=6.0), ErrorOptions(mode="bidirectional",
                                                                  penalty_weight=0.5),
           ErrorOptions(one_to_one=True), ErrorOptions(mode="bounded", cap_px=6.0,
                                                       one_to_one=True)]


@pytest.mark.parametrize("opts", OPTIONS, ids=lambda o: f"{o.mode}-{o.cap_px}-{o.one_to_one}")
def test_cloud_error_kernel_equals_twin(opts):
    rng = np.random.default_rng(3)
    for _ in range(20):
        mk, cloud = random_cloud(rng)
        nearest = np.empty(len(mk), np.int64)
        got = _error3d.cloud_error(mk, cloud, 0, len(mk), _codes.NO_CLAIMS,
                             opts.penalty_weight if opts.bidirectional else 0.0, opts.cap,
                             opts.penalty_cap, opts.one_to_one, nearest)
        assert got == pytest.approx(cloud_error(mk, cloud, opts), rel=1e-12)


@pytest.mark.parametrize("opts", OPTIONS, ids=lambda o: f"{o.mode}-{o.cap_px}-{o.one_to_one}")
def test_a_cloud_of_colours_lets_a_marker_take_only_its_colours_points(opts):
    """Each point carries which markers may take it (its colour's): the kernel equals the
    twin, a marker whose colour has no point pays the missing cost, and a point no marker
    may take is explained by none and costs nothing."""
    rng = np.random.default_rng(8)
    for trial in range(30):
        mk, cloud = random_cloud(rng)
        colour = rng.integers(0, 3, len(mk))
        point_colour = rng.integers(0, 3 if trial % 5 else 2, len(cloud))
        may = (point_colour[:, None] == colour[None]).astype(float)
        coloured = np.concatenate([cloud, may], axis=1)
        nearest = np.empty(len(mk), np.int64)
        got = _error3d.cloud_error(mk, coloured, 0, len(mk), _codes.NO_CLAIMS,
                             opts.penalty_weight if opts.bidirectional else 0.0, opts.cap,
                             opts.penalty_cap, opts.one_to_one, nearest)
        assert got == pytest.approx(cloud_error(mk, coloured, opts), rel=1e-12)
        for i, c in enumerate(nearest):  # every pairing within the colour
            point = c if c >= 0 else -c - 2
            if c != -1 and not opts.one_to_one:
                assert may[point, i]
        claimed = np.zeros(len(cloud), np.bool_)
        _error3d.claim_cloud(mk, coloured, np.ones(len(mk), np.bool_), 1e9, claimed)
        assert all(may[c].any() for c in np.flatnonzero(claimed))
        far = _error3d.count_unexplained_cloud(mk, coloured, 1e9)  # only colours no marker has
        assert far == int(((cloud[:, 3] > 0) & ~may.any(axis=1)).sum())


def test_partition_cloud_error_leaves_claimed_points_out():
    rng = np.random.default_rng(5)
    opts = ErrorOptions(mode="bounded", cap_px=30.0)
    for _ in range(20):
        mk, cloud = random_cloud(rng)
        claimed = np.zeros(len(cloud), np.bool_)
        others = np.ones(len(mk), np.bool_)
        others[2:5] = False
        _error3d.claim_cloud(mk, cloud, others, 40.0, claimed)  # markers outside 2:5 claim
        want = set()
        for i in [0, 1, 5, 6]:
            d = cloud[:, 3] * np.linalg.norm(mk[i] - cloud[:, :3], axis=1)
            d[cloud[:, 3] <= 0] = np.inf
            if d.min() <= 40.0:
                want.add(int(np.argmin(d)))
        assert set(np.flatnonzero(claimed)) == want
        got = _objective.partition_error(_codes.OBJ_CLOUD, np.zeros((0, len(mk), 2)), mk,
                                         np.empty((0, 2)),
                                 np.empty(0), np.zeros(1, np.int64), cloud, opts.cap, 2, 5,
                                 claimed, opts.penalty_weight, opts.penalty_cap,
                                 opts.one_to_one, np.empty(len(mk), np.int64))
        assert got == pytest.approx(cloud_error(mk[2:5], cloud, opts, claimed), rel=1e-12)


def test_refinement_pairs_markers_with_their_nearest_point_in_pixels():
    mk = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    cloud = np.array([[0.1, 0.0, 0.0, 10.0], [3.0, 0.5, 0.0, 10.0], [0.0, 0.0, 0.05, 0.0]])
    pair = np.empty(2, np.int64)
    proj = np.zeros((0, 2, 2))
    n = rk.assign_pairs(_codes.OBJ_CLOUD, proj, mk, np.empty((0, 2)), np.empty(0),
                        np.zeros(1, np.int64), cloud, 2.0, pair)  # gate 2 px = 0.2 units
    assert n == 1 and pair.tolist() == [0, -1]  # padding row 2 is never a pair
    res = np.empty(6)
    sse = rk.fill_residuals(_codes.OBJ_CLOUD, proj, mk, np.empty((0, 2)), np.empty(0), cloud,
                            pair, res)
    assert sse == pytest.approx(1.0)  # 0.1 units at 10 px per unit


def test_polish_pairs_each_point_with_one_marker():
    """``OBJ_CLOUD_ONE`` (the final polish): a point two markers have as their nearest stays
    with the closer one, the other takes its next free point within the gate, or none."""
    mk = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [5.0, 0.0, 0.0], [5.2, 0.0, 0.0]])
    cloud = np.array([[0.1, 0.0, 0.0, 10.0], [0.6, 0.0, 0.0, 10.0], [5.0, 0.0, 0.0, 10.0]])
    pair = np.empty(4, np.int64)
    args = (np.zeros((0, 4, 2)), mk, np.empty((0, 2)), np.empty(0), np.zeros(1, np.int64),
            cloud, 5.0, pair)
    assert rk.assign_pairs(_codes.OBJ_CLOUD, *args) == 4 and pair.tolist() == [0, 0, 2, 2]
    assert rk.assign_pairs(_codes.OBJ_CLOUD_ONE, *args) == 3
    assert pair.tolist() == [0, 1, 2, -1]  # marker 3's spare point is 46 px off: no pair
    res = np.empty(12)
    sse = rk.fill_residuals(_codes.OBJ_CLOUD_ONE, args[0], mk, args[2], args[3], cloud, pair,
                            res)
    assert sse == pytest.approx(1.0 + 9.0)  # 0.1 and 0.3 units at 10 px per unit
    # two markers that both lost point 0 take the one spare point in turn: the first keeps it
    mk = np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [-0.2, 0.0, 0.0]])
    cloud = np.array([[0.0, 0.0, 0.0, 10.0], [1.0, 0.0, 0.0, 10.0]])
    pair = np.empty(3, np.int64)
    assert rk.assign_pairs(_codes.OBJ_CLOUD_ONE, np.zeros((0, 3, 2)), mk, np.empty((0, 2)),
                           np.empty(0), np.zeros(1, np.int64), cloud, 50.0, pair) == 2
    assert pair.tolist() == [0, 1, -1]


@pytest.mark.parametrize("one_to_one", [False, True], ids=["nearest", "one-to-one"])
def test_three_legs_fitted_to_their_triangulated_markers(one_to_one):
    body = three_legs()
    cams = ring()
    angles, frames = planted_postures(body, cams, 8, seed=11, shuffle=True)
    # the defaults (bounded error, 10-px cap, start search); without the search the cap
    # leaves far limbs no slope to follow and 4 of 8 frames end off
    params = AnnealParams(match="3d", candidates=1, threshold_mode="absolute",
                          reanalysis_threshold=8.0,
                          error=ErrorOptions("bounded", cap_px=10.0, one_to_one=one_to_one)
                          ).with_schedule(3000)
    fitter = Fitter(body, cams, params)
    obs = fitter.observations(frames)
    assert obs.kind == "cloud" and (obs.points3d[..., 3] > 0).sum(axis=1).tolist() == [8] * 8
    res = fitter.fit(frames)
    err = marker_errors(body, res, angles)
    assert np.median(err) < 0.05 and err.max() < 0.2, err
    assert all(r.status == "ok" and r.unexplained == 0 for r in res)
    # E is the sum over markers in pixels at the markers: about the 2D noise per marker
    assert np.median([r.error for r in res]) < 0.5 * 8
    e, per_view = fitter.error(res[0].angles_deg, frames[0])
    assert e == pytest.approx(res[0].error, rel=1e-9) and not per_view.any()


def test_match_3d_needs_unlabelled_points_and_valid_settings():
    with pytest.raises(KinematicsError, match="match"):
        AnnealParams(match="2d")
    obs = Observations.points_3d(np.zeros((2, 1, 3)), ["m"], ["m"])
    with pytest.raises(KinematicsError, match="unlabelled"):
        obs.with_cloud(np.zeros((2, 1, 4)))


def test_match_3d_refuses_two_views():
    cams = dict(list(ring().items())[:2])
    fitter = Fitter(three_legs(), cams, AnnealParams(match="3d"))
    with pytest.raises(KinematicsError, match="3 or more views"):
        fitter.observations([[np.zeros((1, 2)), np.zeros((1, 2))]])


def test_3d_points_fit_with_cameras_given():
    """Labelled 3D points need no cameras, but a fitter made with them fits them too (the
    views simply have no observations), to the bit as without them: the annealing, the
    search and the refinement project a 3D objective into no view (drawn_views)."""
    body = three_legs()
    cams = ring()
    angles, _ = planted_postures(body, cams, 3, seed=2, shuffle=True)
    pts = forward_kinematics_reference(body, angles[0]).markers[None].repeat(2, axis=0)
    pts[1] += 0.3  # a second frame the chain cannot fit exactly
    obs = Observations.points_3d(pts, body.marker_names, body.marker_names)
    params = AnnealParams(tau0=5.0, candidates=1, threshold_mode="absolute",
                          reanalysis_threshold=1.0).with_schedule(2000)
    res = Fitter(body, cams, params).fit(obs)
    assert len(res) == 2 and all(np.isfinite(r.error) for r in res)
    assert res[0].missing_views == ()
    assert res[0].refined_pairs > 0  # the refinement ran
    alone = Fitter(body, {}, params).fit(obs)
    for a, b in zip(res, alone, strict=True):
        assert a.error == b.error and np.array_equal(a.angles_deg, b.angles_deg)


def test_final_polish_spreads_a_misfit_by_least_squares():
    """Matching in 3D, the chosen posture is finally fitted by least squares to its cloud
    points (``final_polish_px``): where a marker's point lies off the rigid chain, the
    polished posture has a lower sum of squared distances than the annealed one (which
    minimises a sum of distances), as low as scipy's least squares from it reaches; E is
    that of the polished posture, the status the fit's; None leaves the fit as annealed. A
    limb one of whose markers has no point (leg c's tip, hidden in every view of a fifth
    frame) keeps its annealed posture while the others move."""
    from scipy.optimize import least_squares

    body = three_legs()
    cams = ring()
    angles, _ = planted_postures(body, cams, 5, seed=5)
    rng = np.random.default_rng(2)
    frames, targets = [], []
    for a in angles:
        m = forward_kinematics_reference(body, a).markers
        step = rng.normal(0.0, 1.0, 3)
        m[4] += step / np.linalg.norm(step)  # b's knee 10 px off where the chain can be
        targets.append(m)
        frames.append([c.project(m) for c in cams.values()])
    frames[4] = [v[:7] for v in frames[4]]  # c's tip: no point in the last frame
    params = AnnealParams(match="3d", candidates=1, threshold_mode="absolute",
                          reanalysis_threshold=50.0).with_schedule(3000)
    polished = Fitter(body, cams, params).fit(frames)
    with_candidates = Fitter(body, cams, replace(params, candidates=2)).fit(frames[:2])
    for r in with_candidates:  # the chosen candidate is polished with it
        assert sum(np.array_equal(c.angles_deg, r.angles_deg) for c in r.candidates) == 1
    fitter = Fitter(body, cams, replace(params, final_polish_px=None))
    annealed = fitter.fit(frames)
    free = ~body.locked_mask()

    def sse(a, target):
        return float(((forward_kinematics_reference(body, a).markers - target) ** 2).sum())

    c_leg = slice(15, 21)  # c_hip, c_knee
    # (through radians and back: equal to the last bits)
    assert np.allclose(polished[4].angles_deg[c_leg], annealed[4].angles_deg[c_leg], rtol=0,
                       atol=1e-9)
    assert not np.allclose(polished[4].angles_deg[:15], annealed[4].angles_deg[:15])
    for p, q, target, frame in zip(polished[:4], annealed[:4], targets, frames, strict=False):
        assert p.status == q.status and p.runs == q.runs
        assert sse(p.angles_deg, target) <= sse(q.angles_deg, target) + 1e-9
        lo, hi = body.ranges_deg()[free].T

        def resid(x, target=target, start=p.angles_deg):
            a = start.copy()
            a[free] = x
            return (forward_kinematics_reference(body, a).markers - target).ravel()

        best = least_squares(resid, np.clip(p.angles_deg[free], lo, hi), bounds=(lo, hi))
        # the product weighs each point by its px per unit, scipy does not: 1 % apart
        assert sse(p.angles_deg, target) <= 1.01 * 2 * best.cost + 1e-9
        assert p.error == pytest.approx(fitter.error(p.angles_deg, frame)[0], rel=1e-9)
    # an accepted frame is never polished across its threshold: it stays as fitted
    assert polished[0].error > annealed[0].error
    mid = 0.5 * (polished[0].error + annealed[0].error)
    held = Fitter(body, cams, replace(params, reanalysis_threshold=mid)).fit(frames[:1])[0]
    assert held.status == "ok" and held.error == annealed[0].error
    spread = [sse(p.angles_deg, t) for p, t in zip(polished[:4], targets, strict=False)]
    as_annealed = [sse(q.angles_deg, t) for q, t in zip(annealed[:4], targets, strict=False)]
    assert sum(spread) < 0.8 * sum(as_annealed), (spread, as_annealed)


def test_final_polish_places_a_marker_without_a_point_by_its_views():
    """A marker without a cloud point (a's tip seen by 2 of 5 cameras: no point needs
    fewer than 3) is placed in the polish by its detections in the views that see it, so
    its limb moves too; seen by one camera only, nothing places it, its limb keeps its
    annealed posture and the frame is ambiguous (a look). So is it where a stray blob in a
    second view, near the annealed tip but off the tip's ray, made it look placed: after
    the polish the two views do not both explain it."""
    body = three_legs()
    cams = ring()
    angles, _ = planted_postures(body, cams, 2, seed=7)
    names = body.marker_names
    tip = names.index("a_tip")
    a_leg = [i for i, lab in enumerate(body.axis_labels) if lab.startswith("a_")]
    targets = [forward_kinematics_reference(body, a).markers for a in angles]
    frames = [[c.project(m) for c in cams.values()] for m in targets]
    seen_by = (2, 1)  # frame 0: two cameras see the tip, frame 1: one
    for f, n in enumerate(seen_by):
        frames[f] = [v if k >= len(cams) - n else np.delete(v, tip, axis=0)
                     for k, v in enumerate(frames[f])]
    frames.append(list(frames[1]))  # frame 2: frame 1 and, below, a stray blob
    targets.append(targets[1])
    # 9000 iterations a round: 2700 for each leg, 900 for the trunk (shared by axes)
    params = AnnealParams(match="3d", candidates=1, threshold_mode="absolute",
                          reanalysis_threshold=1e6, final_polish_px=200.0).with_schedule(9000)
    annealing = Fitter(body, cams, replace(params, final_polish_px=None))
    # the stray: in view 3, 5 px from the annealed tip, on the side away from the true tip
    view3 = list(cams.values())[3]
    at = view3.project(forward_kinematics_reference(
        body, annealing.fit(frames)[2].angles_deg).markers[tip])
    away = at - view3.project(targets[2][tip])
    assert np.linalg.norm(away) > 30.0  # the annealed tip is off: nothing places it
    frames[2][3] = np.vstack([frames[2][3], at + 5.0 * away / np.linalg.norm(away)])
    fitter = Fitter(body, cams, params)
    assert not np.isnan(fitter.observations(frames).points3d).all()
    polished = fitter.fit(frames)
    annealed = annealing.fit(frames)

    def tip_error(r, target):
        return np.linalg.norm(forward_kinematics_reference(body, r.angles_deg).markers[tip]
                              - target[tip])

    moved = [not np.allclose(p.angles_deg[a_leg], q.angles_deg[a_leg], rtol=0, atol=1e-9)
             for p, q in zip(polished, annealed, strict=True)]
    assert moved == [True, False, False]
    assert tip_error(polished[0], targets[0]) < 0.5 * tip_error(annealed[0], targets[0])
    assert [r.status for r in annealed] == ["ok", "ok", "ok"]
    assert [r.status for r in polished] == ["ok", "ambiguous", "ambiguous"]


def test_a_held_limb_is_ambiguous_where_its_runs_put_it_apart(monkeypatch):
    """A frame whose limb the final polish held is ``ambiguous`` where the frame's runs put
    that limb's markers more than ``ambiguous_move`` segment lengths apart (one run: always),
    or the next frame's runs do: where every run found the limb in one place it stays ``ok``
    (through 3 cameras 120 of the fly's 660 frames held a limb, 104 of them right). The next
    frame counts only where it follows on, and only frames within the threshold change."""
    body = three_legs()
    cams = ring()
    fitter = Fitter(body, cams, AnnealParams(match="3d", candidates=2))
    apart = fitter._apart(fitter.params)
    assert apart == pytest.approx(0.25 * fitter._segment_scale)
    frames = [0, 1, 2, 3, 4, 5, 7, 8, 9]
    spreads = [None, 0.1 * apart, 2 * apart, 0.1 * apart, 0.1 * apart, 0.5 * apart,
               2 * apart, np.inf, 0.5 * apart]
    statuses = ["ok", "ok", "ok", "ok", "failed", "ok", "ok", "ok", "reanalysed"]
    planted = {f: (s, st) for f, s, st in zip(frames, spreads, statuses, strict=True)}

    def polished(self, obs, position, r):
        spread, status = planted[r.frame]
        return replace(r, status=status), spread
    monkeypatch.setattr(Fitter, "_polished", polished)
    results = [FrameResult(f, np.zeros(body.n_axes), 1.0, np.zeros(len(cams)), 2, 1,
                                  0, "ok", np.zeros((1, 3))) for f in frames]
    out = list(fitter._final_polish(None, np.array(frames), iter(results)))
    assert [r.frame for r in out] == frames
    # 1: the next frame's runs part; 4: failed stays failed; 5: frame 6 is missing, so
    # frame 7 does not count; 8: one run; 9: the last frame, its own runs only
    assert [r.status for r in out] == ["ok", "ambiguous", "ambiguous", "ok", "failed", "ok",
                                       "ambiguous", "ambiguous", "reanalysed"]


def test_a_held_limbs_runs_are_measured_on_its_own_markers():
    """How far apart a frame's runs put its held limb is measured on that limb's markers
    only: runs that differ in another leg leave it 0 (the frame stays ``ok``), runs that
    differ in the held leg by more than ``ambiguous_move`` segment lengths make it
    ``ambiguous``; a frame without a held limb has none (None). a's tip is seen by one
    camera only, so nothing places it and its leg is held."""
    body = three_legs()
    cams = ring()
    angles, _ = planted_postures(body, cams, 2, seed=7)
    tip = body.marker_names.index("a_tip")
    frames = [[c.project(forward_kinematics_reference(body, a).markers) for c in cams.values()]
              for a in angles]
    frames[0] = [v if k == len(cams) - 1 else np.delete(v, tip, axis=0)
                 for k, v in enumerate(frames[0])]
    params = AnnealParams(match="3d", candidates=1, threshold_mode="absolute",
                          reanalysis_threshold=1e6, final_polish_px=200.0).with_schedule(3000)
    fitter = Fitter(body, cams, params)
    obs = fitter.observations(frames)
    held, whole = fitter.fit(obs)
    assert held.status == "ambiguous" and whole.status == "ok"  # one run: always flagged
    labels = body.axis_labels

    def own(r):  # the result as a candidate (one run keeps none)
        return Candidate(r.angles_deg, r.root_positions, r.error,
                         *fitter.state(r.angles_deg, r.root_positions))

    def moved(r, leg, by):
        a = r.angles_deg.copy()
        a[[i for i, lab in enumerate(labels) if lab.startswith(leg + "_")
           and not body.locked_mask()[i]]] += by
        return own(r)._replace(angles_deg=a)

    for leg, by, spread, status in (("b", 20.0, 0.0, "ok"), ("a", 20.0, None, "ambiguous"),
                                    ("a", 0.01, None, "ok")):
        r = replace(held, status="ok", candidates=(own(held), moved(held, leg, by)))
        out, got = fitter._polished(obs, 0, r)
        if spread is None:
            assert got > 0.0 and (got > fitter._apart(fitter.params)) == (status == "ambiguous")
        else:
            assert got == spread
        assert held_limb(out, got, fitter._apart(fitter.params)).status == status
    r = replace(whole, candidates=(own(whole), moved(whole, "a", 20.0)))
    assert fitter._polished(obs, 1, r)[1] is None


@pytest.mark.parametrize("case, dets, own, placed", [
    ("fused in two views, seen apart in one", [(103, 100), (108, 100), (102, 101)],
     [False, True, False], True),
    ("hidden everywhere, on a neighbour's point", [(101, 100), (99, 101), (100, 102)],
     [False, False, False], False),
    ("seen apart in one view, a point's blob 30 px off in the others",
     [(130, 100), (108, 100), (100, 130)], [False, True, False], False),
    ("seen apart in two views, 40 px off", [(140, 100), (100, 140), (300, 300)],
     [True, True, False], True),
])
def test_a_marker_without_a_point_is_placed_by_two_views_one_its_own(case, dets, own,
                                                                      placed):
    """The polish's rule for a marker without a cloud point: a detection within the gate
    (50 px) where no point has it, within cap_px (10 px) where one has it (a fused blob),
    in two views, one of them the marker's own."""
    from kinematics.fit.polish import _placed

    proj = np.full((3, 1, 2), 100.0)
    points = np.array(dets, float)
    got = _placed(proj, points, np.arange(4), np.array(own), 50.0, 10.0)
    assert got.tolist() == [placed], case


@pytest.mark.parametrize("opts", OPTIONS, ids=lambda o: f"{o.mode}-{o.cap_px}-{o.one_to_one}")
def test_the_unclaimed_points_score_as_the_claims_do(opts):
    """A limb's search and annealing score a cloud without its claimed points and padding
    (``unclaimed_cloud``): the same E to the bit, coloured clouds included."""
    rng = np.random.default_rng(12)
    penalty = opts.penalty_weight if opts.bidirectional else 0.0
    for trial in range(12):
        mk, cloud = random_cloud(rng)
        if trial % 3 == 0:  # one column per marker: which markers may take the point
            cloud = np.concatenate([cloud, rng.integers(0, 2, (len(cloud), len(mk)))], 1)
        claimed = rng.random(len(cloud)) < 0.4
        rest, none = _error3d.unclaimed_cloud(cloud, claimed)
        assert none.size == 0 and len(rest) == int(((cloud[:, 3] > 0) & ~claimed).sum())
        for m0, m1 in ((0, len(mk)), (2, 5)):
            want = _error3d.cloud_error(mk, cloud, m0, m1, claimed, penalty, opts.cap,
                                  opts.penalty_cap, opts.one_to_one, np.empty(len(mk), np.int64))
            got = _error3d.cloud_error(mk, rest, m0, m1, none, penalty, opts.cap, opts.penalty_cap,
                                 opts.one_to_one, np.empty(len(mk), np.int64))
            assert got == want


@pytest.mark.parametrize("opts", [o for o in OPTIONS if not o.one_to_one],
                         ids=lambda o: f"{o.mode}-{o.cap_px}")
def test_each_distance_computed_once_scores_as_cloud_error(opts):
    """The annealing loop's cloud error (``cloud_error_once``: each marker-point distance
    computed once for both terms) equals ``cloud_error`` to the bit, with the same nearest
    points: padding rows, coloured clouds, a partition's markers, and ties (a point given
    twice goes to the lower row)."""
    rng = np.random.default_rng(21)
    penalty = opts.penalty_weight if opts.bidirectional else 0.0
    for trial in range(40):
        mk, cloud = random_cloud(rng, n_points=int(rng.integers(0, 12)))
        if trial % 4 == 1 and len(cloud) > 4:  # a tie: the same point in two rows
            cloud[3] = cloud[1]
        if trial % 3 == 0:  # one column per marker: which markers may take the point
            cloud = np.concatenate([cloud, rng.integers(0, 2, (len(cloud), len(mk)))], 1)
        for m0, m1 in ((0, len(mk)), (2, 5)):
            want_near = np.full(len(mk), -7, np.int64)
            got_near = want_near.copy()
            want = _error3d.cloud_error(mk, cloud, m0, m1, _codes.NO_CLAIMS, penalty, opts.cap,
                                  opts.penalty_cap, False, want_near)
            got = _error3d.cloud_error_once(mk, cloud, m0, m1, penalty, opts.cap, opts.penalty_cap,
                                      got_near, np.empty(len(mk)), np.empty(len(cloud)))
            assert got == want
            assert np.array_equal(got_near, want_near)


@pytest.mark.parametrize("match", ["3d", "views"])
def test_the_start_search_scores_a_draw_from_its_beam(match):
    """The start search scores a draw by its beam's E of the markers earlier stages placed
    plus the E of the markers its stage places, recomputing only the joints that move
    them: the E it returns is that of the posture it keeps, recomputed whole."""
    body = three_legs()
    cams = ring()
    _, frames = planted_postures(body, cams, 1, seed=4, shuffle=True)
    fitter = Fitter(body, cams, AnnealParams(match=match, error=ErrorOptions(cap_px=10.0)))
    pr = fitter.problem
    obs = fitter.observations(frames)
    cams_k, arrays = fitter._kernel_inputs(obs.arrays(np.array([0], np.int64)))
    roots, rots = fitter._place(obs, np.array([0]))
    parts = fitter._partitions(fitter.params)
    assert parts.samples > 0 and parts.bounds.shape[0] == 4  # the trunk and three legs
    obs3 = arrays.points3d[0]
    claimed = np.zeros(max(len(arrays.points), len(obs3)), np.bool_)
    nj, nm, ns, nv = pr.folded.parent.size, pr.folded.marker_joint.size, pr.n_state, len(
        cams_k.kind)
    scratch = new_scratch(ns, nj, nm, nv)
    cs, sn, rot, pos, mk, proj = (scratch.cs, scratch.sn, scratch.rot, scratch.pos, scratch.mk,
                                  scratch.proj)
    schedule = Schedule(1e-300, 16, 1, 1, 1, 1.0, 1.0, 1.0, 1.0, 0.0, 0, 0.0, 1, 0, 0.0, False,
                        -1, 1)
    parts16 = parts._replace(samples=16)
    obs = FrameObs(arrays.objective, arrays.points, arrays.conf, arrays.offsets, obs3)
    for p in range(1, 4):  # each leg (trunk at the start posture)
        work = pr.start.copy()
        _posture.project_posture(work, roots[0], rots[0], pr.folded, cams_k, cs, sn, rot, pos,
                                 mk, proj)
        j0, j1, m0, m1 = parts.bounds[p, :4]
        e = ak.beam_start(work, parts.stage_off[p], parts.stage_off[p + 1], parts16,
                          np.uint64(_fastmath.stream_state(0, p, 0)), roots[0], rots[0],
                          pr.folded, cams_k, pr.dofs, schedule,
                          ErrorArgs(False, 0.0, 10.0, np.inf, False), obs, (j0, j1, m0, m1),
                          claimed, scratch)
        _posture.project_posture(work, roots[0], rots[0], pr.folded, cams_k, cs, sn, rot, pos,
                                 mk, proj)
        whole = _objective.partition_error(arrays.objective, proj, mk, arrays.points, arrays.conf,
                                   arrays.offsets, obs3, 10.0, m0, m1, claimed, 0.0, np.inf,
                                   False, scratch.nearest)
        assert np.isfinite(e) and e == pytest.approx(whole, rel=1e-9, abs=1e-9)
        assert (work != pr.start).any()
