"""One-to-one assignment (``[anneal] one_to_one``): each detection, or each triangulated
point, explains at most one model marker. Planted shared-blob cases by hand, the kernels
against the NumPy twin with partition claims, and a body fitted with it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinematics._kernels import codes as _codes
from kinematics._kernels import error3d as _error3d
from kinematics._kernels import objective as _objective
from kinematics.errors import KinematicsError
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.error_function import cloud_error, one_to_one, projection_error
from kinematics.fit.settings import ErrorOptions
from kinematics.model.fk import forward_kinematics_reference
from tests.fixtures.bodies import three_legs
from tests.fixtures.cameras import ring
from tests.fixtures.planted import planted_postures, random_cloud

ONE = ErrorOptions(one_to_one=True)


def kernel_view_error(proj, pts, opts, m0=0, m1=None, claimed=None):
    """partition_error of markers m0:m1 in one view (the annealing loop's objective)."""
    nm = proj.shape[1]
    m1 = nm if m1 is None else m1
    claimed = np.zeros(len(pts), np.bool_) if claimed is None else claimed
    return _objective.partition_error(_codes.OBJ_NEAREST, np.ascontiguousarray(proj),
                                      np.zeros((nm, 3)),
                              np.asarray(pts, float), np.ones(len(pts)),
                              np.array([0, len(pts)], np.int64), np.zeros((nm, 4)), opts.cap,
                              m0, m1, claimed, opts.penalty_weight if opts.bidirectional
                              else 0.0, opts.penalty_cap, opts.one_to_one,
                              np.empty(nm, np.int64))


def test_shared_blob_goes_to_the_closer_marker():
    # markers 0 and 1 both have blob 0 as their nearest; marker 1 is closer and keeps it,
    # marker 0 takes blob 1, the nearest that is no marker's nearest
    proj = np.array([[[0.0, 0.0], [1.0, 0.0], [20.0, 0.0]]])
    pts = np.array([[1.5, 0.0], [-4.0, 0.0], [20.0, 1.0]])
    nearest_only, _ = projection_error(proj, [pts])
    assert nearest_only == pytest.approx(1.5 + 0.5 + 1.0)
    e, per_view = projection_error(proj, [pts], ONE)
    assert e == pytest.approx(4.0 + 0.5 + 1.0) and per_view[0] == pytest.approx(e)
    assert kernel_view_error(proj, pts, ONE) == pytest.approx(e, rel=1e-12)
    point, dist = one_to_one(np.array([[1.5, 4.0, 20.0], [0.5, 5.0, 19.0]]))
    assert point.tolist() == [1, 0] and dist.tolist() == [4.0, 0.5]


def test_ties_go_to_the_lower_marker_and_none_left_costs_the_cap():
    proj = np.array([[[0.0, 0.0], [2.0, 0.0]]])
    pts = np.array([[1.0, 0.0]])  # one blob, equally near both markers
    opts = ErrorOptions(cap_px=6.0, one_to_one=True)
    e, _ = projection_error(proj, [pts], opts)
    assert e == pytest.approx(1.0 + 6.0)  # marker 1 has no blob left: the cap
    assert kernel_view_error(proj, pts, opts) == pytest.approx(e)
    point, _ = one_to_one(np.array([[1.0], [1.0]]))
    assert point.tolist() == [0, -1]


def test_fused_blob_left_over_pays_the_bounded_term_only_when_shared():
    # two legs' tips on one blob leave the other tip's blob unexplained: with the bounded
    # term that costs penalty_cap; one-to-one makes the second tip pay its real distance
    proj = np.array([[[10.0, 10.0], [10.5, 10.0]]])
    pts = np.array([[10.0, 10.0], [18.0, 10.0]])
    shared = ErrorOptions("bounded", cap_px=10.0)
    e_shared, _ = projection_error(proj, [pts], shared)
    assert e_shared == pytest.approx(0.5 + 3.0)
    own = ErrorOptions("bounded", cap_px=10.0, one_to_one=True)
    e_own, _ = projection_error(proj, [pts], own)
    assert e_own == pytest.approx(0.0 + 7.5)  # blob 1 is explained, by marker 1
    assert kernel_view_error(proj, pts, own) == pytest.approx(e_own)


@pytest.mark.parametrize("bounded", [False, True])
def test_kernel_equals_twin_with_claims(bounded):
    """partition_error with claimed detections and one-to-one equals the twin run on the
    markers of the partition and the unclaimed detections."""
    rng = np.random.default_rng(17)
    opts = ErrorOptions("bounded" if bounded else "paper", cap_px=8.0, one_to_one=True)
    for _ in range(200):
        nm, nd = rng.integers(2, 8), rng.integers(1, 10)
        proj = rng.uniform(0, 30, (1, nm, 2))
        pts = rng.uniform(0, 30, (nd, 2))
        claimed = rng.random(nd) < 0.3
        m0 = int(rng.integers(0, nm - 1))
        m1 = int(rng.integers(m0 + 1, nm + 1))
        got = kernel_view_error(proj, pts, opts, m0, m1, claimed)
        free = pts[~claimed]
        want = projection_error(proj[:, m0:m1], [free], opts)[0] if len(free) else \
            (m1 - m0) * opts.cap
        assert got == pytest.approx(want, rel=1e-12, abs=1e-9)


def test_cloud_kernel_equals_twin_with_claims():
    rng = np.random.default_rng(23)
    opts = ErrorOptions("bounded", cap_px=30.0, one_to_one=True)
    for _ in range(50):
        mk, cloud = random_cloud(rng, n_markers=7, n_points=6)
        claimed = rng.random(len(cloud)) < 0.25
        got = _error3d.cloud_error(mk, cloud, 1, 6, claimed, opts.penalty_weight, opts.cap,
                             opts.penalty_cap, True, np.empty(len(mk), np.int64))
        assert got == pytest.approx(cloud_error(mk[1:6], cloud, opts, claimed), rel=1e-12)


def test_the_fitter_scores_one_to_one():
    """The setting reaches the kernels through the fitter: at the start posture, where
    markers of different legs share their nearest points, the fitter's E is the twin's
    one-to-one E, per view and in 3D (the planted fit with it: test_cloud_objective.py)."""
    body = three_legs()
    cams = ring()
    _, frames = planted_postures(body, cams, 1, seed=5, shuffle=True)
    start = body.mean_posture_deg()
    markers = forward_kinematics_reference(body, start).markers
    nv = len(cams)
    for match in ("views", "3d"):
        plain = AnnealParams(match=match)
        one = replace(plain, error=replace(plain.error, one_to_one=True))
        fitter = Fitter(body, cams, one)
        e_one, _ = fitter.error(start, frames[0])
        e_plain, _ = Fitter(body, cams, plain).error(start, frames[0])
        if match == "views":
            proj = np.stack([c.project(markers) for c in cams.values()])
            want = projection_error(proj, frames[0], one.error)[0]
        else:  # in 3D a marker counts once: the caps are the views' together
            cloud = fitter.observations([frames[0]]).points3d[0]
            want = cloud_error(markers, cloud, replace(one.error, cap_px=10.0 * nv,
                                                       penalty_cap_px=3.0 * nv))
        assert e_one == pytest.approx(want, rel=1e-9), match
        assert e_one != pytest.approx(e_plain, rel=1e-6), match


def test_one_to_one_must_be_a_boolean():
    with pytest.raises(KinematicsError, match="one_to_one"):
        ErrorOptions(one_to_one="yes")
