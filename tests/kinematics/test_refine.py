"""Local refinement: numba Levenberg-Marquardt == scipy least_squares, ranges, locked axes,
gating, and accuracy near the Cramér-Rao bound."""

from dataclasses import replace

import numpy as np
import pytest

from kinematics.errors import KinematicsError
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.refine import (
    cramer_rao_bound,
    projection_jacobian,
    refine,
    refine_many,
    refine_reference,
)
from kinematics.model.fk import forward_kinematics
from tests.fixtures.bodies import three_legs
from tests.fixtures.cameras import top_and_side
from tests.fixtures.planted import planted_postures
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import locust_cameras


def detections(body, cams, angles, rng, noise=0.2):
    markers = forward_kinematics(body, angles).markers
    return [c.project(markers) + rng.normal(0, noise, (len(markers), 2)) for c in cams.values()]


def test_kernel_equals_scipy_least_squares(locust):
    cams = locust_cameras()
    fitter = Fitter(locust, cams)
    rng = np.random.default_rng(0)
    free = ~locust.locked_mask()
    for truth in smooth_random_motion(locust, 8, 8, seed=0):
        det = detections(locust, cams, truth, rng)
        start = truth + np.where(free, rng.normal(0, 1.0, truth.size), 0.0)
        # A wide gate: the twin pairs once at the start, the kernel after every step.
        got = refine(fitter, start, det, steps=30, gate_px=20.0)
        want = refine_reference(fitter, start, det, gate_px=20.0)
        assert got.n_pairs == want.n_pairs == 8
        np.testing.assert_allclose(got.angles_deg, want.angles_deg, atol=2e-4)
        assert got.sse == pytest.approx(want.sse, rel=1e-6, abs=1e-9)
        assert got.sse <= np.sum((np.concatenate(det) - np.concatenate(
            list(fitter.project(start)))) ** 2)


def test_refinement_reaches_the_cramer_rao_bound(locust):
    """Annealing on a short schedule, then refinement: RMS error within 1.3x of the bound
    (40 frames; the benchmark checks 668)."""
    cams = locust_cameras()
    sigma = 0.2
    truth = smooth_random_motion(locust, 40, 40, seed=1)
    rng = np.random.default_rng(1)
    dets = [detections(locust, cams, a, rng, sigma) for a in truth]
    fitter = Fitter(locust, cams, AnnealParams.paper(refine=True).with_schedule(5000))
    results = fitter.fit(dets)
    free = ~locust.locked_mask()
    err = np.array([r.angles_deg for r in results])[:, free] - truth[:, free]
    rmse = np.sqrt((err**2).mean(axis=0))
    bound = np.sqrt(np.mean([cramer_rao_bound(fitter, a, sigma) ** 2 for a in truth], axis=0))
    assert np.all(rmse < 1.3 * bound + 0.02), (rmse, bound)
    assert all(r.refined_pairs == 8 for r in results)
    for r, d in zip(results[:5], dets[:5], strict=True):
        assert r.error == pytest.approx(fitter.error(r.angles_deg, d)[0], rel=1e-9)


def test_ranges_and_locked_axes_are_respected(locust):
    cams = locust_cameras()
    fitter = Fitter(locust, cams)
    truth = np.array([219.5, 39.5, 9.5, 0, 0, 59.5, 0, 0, 159.5])  # just inside every max
    rng = np.random.default_rng(2)
    lo, hi = locust.ranges_deg().T
    locked = locust.locked_mask()
    hit_bound = 0
    for _ in range(10):
        det = detections(locust, cams, truth, rng, noise=0.5)
        r = refine(fitter, truth, det)
        assert np.all(r.angles_deg >= lo - 1e-9) and np.all(r.angles_deg <= hi + 1e-9)
        np.testing.assert_array_equal(r.angles_deg[locked], 0.0)
        hit_bound += np.isclose(r.angles_deg[~locked], hi[~locked]).sum()
    assert hit_bound > 0  # the noise pushed some axis against its bound


