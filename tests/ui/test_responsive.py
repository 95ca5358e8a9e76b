"""Cancelling a fit gives the window back at once (issue 15, item 1): the fit is let go and
finishes the frames in hand in the background, its results discarded."""

from __future__ import annotations

import time

import pytest

from ui.state import backend


def test_cancel_returns_at_once_and_a_new_fit_may_start(session, qtbot, wait_idle,
                                                        monkeypatch):
    from kinematics.fit import AnnealParams

    s = session
    s.fit([0])  # a parallel kernel has run: numba's threading layer is known
    wait_idle(s)
    if not backend.concurrent_fits():
        pytest.skip("numba's workqueue layer: a cancelled fit is waited for")
    s.undo()
    # with candidates the fitter hands results over 32 frames at a time: 12 frames come at
    # the end, seconds from now
    s.set_params(AnnealParams().with_schedule(300_000))
    assert s.fit()
    qtbot.wait(200)
    t = time.perf_counter()
    s.cancel()
    assert not s.busy and time.perf_counter() - t < 0.2
    assert s.results == {} and s._released  # nothing arrived; the worker is still running
    assert s.undo_label != "fit (12 frames)"  # an empty run is no undo step
    # a new task starts while the old fit runs out; the old one's results never arrive
    s.set_params(AnnealParams.paper().with_schedule(3000))
    assert s.fit([3, 4])
    wait_idle(s)
    qtbot.waitUntil(lambda: not s._released, timeout=120000)
    qtbot.wait(50)
    assert sorted(s.results) == [3, 4]
