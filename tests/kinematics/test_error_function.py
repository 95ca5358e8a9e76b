"""Eq. 5 and its variants: hand-computed values, numba kernels == NumPy twin."""

import numpy as np
import pytest

from kinematics._kernels import codes as _codes
from kinematics._kernels import error2d as _error2d
from kinematics.cameras import OrthographicCamera, PinholeCamera
from kinematics.errors import KinematicsError
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.error_function import (
    NAN_MARKER_COST,
    ErrorOptions,
    nearest_residuals,
    posture_error,
    projection_error,
)
from kinematics.fit.problem import fold_body
from kinematics.model import Axis, Body, Chain, Joint, Marker, Segment
from kinematics.model.fk import forward_kinematics_reference
from tests.fixtures.settings import ERROR_VARIANT_IDS, ERROR_VARIANTS
from videotrack.synth.paper_setup import locust_cameras


def kernel_error(proj, detections, opts: ErrorOptions):
    counts = [len(d) for d in detections]
    off = np.zeros(len(detections) + 1, np.int64)
    np.cumsum(counts, out=off[1:])
    pts = np.concatenate([np.reshape(d, (-1, 2)) for d in detections]).astype(float)
    per_view = np.empty(len(detections))
    nearest = np.empty(proj.shape[1], np.int64)
    e = _error2d.projection_error(np.ascontiguousarray(proj), pts, off, _codes.NO_HIDDEN,
                            opts.bidirectional,
                            float(opts.penalty_weight), opts.cap, opts.penalty_cap,
                            opts.one_to_one, per_view, nearest)
    fast = _error2d.paper_error(np.ascontiguousarray(proj), pts, off, opts.cap)
    return e, per_view, fast


def test_eq5_by_hand():
    # One view, markers at (0, 0) and (10, 0); detections at (3, 4), (10, 1), (50, 50).
    proj = np.array([[[0.0, 0.0], [10.0, 0.0]]])
    det = [np.array([[3.0, 4.0], [10.0, 1.0], [50.0, 50.0]])]
    e, per_view = projection_error(proj, det)
    assert e == pytest.approx(5.0 + 1.0)
    np.testing.assert_allclose(per_view, [6.0])
    # Cap: the first marker costs min(5, 2) = 2.
    assert projection_error(proj, det, ErrorOptions(cap_px=2.0))[0] == pytest.approx(3.0)
    # Bidirectional: (50, 50) is nobody's nearest; its nearest marker is (10, 0).
    ghost = np.hypot(40.0, 50.0)
    e, _ = projection_error(proj, det, ErrorOptions("bidirectional", penalty_weight=0.5))
    assert e == pytest.approx(6.0 + 0.5 * ghost)
    e, _ = projection_error(proj, det, ErrorOptions("bidirectional", cap_px=10.0))
    assert e == pytest.approx(6.0 + 10.0)


def test_two_views_sum_and_empty_view_contributes_nothing():
    proj = np.array([[[0.0, 0.0]], [[1.0, 1.0]]])
    e, per_view = projection_error(proj, [np.array([[0.0, 2.0]]), np.empty((0, 2))])
    assert e == pytest.approx(2.0)
    np.testing.assert_allclose(per_view, [2.0, 0.0])


@pytest.mark.parametrize("opts", ERROR_VARIANTS, ids=ERROR_VARIANT_IDS)
def test_kernel_equals_twin_random(opts):
    rng = np.random.default_rng(7)
    for _ in range(300):
        nv, nm = rng.integers(1, 4), rng.integers(1, 7)
        proj = rng.uniform(0, 50, (nv, nm, 2))
        if rng.random() < 0.2:  # a marker behind a pinhole camera
            proj[rng.integers(nv), rng.integers(nm)] = np.nan
        dets = [rng.uniform(0, 50, (rng.integers(0, 9), 2)) for _ in range(nv)]
        want, want_views = projection_error(proj, dets, opts)
        got, got_views, fast = kernel_error(proj, dets, opts)
        assert got == pytest.approx(want, rel=1e-12, abs=1e-9)
        np.testing.assert_allclose(got_views, want_views, rtol=1e-12, atol=1e-9)
        if not (opts.bidirectional or opts.one_to_one):  # the loop's fast path: the same sum
            assert fast == pytest.approx(want, rel=1e-12, abs=1e-9)


