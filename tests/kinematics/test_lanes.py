"""The lane backend (many annealing runs in SIMD lanes) against the scalar kernel: the same
results to the last bit, whatever the lane and thread counts."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numba
import numpy as np
import pytest

from kinematics._kernels import codes as _codes
from kinematics._kernels import fastmath as _fastmath
from kinematics._kernels import lane_iterations as _li
from kinematics._kernels import lanes as _lk
from kinematics.errors import KinematicsError
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.partitions import partitions_of
from kinematics.fit.problem import FitOutputs, error_args, schedule_of
from kinematics.fit.settings import ErrorOptions
from kinematics.model.fk import forward_kinematics, forward_kinematics_reference
from kinematics.observe.observations import Observations
from tests.fixtures.assertions import assert_same
from tests.fixtures.bodies import mouse_like
from tests.fixtures.cameras import three_pinholes
from tests.fixtures.planted import labelled_keypoints, planted_detections, planted_frames
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import locust_cameras


def fit_both(body, cams, detections, params):
    """Results of the scalar and the lane backend for the same frames."""
    out = []
    for backend in ("scalar", "lanes"):
        out.append(Fitter(body, cams, replace(params, backend=backend)).fit(detections))
    return out


def _sincos_twin(x: float) -> tuple[float, float]:
    """The kernels' sine/cosine written with branches, in Python floats (IEEE doubles)."""
    fm = _fastmath
    k = float(np.rint(x * fm._TWO_OVER_PI))
    r = (x - k * fm._PIO2_HI) - k * fm._PIO2_LO
    z = r * r
    s = r + r * z * (fm._S1 + z * (fm._S2 + z * (fm._S3 + z * (fm._S4 + z * (
        fm._S5 + z * fm._S6)))))
    c = 1.0 - 0.5 * z + z * z * (fm._C1 + z * (fm._C2 + z * (fm._C3 + z * (fm._C4 + z * (
        fm._C5 + z * fm._C6)))))
    return [(s, c), (c, -s), (-s, -c), (-c, s)][int(k) & 3]


def test_branch_free_sincos_is_the_branching_one_to_the_bit():
    x = np.concatenate([np.linspace(-20, 20, 4001), np.random.default_rng(0).normal(0, 50,
                                                                                    2000)])
    s, c = np.empty_like(x), np.empty_like(x)
    _li.sincos_lanes(x, s, c)
    ref = np.array([_sincos_twin(float(v)) for v in x])
    np.testing.assert_array_equal(s, ref[:, 0])
    np.testing.assert_array_equal(c, ref[:, 1])


def test_float32_sincos_is_within_two_float32_ulp():
    x = np.random.default_rng(1).uniform(-1000.0, 1000.0, 20000)
    got = np.array([_fastmath.sincos32(v) for v in x], dtype=float)
    xf = x.astype(np.float32).astype(float)  # the kernel's input, rounded to float32
    for k, true in enumerate((np.sin(xf), np.cos(xf))):
        ulp = np.spacing(np.abs(true).astype(np.float32)).astype(float)
        assert np.all(np.abs(got[:, k] - true) <= 2.0 * ulp)


def test_paper_profile_identical(locust):
    truth = smooth_random_motion(locust, 20, 1, seed=4)
    dets = planted_detections(locust, locust_cameras(), truth, ghosts=1)
    scalar, lanes = fit_both(locust, locust_cameras(), dets,
                             AnnealParams.paper().with_schedule(3000))
    assert_same(scalar, lanes)
    assert max(r.runs for r in lanes) > 1  # re-analysis happened, and matched


def test_defaults_identical_with_ghosts_and_an_empty_frame(locust):
    truth = smooth_random_motion(locust, 24, 1, seed=5)
    dets = planted_detections(locust, locust_cameras(), truth, ghosts=2)
    dets[7] = [np.zeros((0, 2)), np.zeros((0, 2))]  # nothing detected
    dets[9][1] = np.zeros((0, 2))  # one view empty
    params = AnnealParams().with_schedule(2000)
    scalar, lanes = fit_both(locust, locust_cameras(), dets, params)
    assert_same(scalar, lanes)
    assert lanes[7].status == "no-detections" and lanes[7].runs == 0
    assert any(len(r.candidates) > 1 for r in lanes)


def test_free_root_and_distorted_pinholes_identical():
    body = mouse_like(translation_window=4.0, rotation_window_deg=30.0)
    cams = three_pinholes()
    _, _, frames = planted_frames(body, cams, n=10, seed=7)
    # per view: its markers all triangulate, so 'auto' would match them in 3D (no lanes)
    params = AnnealParams(max_unexplained=0, match="views").with_schedule(1500)
    scalar, lanes = fit_both(body, cams, frames, params)
    assert_same(scalar, lanes)