def test_gate_ignores_ghosts_and_occluded_markers(locust):
    cams = locust_cameras()
    fitter = Fitter(locust, cams)
    rng = np.random.default_rng(3)
    truth = np.array([170.0, 5.0, 2.0, 0, 0, 30.0, 0, 0, 100.0])
    det = detections(locust, cams, truth, rng)
    start = truth + np.where(locust.locked_mask(), 0.0, 0.3)
    base = refine(fitter, start, det)
    far_ghost = [np.vstack([det[0], [[20.0, 20.0]]]), det[1]]
    np.testing.assert_array_equal(refine(fitter, start, far_ghost).angles_deg, base.angles_deg)
    occluded = [det[0][[0, 1, 3]], det[1]]  # M2 hidden in the side view
    r = refine(fitter, start, occluded, gate_px=3.0)
    assert r.n_pairs == 7
    assert np.abs(r.angles_deg - truth).max() < 3.0
    unchanged = refine(fitter, start, det, steps=0)
    np.testing.assert_allclose(unchanged.angles_deg, start, atol=1e-12)
    with pytest.raises(KinematicsError) as err:
        refine(fitter, start, det, gate_px=0.0)
    assert err.value.field == "refine_gate_px"


def test_cramer_rao_bound_properties(locust):
    fitter = Fitter(locust, locust_cameras())
    angles = np.array([170.0, 5.0, 2.0, 0, 0, 30.0, 0, 0, 100.0])
    jac = projection_jacobian(fitter, angles)
    assert jac.shape == (2 * 4 * 2, 5)
    assert np.all(jac[:2] == 0)  # M0 sits on the fixed root: no information
    b1 = cramer_rao_bound(fitter, angles, 0.1)
    np.testing.assert_allclose(cramer_rao_bound(fitter, angles, 0.3), 3 * b1)
    hidden = np.ones((2, 4), bool)
    hidden[0, 1] = False  # M1 occluded in the side view
    assert np.all(cramer_rao_bound(fitter, angles, 0.1, visible=hidden) >= b1 - 1e-12)
    ab = cramer_rao_bound(fitter, angles, 0.1, combos=[[0, 0, 1, 1, 0]])
    assert ab[-1] < min(ab[2], ab[3])  # alpha + beta is far better known than each


def test_refine_many_equals_refine(locust):
    cams = locust_cameras()
    fitter = Fitter(locust, cams)
    rng = np.random.default_rng(4)
    truth = smooth_random_motion(locust, 6, 6, seed=4)
    dets = [detections(locust, cams, a, rng) for a in truth]
    start = truth + np.where(locust.locked_mask(), 0.0, 0.5)
    start[2] = np.nan  # a frame without a fit stays as it is
    many = refine_many(fitter, start, dets)
    for k, (a, d) in enumerate(zip(start, dets, strict=True)):
        if k == 2:
            assert np.isnan(many[k].angles_deg).all() and many[k].n_pairs == 0
            continue
        one = refine(fitter, a, d)
        np.testing.assert_array_equal(many[k].angles_deg, one.angles_deg)
        assert (many[k].sse, many[k].n_pairs, many[k].error) == (one.sse, one.n_pairs,
                                                                 one.error)
    with pytest.raises(KinematicsError, match="angles need shape"):
        refine_many(fitter, start[:3], dets)


def one_image_off(body, cams, angles, rng):
    """Detections where refinement and Eq. 5 disagree: the tibia tip's image in the side view
    is 10 px off. Least squares spreads that error over every marker (lower sum of squares),
    which raises the sum of distances E in most frames."""
    det = detections(body, cams, angles, rng, noise=0.05)
    det[0] = det[0].copy()
    det[0][3] += (8.0, 6.0)
    return det


