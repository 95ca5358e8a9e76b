"""The CUDA backend: its frame procedure in rounds (with the GPU kernel's CPU twin) is the
scalar ``fit_frames`` to the last bit, the backend fits with the rounds alone, a machine
without a usable GPU gets a clear error, and on a GPU it fits as the scalar kernel does
(skipped without one)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinematics._kernels import cuda as _ck
from kinematics._kernels import frames as _frames
from kinematics._kernels import lanes as _lk
from kinematics.errors import KinematicsError
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.problem import FitOutputs, schedule_of
from kinematics.fit.settings import ErrorOptions
from tests.fixtures.assertions import assert_same
from tests.fixtures.bodies import mouse_like
from tests.fixtures.cameras import three_pinholes
from tests.fixtures.planted import labelled_keypoints, planted_detections, planted_frames
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import locust_cameras

GPU = _ck.available()


def outputs(fitter: Fitter, detections, rounds: bool) -> FitOutputs:
    """Every frame fitted by the scalar ``fit_frames`` or by the rounds (the GPU kernel's
    CPU twin annealing), from the inputs ``Fitter`` gives its kernels."""
    p, pr = fitter.params, fitter.problem
    obs = fitter.observations(detections)
    sel = np.arange(obs.n_frames)
    block = obs.arrays(sel)
    roots, rots = fitter._place(obs, sel)
    out = FitOutputs.empty(len(sel), pr.n_state, len(pr.cams.kind),
                           max(p.max_runs, p.candidates))
    args = (sel, roots, rots, pr.start, pr.folded, pr.cams, pr.dofs, schedule_of(p),
            fitter._error_args(p, block.objective), block)
    if rounds:
        _ck.fit_frames_rounds(*args, float(p.claim_gate_px), out, gpu=False)
    else:
        _frames.fit_frames(np.arange(len(sel) + 1, dtype=np.int64), *args, fitter._partitions(p),
                       out)
    return out


def assert_rounds_are_fit_frames(body, cams, detections, params) -> FitOutputs:
    fitter = Fitter(body, cams, params)
    scalar, rounds = (outputs(fitter, detections, r) for r in (False, True))
    for name in FitOutputs._fields:
        np.testing.assert_array_equal(getattr(rounds, name), getattr(scalar, name),
                                      err_msg=name)
    return rounds


def locust_frames(locust, n, seed, ghosts=1):
    truth = smooth_random_motion(locust, n, 1, seed=seed)
    return truth, planted_detections(locust, locust_cameras(), truth, ghosts=ghosts)


def test_rounds_reanalyse_as_fit_frames(locust):
    _, dets = locust_frames(locust, 20, seed=4)
    out = assert_rounds_are_fit_frames(locust, locust_cameras(), dets,
                                       AnnealParams.paper().with_schedule(1500))
    assert out.runs.max() > 1  # re-analysis happened, and matched


def test_rounds_with_candidates_refinement_and_empty_frames(locust):
    _, dets = locust_frames(locust, 16, seed=5, ghosts=2)
    dets[7] = [np.zeros((0, 2)), np.zeros((0, 2))]  # nothing detected
    dets[9][1] = np.zeros((0, 2))  # one view empty
    out = assert_rounds_are_fit_frames(locust, locust_cameras(), dets,
                                       AnnealParams().with_schedule(800))
    assert out.runs[7] == 0 and out.runs.min(initial=9, where=out.runs > 0) >= 2
    assert out.pairs.max() > 0  # refined


def test_rounds_keypoints_and_unexplained_detections():
    body = mouse_like(translation_window=4.0, rotation_window_deg=30.0)
    cams = three_pinholes()
    _, _, frames = planted_frames(body, cams, n=8, seed=7)
    assert_rounds_are_fit_frames(body, cams, frames,
                                 AnnealParams(max_unexplained=0).with_schedule(800))
    kp = labelled_keypoints(body, {c.name: c for c in cams}, frames, seed=12)
    assert_rounds_are_fit_frames(body, cams, kp, AnnealParams.paper(
        error=ErrorOptions(cap_px=20.0)).with_schedule(800))


def test_cuda_without_a_gpu_is_named(locust):
    if GPU:
        pytest.skip("this machine has a GPU numba can use")
    _, dets = locust_frames(locust, 4, seed=1)
    with pytest.raises(KinematicsError, match="cuda backend needs an NVIDIA GPU") as err:
        Fitter(locust, locust_cameras(), AnnealParams(backend="cuda")).fit(dets)
    assert err.value.field == "backend"


def test_the_cuda_backend_fits_with_the_rounds_alone(locust, monkeypatch):
    # where numba sees a GPU, the block goes to the rounds and to nothing else (here the
    # rounds anneal with the kernel's CPU twin, so the results are the scalar kernel's)
    rounds = _ck.fit_frames_rounds
    monkeypatch.setattr(_ck, "available", lambda: True)
    monkeypatch.setattr(_ck, "fit_frames_rounds",
                        lambda *a, **k: rounds(*a, **{**k, "gpu": False}))
    _, dets = locust_frames(locust, 6, seed=2)
    # one candidate: no path through time, whose re-fits of single frames are the scalar
    # kernel's by design
    params = AnnealParams(threshold_mode="absolute", candidates=1,
                          reanalysis_threshold=1.0).with_schedule(300)
    expected = Fitter(locust, locust_cameras(), replace(params, backend="scalar")).fit(dets)

    def refuse(*args):
        raise AssertionError("a CPU kernel fitted the block again")

    monkeypatch.setattr(_frames, "fit_frames", refuse)
    monkeypatch.setattr(_lk, "fit_frames_lanes", refuse)
    got = Fitter(locust, locust_cameras(), replace(params, backend="cuda")).fit(dets)
    assert_same(expected, got)
    assert max(r.runs for r in got) > 1  # with re-analysis


def test_a_gpu_that_fails_is_named(locust, monkeypatch):
    # numba says there is a GPU, and copying to it fails for real (none here)
    if GPU:
        pytest.skip("this machine has a GPU numba can use")
    monkeypatch.setattr(_ck, "available", lambda: True)
    _, dets = locust_frames(locust, 4, seed=3)
    with pytest.raises(KinematicsError, match="the cuda backend failed") as err:
        Fitter(locust, locust_cameras(), AnnealParams(backend="cuda")).fit(dets)
    assert err.value.field == "backend"
    assert "\n" not in str(err.value)  # one line, whatever numba's message spans
    many = _ck._reason("the GPU kernel failed", TypeError("first line\n\nsecond\nthird"))
    assert str(many) == "the GPU kernel failed (TypeError: first line)"


@pytest.mark.skipif(not GPU, reason="needs a CUDA GPU that numba can use")
@pytest.mark.parametrize("params", [
    AnnealParams.paper().with_schedule(3000), AnnealParams().with_schedule(2000)],
    ids=["paper", "defaults"])
def test_gpu_fits_as_the_scalar_kernel(locust, params):
    # NVVM fuses multiplies and adds, so the GPU's roundings are not the CPU's: a run takes
    # the scalar kernel's path to within rounding, unless an acceptance decision flips
    truth, dets = locust_frames(locust, 64, seed=6)
    fits = {b: Fitter(locust, locust_cameras(), replace(params, backend=b)).fit(dets)
            for b in ("scalar", "cuda")}
    assert _ck._kernels  # the GPU's kernel was compiled and launched
    a, b = (np.array([r.angles_deg for r in fits[k]]) for k in ("scalar", "cuda"))
    assert np.median(np.abs(a - b).max(axis=1)) < 0.01
    err = {k: np.median(np.abs(np.array([r.angles_deg for r in v]) - truth))
           for k, v in fits.items()}
    assert err["cuda"] <= 1.1 * err["scalar"] + 0.01