def test_nan_projection_costs_cap_or_constant():
    proj = np.array([[[np.nan, np.nan], [0.0, 0.0]]])
    det = [np.array([[0.0, 1.0]])]
    assert projection_error(proj, det)[0] == pytest.approx(NAN_MARKER_COST + 1.0)
    assert projection_error(proj, det, ErrorOptions(cap_px=5.0))[0] == pytest.approx(6.0)
    assert kernel_error(proj, det, ErrorOptions(cap_px=5.0))[0] == pytest.approx(6.0)


@pytest.mark.parametrize("kwargs, field", [
    ({"mode": "both"}, "error.mode"),
    ({"penalty_weight": -1.0}, "error.penalty_weight"),
    ({"cap_px": 0.0}, "error.cap_px"),
    ({"cap_px": float("inf")}, "error.cap_px"),
])
def test_error_options_reject(kwargs, field):
    with pytest.raises(KinematicsError) as err:
        ErrorOptions(**kwargs)
    assert err.value.field == field


def odd_body() -> Body:
    """Exercises every folding case: free y and z around a locked x, non-identity R^s and
    R^d, a joint translation, a locked prefix (hinge about z after locked y, x at non-zero
    values), a locked suffix, two chains, markers off the segment axis."""
    tip = Segment("tip", 5.0, (0.0, 20.0, 0.0), markers=(Marker("m4", (1.0, 2.0, -1.0)),))
    j2 = Joint("j2", (Axis.fixed("ry", "y", 15.0), Axis.fixed("rx", "x", -25.0),
                      Axis.free("g", "z", 0, 90)), (10.0, 0.0, 30.0), (0.5, 0.0, 0.0), (tip,))
    mid = Segment("mid", 8.0, (5.0, -10.0, 30.0), markers=(Marker("m2", (0.0, 1.0, 0.0)),),
                  joints=(j2,))
    j1 = Joint("j1", (Axis.free("a", "y", -60, 60), Axis.fixed("rx", "x", 10.0),
                      Axis.free("c", "z", -45, 45)), (0.0, 30.0, 0.0), (0.0, 1.0, 0.0), (mid,))
    base = Segment("base", 10.0, markers=(Marker("m0", (-10.0, 0.0, 0.0)), Marker("m1")),
                   joints=(j1,))
    j0 = Joint("j0", (Axis.free("p", "y", 120, 220), Axis.free("q", "x", -40, 40),
                      Axis.fixed("rz", "z", 12.0)), (0.0, 0.0, 5.0), segments=(base,))
    other = Joint("k0", (Axis.fixed("ry", "y"), Axis.free("r", "x", -30, 30),
                         Axis.fixed("rz", "z", -20.0)),
                  segments=(Segment("s", 4.0, markers=(Marker("n0", (0.0, 0.0, 1.0)),)),))
    return Body("odd", (Chain("a", j0), Chain("b", other)))


def pinhole_and_ortho():
    ortho = OrthographicCamera.from_axes("top", 3.0, ("x", "z"), (300.0, 200.0))
    pin = PinholeCamera("cam", [[800.0, 0, 320.0], [0, 800.0, 240.0], [0, 0, 1]],
                        [0.05, -0.01, 0.001, 0.0005, 0.0], rvec=[0.1, -0.2, 0.05],
                        t=[-2.0, 1.0, 120.0])
    return {"top": ortho, "cam": pin}


@pytest.mark.parametrize("which", ["locust", "stick", "odd"])
def test_folded_kinematics_equal_reference(which, locust, stick_insect):
    body = {"locust": locust, "stick": stick_insect, "odd": odd_body()}[which]
    cams = locust_cameras() if which == "locust" else pinhole_and_ortho()
    fitter = Fitter(body, cams)
    rng = np.random.default_rng(1)
    lo, hi = body.ranges_deg().T
    roots = body.root_positions() + rng.normal(0, 2, body.root_positions().shape)
    for _ in range(40):
        angles = rng.uniform(lo, hi)
        markers = forward_kinematics_reference(body, angles, roots).markers
        want = np.stack([c.project(markers) for c in cams.values()])
        np.testing.assert_allclose(fitter.project(angles, roots), want, rtol=1e-12, atol=1e-9)


