"""A fit running in a worker thread leaves the main thread (a GUI's event loop, a server)
free to run: the kernels release the GIL (``nogil=True``)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from kinematics._kernels import anneal as ak
from kinematics._kernels import fastmath as _fastmath
from kinematics._kernels.records import FrameObs, new_scratch
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.problem import ErrorArgs, Schedule
from tests.fixtures.planted import planted_detections
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import locust_cameras


def longest_stall(work) -> tuple[float, float]:
    """Run ``work`` in a thread; return the longest gap of a 2-ms sleep loop in this thread
    while it ran, and how long it ran."""
    done = threading.Event()
    worker = threading.Thread(target=lambda: (work(), done.set()))
    t0 = last = time.perf_counter()
    gaps = []
    worker.start()
    while not done.is_set():
        time.sleep(0.002)
        now = time.perf_counter()
        gaps.append(now - last)
        last = now
    # A thread holding the GIL keeps this loop from running at all until it ends: that
    # stall ends here.
    gaps.append(time.perf_counter() - last)
    worker.join()
    return max(gaps), time.perf_counter() - t0


def test_main_thread_runs_while_one_annealing_run_goes_on(locust):
    """One long call of the serial annealing kernel (numba's parallel launch releases the
    GIL anyway; this kernel only does so because it is compiled nogil)."""
    cams = locust_cameras()
    frame = planted_detections(locust, cams, smooth_random_motion(locust, 1, 1, seed=3))[0]
    pts = np.ascontiguousarray(np.concatenate(frame))
    off = np.array([0, len(frame[0]), len(pts)], np.int64)
    pr = Fitter(locust, cams).problem
    na, nj, nm = pr.n_state, 3, 4
    scratch = new_scratch(na, nj, nm, 2)
    schedule = Schedule(1e-300, 16, 1, 1, 1, 200.0, 1.0, 0.75, 0.75, 0.0, 0, 0.0, 1, 0, 0.0,
                        False, -1, 1)
    obs = FrameObs(0, pts, np.ones(len(pts)), off, np.zeros((nm, 4)))

    def run(n_end):
        return ak.anneal_chain(pr.start, pr.free_idx, (n_end, n_end, n_end),
                               _fastmath.stream_state(0, 0, 0), np.zeros((1, 3)),
                               pr.identity_rotations(), pr.folded, pr.cams, pr.dofs, schedule,
                               ErrorArgs(False, 1.0, np.inf, np.inf, False), obs,
                               (0, nj, 0, nm), np.zeros(len(pts), np.bool_), scratch,
                               np.empty(0))

    run(10)  # compile outside the measurement
    gap, duration = longest_stall(lambda: run(3_000_000))
    assert duration > 0.3, "the run was too short to tell"
    # A kernel holding the GIL would stall this loop for the whole call.
    assert gap < max(0.2, 0.3 * duration), (gap, duration)


@pytest.mark.parametrize(("backend", "frames"), [("scalar", 120), ("lanes", 1200)])
def test_main_thread_runs_while_a_video_is_fitted(locust, backend, frames):
    cams = locust_cameras()
    dets = planted_detections(locust, cams, smooth_random_motion(locust, frames, 4, seed=3))
    fitter = Fitter(locust, cams, AnnealParams.paper(epsilon=0.0, max_runs=1,
                                                     backend=backend))
    fitter.fit(dets[:1])
    gap, duration = longest_stall(lambda: list(fitter.iter_fit(dets, chunk_size=len(dets))))
    assert duration > 0.3, "the fit was too short to tell"
    assert gap < max(0.25, 0.3 * duration), (gap, duration)
