"""A fit running in a worker thread leaves the main thread (a GUI's event loop, a server)
free to run: the kernels release the GIL (``nogil=True``; numba's parallel launch does too)."""

from __future__ import annotations

import threading
import time

import numpy as np

from kinematics.anneal import AnnealParams, Fitter
from tests.kinematics.test_anneal import planted
from videotrack.motion import smooth_random_motion
from videotrack.paper_setup import locust_cameras


def test_main_thread_runs_while_a_kernel_fits(locust):
    cams = locust_cameras()
    dets = planted(locust, cams, smooth_random_motion(locust, 120, 4, seed=3))
    fitter = Fitter(locust, cams, AnnealParams(epsilon=0.0, max_runs=1))
    fitter.fit(dets[:1])  # compile outside the measurement
    done = threading.Event()
    t0 = time.perf_counter()

    def work():
        list(fitter.iter_fit(dets, chunk_size=len(dets)))  # one long kernel call
        done.set()

    worker = threading.Thread(target=work)
    worker.start()
    gaps, last = [], time.perf_counter()
    while not done.is_set():
        time.sleep(0.002)
        now = time.perf_counter()
        gaps.append(now - last)
        last = now
    worker.join()
    duration = time.perf_counter() - t0
    assert duration > 0.3, "the fit was too short to tell"
    # A kernel holding the GIL would stall this loop for the whole call (the duration).
    assert np.max(gaps) < max(0.25, 0.3 * duration), (np.max(gaps), duration)