def _projected(body, cams, angles, noise):
    """Per frame, per view: the markers of ``angles`` projected, with Gaussian noise."""
    return [[c.project(forward_kinematics(body, a).markers)
             + np.random.default_rng(k).normal(0, noise, (len(body.marker_names), 2))
             for c in cams.values()] for k, a in enumerate(angles)]


@pytest.mark.parametrize("params", [
    AnnealParams().with_schedule(1500),  # the defaults: candidates and the path
    AnnealParams.paper(error=ErrorOptions(cap_px=20.0)).with_schedule(1500),  # re-analysis
], ids=["defaults", "paper-capped"])
def test_labelled_keypoints_identical(locust, params):
    cams = locust_cameras()
    truth = smooth_random_motion(locust, 16, 1, seed=8)
    obs = labelled_keypoints(locust, cams, _projected(locust, cams, truth, 0.5), seed=9)
    scalar, lanes = fit_both(locust, cams, obs, params)
    assert_same(scalar, lanes)
    assert lanes[4].status == "no-detections"
    off = np.abs(np.array([r.angles_deg for r in lanes])[5:] - truth[5:])
    assert np.median(off) < 2  # fitted, not only equal


@pytest.mark.parametrize("loops", ["generated", "general", "float32 asked"])
def test_labelled_keypoints_free_root_pinholes_identical(loops, monkeypatch):
    # the kernel generated for the body (in float64 also where float32 is asked for:
    # labelled keypoints have no float32 kernel), or the general loops (labelled_lanes)
    if loops == "general":
        monkeypatch.setenv("VIDEOTRACK_NO_CODEGEN", "1")
    body = mouse_like(translation_window=4.0, rotation_window_deg=30.0)
    cams = three_pinholes()
    _, _, frames = planted_frames(body, cams, n=10, seed=11)
    obs = labelled_keypoints(body, {c.name: c for c in cams}, frames, seed=12)
    params = AnnealParams(precision="float32" if loops == "float32 asked" else "float64")
    fitter = Fitter(body, cams, params)
    fused, _ = fitter._fused_kernel(fitter.observations(obs).arrays(np.arange(10)),
                                    error_args(params.error))
    assert (fused is _lk.no_fused) == (loops == "general")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no kernel given up on (a float32 one asked for)
        scalar, lanes = fit_both(body, cams, obs, params.with_schedule(1500))
    assert_same(scalar, lanes)


_DEFAULTS_3D = AnnealParams(tau0=5.0).with_schedule(1500)  # candidates and the path
_REFINED_3D = AnnealParams.paper(refine=True, tau0=5.0, reanalysis_threshold=1.0,
                                 error=ErrorOptions(cap_px=3.0)).with_schedule(1500)


@pytest.mark.parametrize(("params", "loops"), [
    (_DEFAULTS_3D, "generated"), (_REFINED_3D, "generated"), (_DEFAULTS_3D, "general"),
], ids=["defaults", "paper-refined (re-analysis)", "defaults, general loops"])
def test_3d_points_identical(params, loops, monkeypatch):
    # labelled 3D points (triangulated keypoints, an Anipose CSV): no cameras, a free root
    if loops == "general":
        monkeypatch.setenv("VIDEOTRACK_NO_CODEGEN", "1")
    body = mouse_like(translation_window=4.0, rotation_window_deg=30.0)
    angles, roots, _ = planted_frames(body, three_pinholes(), n=14, seed=13)
    rng = np.random.default_rng(14)
    pts = np.array([forward_kinematics_reference(body, a, r).markers
                    for a, r in zip(angles, roots, strict=True)])
    pts = np.concatenate([pts + rng.normal(0, 0.1, pts.shape),
                          rng.uniform(0.3, 1.0, (*pts.shape[:2], 1))], axis=2)
    pts[3, 1, 0] = np.nan  # a point not found
    pts[5, 2, 3] = 0.0  # a point of weight 0
    pts[6, :, :3] = np.nan  # nothing in the frame
    obs = Observations.points_3d(pts, body.marker_names, body.marker_names)
    fitter = Fitter(body, {}, params)
    fused, _ = fitter._fused_kernel(fitter.observations(obs).arrays(np.arange(14)),
                                    error_args(params.error))
    assert (fused is _lk.no_fused) == (loops == "general")
    scalar, lanes = fit_both(body, {}, obs, params)
    assert_same(scalar, lanes)
    assert lanes[6].status == "no-detections" and lanes[6].runs == 0
    assert max(r.runs for r in lanes) > 1


