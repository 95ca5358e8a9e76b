"""Corrections that spread (issue 15, item 4): re-fit forward/backward from a corrected
frame, interpolate pinned axes over a range; all in the worker, cancellable, one undo step."""

from __future__ import annotations

from dataclasses import replace

import numpy as np


def _fit_all(s, wait_idle) -> None:
    assert s.fit()
    wait_idle(s)


def test_refit_forward_stops_at_a_frame_set_by_hand(session, wait_idle):
    s = session
    _fit_all(s, wait_idle)
    s.set_params(replace(s.params, reanalysis_threshold=1e9))
    assert s.correct({8: 100.0}, refit=False, frame=3)  # the corrected posture to carry
    assert s.accept([8]) == 1  # an accepted frame is a wall
    before = dict(s.results)
    assert s.refit_from(1, frame=3)
    assert s.busy  # in the worker: the window is free meanwhile
    wait_idle(s)
    changed = sorted(f for f in s.results if s.results[f] is not before[f])
    assert changed == [4, 5, 6, 7]
    assert all(s.results[f].status != "corrected" for f in changed)
    # each frame was fitted from the one before it (seeds are per frame: reproducible)
    fitter = s._fitter()
    for f in changed:
        again = fitter.fit_frame(s.frame_detections(f), f, start_deg=s.results[f - 1].angles_deg,
                                 root_positions=before[f].root_positions)
        np.testing.assert_array_equal(again.angles_deg, s.results[f].angles_deg)
    assert s.results[8] is before[8] and s.results[3] is before[3]
    assert s.undo_label == "re-fit forward from frame 3"
    s.undo()
    assert all(s.results[f] is before[f] for f in before)
    # backward from 3 runs to the start
    assert s.refit_from(-1, frame=3)
    wait_idle(s)
    assert sorted(f for f in s.results if s.results[f] is not before[f]) == [0, 1, 2]


def test_refit_forward_stops_where_the_error_exceeds_the_threshold(session, wait_idle):

    s = session
    _fit_all(s, wait_idle)
    s.set_params(replace(s.params, reanalysis_threshold=1e-6))  # every frame is above it
    before = dict(s.results)
    messages = []
    s.status.connect(messages.append)
    assert s.refit_from(1, frame=5)
    wait_idle(s)
    assert all(s.results[f] is before[f] for f in before)  # frame 6 left as it was
    assert any("stopped at frame 6" in m and "above the threshold" in m for m in messages)


def test_refit_without_a_posture_says_so(session):
    s = session
    assert not s.refit_from(1, frame=2)
    assert "no posture to carry" in s.messages[-1]


def test_refit_forward_is_cancellable(session, wait_idle):

    s = session
    _fit_all(s, wait_idle)
    before = dict(s.results)
    s.set_params(replace(s.params, reanalysis_threshold=1e9, epsilon=0.0, max_runs=1)
                 .with_schedule(400_000))
    s.resultsChanged.connect(lambda *_: s.cancel())  # cancel once the first frame is in
    assert s.refit_from(1, frame=0)
    wait_idle(s, timeout=60000)
    changed = [f for f in s.results if s.results[f] is not before[f]]
    assert 1 <= len(changed) < 11 and changed[0] == 1
    assert s.can_undo


def test_interpolate_pinned_axes_between_two_corrected_frames(session, wait_idle):
    s = session
    _fit_all(s, wait_idle)
    assert not s.interpolate(2, 6)  # ends not corrected
    assert "corrected frames at both ends" in s.messages[-1]
    s.correct({8: 60.0}, refit=False, frame=2)
    s.correct({8: 100.0}, refit=False, frame=6)
    assert s.interpolate(6, 2, refit=True)
    wait_idle(s)
    for f, value in ((3, 70.0), (4, 80.0), (5, 90.0)):
        r = s.results[f]
        assert r.status == "corrected" and s.pins[f] == {8: value}
        assert r.angles_deg[8] == value  # held while the rest was re-fitted
        assert np.isfinite(r.error)
    assert s.undo_label == "interpolate frames 2–6"
    s.undo()
    assert all(s.results[f].status != "corrected" and f not in s.pins for f in (3, 4, 5))


def test_refit_forward_stops_where_the_error_jumps_even_under_a_loose_bar(session,
                                                                          wait_idle):
    s = session
    _fit_all(s, wait_idle)
    s.set_bar(1e9)  # the bar alone would carry on to the end
    for point in s.frame_detections(6)[0]:  # frame 6's first view: every blob 40 px off
        assert s.edit_detection(0, remove=tuple(point), add=(point[0] + 40.0, point[1]),
                                frame=6)
    before = dict(s.results)
    messages = []
    s.status.connect(messages.append)
    assert s.refit_from(1, frame=3)
    wait_idle(s)
    assert s.results[6] is before[6] and s.results[7] is before[7]
    assert all(s.results[f] is not before[f] for f in (4, 5))
    assert any("stopped at frame 6" in m and "jumps" in m for m in messages)