def test_fold_keeps_locked_rotations_out_of_the_loop(locust):
    folded = fold_body(locust)
    # Hinges J1 and J2 rotate about z only; J0 about y, x and z (world axes 1, 0, 2).
    np.testing.assert_array_equal(folded.elem_axis, [[1, 0, 2], [2, -1, -1], [2, -1, -1]])
    np.testing.assert_array_equal(folded.elem_index[:, 0], [0, 5, 8])
    # J2's default orientation (180 deg about z) is folded into the tibia marker.
    assert folded.joint_flags[2] & _codes.G_IDENTITY


@pytest.mark.parametrize("opts", ERROR_VARIANTS, ids=ERROR_VARIANT_IDS)
@pytest.mark.parametrize("which", ["stick", "odd"])
def test_posture_error_kernel_equals_twin(which, opts, stick_insect):
    body = stick_insect if which == "stick" else odd_body()
    cams = pinhole_and_ortho()
    fitter = Fitter(body, cams, AnnealParams.paper(error=opts))
    rng = np.random.default_rng(2)
    lo, hi = body.ranges_deg().T
    for _ in range(30):
        angles = rng.uniform(lo, hi)
        markers = forward_kinematics_reference(body, angles).markers
        dets = []
        for cam in cams.values():
            p = cam.project(markers) + rng.normal(0, 1.0, (len(markers), 2))
            keep = rng.random(len(p)) > 0.2  # occlusions
            ghosts = rng.uniform(0, 600, (rng.integers(0, 3), 2))
            dets.append(np.concatenate([p[keep], ghosts]))
        want, want_views = posture_error(body, cams, angles, dets, options=opts)
        got, got_views = fitter.error(angles, dets)
        assert got == pytest.approx(want, rel=1e-10, abs=1e-8)
        np.testing.assert_allclose(got_views, want_views, rtol=1e-10, atol=1e-8)


def test_bounded_bidirectional_caps_each_ghost():
    """A ghost far from the model costs its whole distance in 'bidirectional' (no cap) but
    at most penalty_weight * penalty_cap_px in 'bounded'."""
    proj = np.array([[[0.0, 0.0], [10.0, 0.0]]])
    dets = [np.array([[0.0, 0.0], [10.0, 0.0], [500.0, 0.0]])]
    e_paper = projection_error(proj, dets, ErrorOptions())[0]
    e_bidir = projection_error(proj, dets, ErrorOptions("bidirectional"))[0]
    e_bounded = projection_error(proj, dets, ErrorOptions("bounded", penalty_weight=2.0,
                                                          penalty_cap_px=3.0))[0]
    assert e_paper == 0.0
    assert e_bidir == pytest.approx(490.0)
    assert e_bounded == pytest.approx(6.0)
    got = kernel_error(proj, dets, ErrorOptions("bounded", penalty_weight=2.0,
                                                penalty_cap_px=3.0))[0]
    assert got == pytest.approx(6.0)


def test_bad_penalty_cap_is_named():
    with pytest.raises(KinematicsError, match="penalty_cap_px"):
        ErrorOptions("bounded", penalty_cap_px=0.0)


@pytest.mark.parametrize("seed", range(6))
def test_nearest_residuals_kernel_equals_twin(seed):
    """Residuals and unexplained detections: views without detections, markers not seen,
    a view that sees no marker, and a marker behind a pinhole camera (NaN)."""
    rng = np.random.default_rng(seed)
    nv, nm = 3, 5
    proj = rng.uniform(0, 50, (nv, nm, 2))
    proj[1, 2] = np.nan
    counts = rng.integers(0, 7, nv)
    counts[seed % nv] = 0
    view_off = np.r_[0, np.cumsum(counts)].astype(np.int64)
    points = rng.uniform(0, 50, (int(view_off[-1]), 2))
    seen = rng.uniform(size=(nv, nm)) < 0.7
    seen[2] = seed % 2 == 0
    out = np.full((nv, nm), np.nan)
    n = _error2d.nearest_residuals(proj, points, view_off, seen, 8.0, out)
    twin, n_twin = nearest_residuals(proj, points, view_off, seen, 8.0)
    np.testing.assert_array_equal(out, twin)
    assert n == n_twin
