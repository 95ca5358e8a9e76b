"""Labelled observations: 2D keypoints and 3D points, their objectives against the NumPy
twins, and fitting a freely moving body to them."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics._kernels import error2d as _error2d
from kinematics._kernels import error3d as _error3d
from kinematics.errors import KinematicsError
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.error_function import labelled_error, points3d_error
from kinematics.fit.settings import ErrorOptions
from kinematics.model.fk import forward_kinematics_reference
from kinematics.observe.observations import Observations
from tests.fixtures.bodies import mouse_like
from tests.fixtures.cameras import three_pinholes
from tests.fixtures.planted import joint_errors, planted_frames

CAPS = [ErrorOptions(), ErrorOptions(cap_px=2.0)]


@pytest.mark.parametrize("opts", CAPS, ids=["no-cap", "cap"])
def test_labelled_error_kernel_equals_twin(opts):
    rng = np.random.default_rng(4)
    nv, nm = 3, 5
    proj = rng.uniform(0, 100, (nv, nm, 2))
    kp = np.concatenate([proj + rng.normal(0, 2, proj.shape), rng.uniform(0, 1, (nv, nm, 1))],
                        axis=2)
    kp[0, 1, :2] = np.nan
    kp[2, 3, 2] = 0.0
    want, want_view = labelled_error(proj, kp, opts)
    pts = np.ascontiguousarray(kp[..., :2].reshape(-1, 2))
    conf = np.ascontiguousarray(kp[..., 2].ravel())
    off = np.arange(nv + 1, dtype=np.int64) * nm
    per_view = np.empty(nv)
    got = _error2d.labelled_error(proj, pts, conf, off, opts.cap, per_view)
    assert got == pytest.approx(want, rel=1e-12)
    np.testing.assert_allclose(per_view, want_view, rtol=1e-12)


@pytest.mark.parametrize("opts", CAPS, ids=["no-cap", "cap"])
def test_points3d_error_kernel_equals_twin(opts):
    rng = np.random.default_rng(5)
    mk = rng.normal(0, 10, (6, 3))
    pts = np.concatenate([mk + rng.normal(0, 1, mk.shape), rng.uniform(0.2, 1, (6, 1))], 1)
    pts[2, :3] = np.nan
    pts[4, 3] = 0.0
    assert _error3d.points3d_error(mk, pts, opts.cap) == pytest.approx(
        points3d_error(mk, pts, opts), rel=1e-12)


def test_keypoints_packing_and_errors():
    body = mouse_like()
    names = body.marker_names
    kp = np.random.default_rng(0).uniform(0, 100, (4, 2, 3, 3))
    kp[1, 0] = np.nan  # view 0 of frame 1 sees nothing: it holds no rows
    obs = Observations.keypoints(kp, ["a", "b"], [names[2], names[0], names[5]], names)
    counts = obs.view_counts(np.arange(4))
    assert counts.tolist() == [[6, 6], [0, 6], [6, 6], [6, 6]]
    pts, conf, _, _ = obs.select(np.array([2]))
    rows = pts.reshape(2, 6, 2)
    np.testing.assert_array_equal(rows[1, 2], kp[2, 1, 0, :2])  # marker 2 is keypoint 0
    assert np.isnan(rows[0, 1]).all() and conf.reshape(2, 6)[0, 1] == 0.0
    with pytest.raises(KinematicsError, match="not a marker"):
        Observations.keypoints(kp, ["a", "b"], ["nose", names[0], names[1]], names)
    with pytest.raises(KinematicsError, match="shape"):
        Observations.keypoints(kp[..., :1], ["a", "b"], names[:3], names)
    bad = kp.copy()
    bad[0, 0, 0, 2] = -1.0
    with pytest.raises(KinematicsError, match="confidences"):
        Observations.keypoints(bad, ["a", "b"], names[:3], names)
    p3 = np.ones((2, 3, 4))
    p3[1, 2, 3] = -0.5
    with pytest.raises(KinematicsError, match="weights"):
        Observations.points_3d(p3, names[:3], names)


def test_one_frame_of_a_block_is_that_frame_selected_alone():
    body = mouse_like()
    names = body.marker_names
    kp = np.random.default_rng(1).uniform(0, 100, (5, 2, 3, 3))
    kp[1, 0] = np.nan  # a view without rows
    keypoints = Observations.keypoints(kp, ["a", "b"], [names[2], names[0], names[5]], names)
    p3 = np.random.default_rng(2).uniform(0, 10, (5, 3, 4))
    points3d = Observations.points_3d(p3, names[:3], names)
    for obs in (keypoints, points3d):
        sel = np.array([4, 1, 2, 1])
        block = obs.arrays(sel)
        for k, frame in enumerate(sel):
            alone, one = obs.arrays(np.array([frame])), block.frame(k, obs.n_views)
            assert one.objective == alone.objective
            for a, b in zip(alone[1:], one[1:], strict=True):
                np.testing.assert_array_equal(a, b)


def test_free_body_from_labelled_keypoints():
    body = mouse_like()
    cams = three_pinholes()
    angles, roots, frames = planted_frames(body, cams, n=8, noise=0.5)
    kp = np.array(frames)  # (n, views, markers, 2), in body-marker order
    rng = np.random.default_rng(6)
    kp[rng.uniform(size=kp.shape[:3]) < 0.05] = np.nan
    obs = Observations.keypoints(kp, [c.name for c in cams], body.marker_names,
                                 body.marker_names)
    params = AnnealParams.paper(refine=True, reanalysis_threshold=30.0).with_schedule(5000)
    res = Fitter(body, cams, params).fit(obs)
    err = joint_errors(body, res, angles, roots, "joints")
    assert np.median(err) < 0.3, err
    assert res[0].marker_residuals.shape == (3, len(body.marker_names))


def test_free_body_from_3d_points_without_cameras():
    body = mouse_like()
    angles, roots, _ = planted_frames(body, three_pinholes(), n=8)
    rng = np.random.default_rng(7)
    pts = np.array([forward_kinematics_reference(body, a, r).markers
                    for a, r in zip(angles, roots, strict=True)])
    pts += rng.normal(0, 0.1, pts.shape)
    pts[3, 1] = np.nan
    obs = Observations.points_3d(pts, body.marker_names, body.marker_names)
    params = AnnealParams.paper(refine=True, tau0=5.0, reanalysis_threshold=3.0,
                          refine_gate_px=5.0).with_schedule(5000)
    res = Fitter(body, {}, params).fit(obs)
    err = joint_errors(body, res, angles, roots, "joints")
    assert np.median(err) < 0.3, err
    assert all(r.status in ("ok", "reanalysed") for r in res)


def test_fitter_error_of_one_record_is_its_objective():
    body = mouse_like()
    cams = three_pinholes()
    names = body.marker_names
    angles, roots, _ = planted_frames(body, cams, n=1, seed=2)
    fitter = Fitter(body, cams, AnnealParams(error=ErrorOptions(cap_px=30.0)))
    markers = forward_kinematics_reference(body, angles[0], roots[0]).markers
    proj = np.stack([c.project(markers) for c in cams])
    kp = np.concatenate([proj + 1.5, np.full((*proj.shape[:2], 1), 0.8)], axis=2)
    obs = Observations.keypoints(kp[None], [c.name for c in cams], names, names)
    error, per_view = fitter.error(angles[0], obs, roots[0])
    want, want_view = labelled_error(proj, kp, fitter.params.error)
    assert error == pytest.approx(want, rel=1e-9) and error > 0
    np.testing.assert_allclose(per_view, want_view, rtol=1e-9)
    pts = np.concatenate([markers + 0.5, np.ones((len(names), 1))], axis=1)
    e3, _ = fitter.error(angles[0], Observations.points_3d(pts[None], names, names), roots[0])
    assert e3 == pytest.approx(points3d_error(markers, pts, fitter.params.error), rel=1e-9)