def _kernel_outputs(fitter, dets, n_lanes, groups, generated=True, single=False):
    p = fitter.params
    pr = fitter.problem
    obs = fitter.observations(dets)
    idx = np.arange(obs.n_frames)
    roots, rots = fitter._place(obs, idx)
    out = FitOutputs.empty(len(idx), pr.n_state, fitter.n_views, max(p.max_runs, p.candidates))
    arrays, error = obs.arrays(idx), error_args(p.error)
    fused, n_fused = fitter._fused_kernel(arrays, error, single) if generated else \
        (_lk.no_fused, 0)
    _lk.fit_frames_lanes(np.asarray(groups, np.int64), idx, roots, rots, pr.start, pr.folded,
                         pr.cams, pr.dofs, schedule_of(p), error, arrays,
                         float(p.claim_gate_px), fused, (n_lanes, n_fused, single), out)
    return out


def test_general_loops_equal_the_generated_kernel(locust):
    truth = smooth_random_motion(locust, 12, 1, seed=6)
    dets = planted_detections(locust, locust_cameras(), truth, ghosts=1)
    fitter = Fitter(locust, locust_cameras(), AnnealParams().with_schedule(800))
    fused, n_fused = fitter._fused_kernel(fitter.observations(dets).arrays(np.arange(12)),
                                          error_args(fitter.params.error))
    assert fused is not _lk.no_fused and n_fused == 5  # 4 markers per view + 1 ghost
    generated = _kernel_outputs(fitter, dets, 16, [0, 12], True)
    general = _kernel_outputs(fitter, dets, 16, [0, 12], False)
    for name in generated._fields:
        np.testing.assert_array_equal(getattr(generated, name), getattr(general, name))


@pytest.mark.parametrize(("generated", "single"), [(True, False), (False, False), (True, True)])
def test_same_results_for_any_lane_and_thread_count(locust, generated, single):
    truth = smooth_random_motion(locust, 12, 1, seed=6)
    dets = planted_detections(locust, locust_cameras(), truth, ghosts=1)
    _same_for_any_lane_and_thread_count(locust, dets, generated, single)


@pytest.mark.parametrize("generated", [True, False])
def test_labelled_same_results_for_any_lane_and_thread_count(locust, generated):
    # lanes that shrink and reorder (3 and 8 lanes) carry their keypoints' weights along
    cams = locust_cameras()
    truth = smooth_random_motion(locust, 12, 1, seed=10)
    kp = labelled_keypoints(locust, cams, _projected(locust, cams, truth, 2.0), seed=13)
    _same_for_any_lane_and_thread_count(locust, kp, generated, False)


def _same_for_any_lane_and_thread_count(locust, dets, generated, single):
    n = dets.n_frames if isinstance(dets, Observations) else len(dets)  # frames 0 .. n
    fitter = Fitter(locust, locust_cameras(), AnnealParams(threshold_mode="absolute",
                                                           reanalysis_threshold=2.0
                                                           ).with_schedule(1000))
    ref = _kernel_outputs(fitter, dets, 32, [0, n], generated, single)
    before = numba.get_num_threads()
    try:
        for n_lanes, groups, threads in ((8, [0, 5, n], 2), (3, [0, 1, 2, n], 1),
                                         (64, [0, n], 1)):
            numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
            other = _kernel_outputs(fitter, dets, n_lanes, groups, generated, single)
            for name in ref._fields:
                np.testing.assert_array_equal(getattr(ref, name), getattr(other, name),
                                              err_msg=f"{name}, {n_lanes} lanes")
    finally:
        numba.set_num_threads(before)
    assert ref.runs.max() > 2  # some frames were re-analysed


def test_float32_fits_as_well_as_float64(locust):
    """precision 'float32': E within float32 rounding, so the fits end where float64's do
    (or as near the truth), though not always to the bit."""
    truth = smooth_random_motion(locust, 24, 1, seed=9)
    dets = planted_detections(locust, locust_cameras(), truth, ghosts=2)
    params = AnnealParams(backend="lanes").with_schedule(2000)
    res = {prec: Fitter(locust, locust_cameras(), replace(params, precision=prec)).fit(dets)
           for prec in ("float64", "float32")}
    err = {}
    for prec, rs in res.items():
        d = np.array([r.angles_deg for r in rs]) - truth
        err[prec] = np.sqrt(np.mean(((d + 180.0) % 360.0 - 180.0) ** 2))
    assert err["float64"] < 3.0 and err["float32"] < 1.2 * err["float64"] + 0.1, err
    ok = {prec: sum(r.status == "ok" for r in rs) for prec, rs in res.items()}
    assert ok["float32"] >= ok["float64"] - 1, ok
    locked = locust.locked_mask()
    for a, b in zip(res["float64"], res["float32"], strict=True):
        np.testing.assert_array_equal(a.angles_deg[locked], b.angles_deg[locked])