def test_refinement_never_returns_a_worse_error(locust):
    cams = locust_cameras()
    fitter = Fitter(locust, cams)
    rng = np.random.default_rng(11)
    truth = smooth_random_motion(locust, 12, 2, seed=11)
    kept_start = 0
    for a in truth:
        det = one_image_off(locust, cams, a, rng)
        e0 = fitter.error(a, det)[0]
        r = refine(fitter, a, det, gate_px=20.0)
        assert r.error <= e0 + 1e-9
        kept_start += bool(np.allclose(r.angles_deg, a, atol=1e-9))
    assert kept_start >= len(truth) // 2  # the guard was needed in most frames
    dets = [one_image_off(locust, cams, a, rng) for a in truth]
    many = refine_many(fitter, truth, dets, gate_px=20.0)
    for m, a, d in zip(many, truth, dets, strict=True):
        assert m.error <= fitter.error(a, d)[0] + 1e-9


def test_fit_with_refinement_never_has_a_worse_error_than_without(locust):
    """Same seed, one run: the annealed posture is the same, and refinement keeps its result
    only where E did not grow."""
    cams = locust_cameras()
    rng = np.random.default_rng(12)
    truth = smooth_random_motion(locust, 16, 2, seed=12)
    dets = [one_image_off(locust, cams, a, rng) for a in truth]
    base = AnnealParams.paper(max_runs=1, seed=5).with_schedule(3000)
    plain = Fitter(locust, cams, base).fit(dets)
    refined = Fitter(locust, cams, replace(base, refine=True, refine_gate_px=20.0)).fit(dets)
    for p, r in zip(plain, refined, strict=True):
        assert r.error <= p.error + 1e-9


def test_kernel_equals_scipy_on_a_branched_body():
    """Each entry's Jacobian column is computed from its own subtree only (entry_spans):
    on a body whose legs hang off a trunk the kernel still solves the twin's problem."""
    body, cams = three_legs(), top_and_side()
    fitter = Fitter(body, cams)
    angles, frames = planted_postures(body, cams, 6, seed=4)
    free = ~body.locked_mask()
    rng = np.random.default_rng(1)
    for truth, det in zip(angles, frames, strict=True):
        start = truth + np.where(free, rng.normal(0, 1.0, truth.size), 0.0)
        got = refine(fitter, start, det, steps=30, gate_px=20.0)
        want = refine_reference(fitter, start, det, gate_px=20.0)
        assert got.n_pairs == want.n_pairs == 2 * len(body.marker_names)
        np.testing.assert_allclose(got.angles_deg, want.angles_deg, atol=2e-4)
        assert got.sse == pytest.approx(want.sse, rel=1e-6, abs=1e-9)


def test_entry_spans_are_subtrees_or_the_whole_body():
    """A free entry moves its joint's subtree (joints and markers contiguous in depth-first
    order); where the order breaks that, the whole body (never too little)."""
    from kinematics._kernels.refine import entry_spans
    from kinematics.fit.problem import FitProblem

    body = three_legs()
    pr = FitProblem.build(body, top_and_side())
    f = pr.folded
    spans = entry_spans(pr.free_idx, f.parent, f.elem_axis, f.elem_index, f.slide_index,
                        f.marker_joint)
    names = body.joint_names
    marks = body.marker_names
    got = {}
    for j0, j1, m0, m1 in spans:
        got.setdefault(names[j0], set()).add(
            (tuple(names[j0:j1]), tuple(marks[m0:m1])))
    assert got["body"] == {(tuple(names), tuple(marks))}  # the trunk reaches everything
    assert got["a_hip"] == {(("a_hip", "a_knee"), ("a_knee_mk", "a_tip"))}
    assert got["b_knee"] == {(("b_knee",), ("b_tip",))}
    # a joint listed before its parent: every entry gets the whole body
    parent = f.parent.copy()
    order = np.arange(len(parent))
    order[[1, 2]] = [2, 1]  # swap two joints' places
    swapped = np.argsort(order)
    parent = np.array([swapped[parent[k]] if parent[k] >= 0 else -1 for k in order])
    spans = entry_spans(pr.free_idx, parent, f.elem_axis[order], f.elem_index[order],
                        f.slide_index[order], swapped[f.marker_joint])
    assert (spans == [0, len(parent), 0, len(marks)]).all()