def test_locked_axes_untouched(locust):
    dets = planted_detections(locust, locust_cameras(), smooth_random_motion(locust, 4, 1, seed=1))
    res = Fitter(locust, locust_cameras(), AnnealParams(backend="lanes").with_schedule(500)
                 ).fit(dets)
    locked = locust.locked_mask()
    start = Fitter(locust, locust_cameras()).start_posture_deg
    for r in res:
        np.testing.assert_array_equal(r.angles_deg[locked], start[locked])


def test_auto_uses_lanes_only_where_valid(locust):
    f = Fitter(locust, locust_cameras(), AnnealParams())
    parts = partitions_of(f.problem)
    many = _lk.MIN_RUNS_PER_THREAD * numba.get_num_threads()  # runs, 2 per frame
    def backend(params, objective, n):
        return f._backend(params, objective, parts, n)

    assert backend(f.params, _codes.OBJ_NEAREST, many // 2) == "lanes"
    assert backend(f.params, _codes.OBJ_NEAREST, many // 2 - 1) == "scalar"
    assert backend(f.params, _codes.OBJ_NEAREST, 1) == "scalar"  # a single frame (GUI)
    assert backend(f.params, _codes.OBJ_LABELLED, many) == "lanes"  # labelled 2D keypoints
    assert backend(f.params, _codes.OBJ_POINTS3D, many) == "lanes"  # 3D points
    assert backend(f.params, _codes.OBJ_CLOUD, many) == "scalar"
    assert backend(replace(f.params, backend="scalar"), _codes.OBJ_NEAREST, many) == "scalar"
    for name in ("lanes", "cuda"):
        with pytest.raises(KinematicsError, match=f"the {name} backend") as err:
            backend(replace(f.params, backend=name, start="previous"), _codes.OBJ_NEAREST, many)
        assert err.value.field == "backend"


def test_bad_backend_is_named():
    with pytest.raises(KinematicsError) as err:
        AnnealParams(backend="gpu")
    assert err.value.field == "backend"
    with pytest.raises(KinematicsError) as err:
        AnnealParams(precision="float16")
    assert err.value.field == "precision"


def test_choice_over_time_does_not_depend_on_chunk_size(locust):
    # the lane backend fits bigger chunks than the scalar one; the path must not notice
    truth = smooth_random_motion(locust, 90, 1, seed=8)
    dets = planted_detections(locust, locust_cameras(), truth, ghosts=1)
    fitter = Fitter(locust, locust_cameras(), AnnealParams(backend="scalar").with_schedule(400))
    small = list(fitter.iter_fit(dets, chunk_size=8))
    large = list(fitter.iter_fit(dets, chunk_size=90))
    assert_same(small, large)


def test_the_last_runs_move_into_fewer_lanes():
    """Once no run waits and at most half the lanes are busy, the busy lanes are kept (with
    idle ones up to MIN_LANES); never while runs wait, never below MIN_LANES. The results of
    the backend tests above are bit-identical with this shrinking at work (e.g. the paper
    profile's 20 frames start in 64 lanes)."""
    active = np.zeros(64, np.bool_)
    active[[3, 17, 40]] = True
    assert _lk._kept_lanes(active, False).size == 0  # runs wait: keep every lane
    kept = _lk._kept_lanes(active, True)
    assert kept.tolist()[:3] == [3, 17, 40] and kept.size == _lk.MIN_LANES
    assert len(set(kept.tolist())) == kept.size
    active[:33] = True
    assert _lk._kept_lanes(active, True).size == 0  # more than half busy
    active[:] = False
    active[:20] = True
    assert _lk._kept_lanes(active, True).tolist() == list(range(20))
    assert _lk._kept_lanes(np.ones(_lk.MIN_LANES, np.bool_), True).size == 0
    a = np.arange(24.0).reshape(2, 3, 4)
    np.testing.assert_array_equal(_lk._take3(a, np.array([3, 1])), a[:, :, [3, 1]])
