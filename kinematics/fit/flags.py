"""Flags over a sequence of results: a limb on another limb's points (misplaced), and a
tracked frame whose E spikes against its neighbours.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import replace

import numpy as np

from kinematics.fit.result import WITHIN, FrameResult, Status
from kinematics.fit.status import auto_threshold
from kinematics.fit.tuning import TUNING, Tuning


def misplaced(results: Sequence[FrameResult], gate: float, tuning: Tuning = TUNING
              ) -> np.ndarray:
    """Per result: a marker lies off every detection of its view (``worst_px`` above the
    results' median + ``Tuning.misplaced_k`` robust SDs, and above ``gate``) while the frame
    leaves more detections unexplained than these frames do (above their median +
    ``Tuning.misplaced_unexplained_k`` robust SDs): a limb on another limb's points, its own
    left over. A marker off its point alone is an occluded one, a frame's unexplained
    detections alone its ghosts."""
    worst = np.array([r.worst_px if r.runs else np.nan for r in results], float)
    left = np.array([r.unexplained for r in results], float)
    fitted = np.isfinite(worst)
    out = np.zeros(len(results), bool)
    if fitted.sum() < 3:  # no statistics of a video
        return out
    limit = max(gate, auto_threshold(worst[fitted], tuning.misplaced_k, 0.0))
    # a count: where over half the frames share one value its MAD is 0, so the spread is at
    # least half the 10-90 % range (a ghost that flickers in half the frames: 1)
    counts = left[fitted]
    med = float(np.median(counts))
    lo, hi = np.percentile(counts, [10.0, 90.0])
    spread = max(1.4826 * float(np.median(np.abs(counts - med))), float(hi - lo) / 2.0)
    usual = med + tuning.misplaced_unexplained_k * spread
    with np.errstate(invalid="ignore"):
        return (worst > limit) & (left > usual)


def flag_misplaced(results: Iterable[FrameResult], gate: float,
                   before: Sequence[FrameResult] = (), starts=(), tuning: Tuning = TUNING
                   ) -> Iterator[FrameResult]:
    """``results`` (frames in order), each ``ok`` or ``reanalysed`` one that :func:`misplaced`
    finds among the ``Tuning.misplaced_half`` results on either side and itself made
    ``ambiguous`` (neighbours in the same run of consecutive frames only, not across a frame
    of ``starts``, where a new sequence starts); a result is yielded once Tuning.misplaced_half
    later ones are known. ``before``: results just before the first (a resumed fit's),
    counted but not yielded."""
    starts = np.asarray(list(starts), np.int64)

    def judge(window: list[FrameResult], k: int) -> FrameResult:
        r = window[k]
        lo = max(0, k - tuning.misplaced_half)  # the same run of consecutive frames only
        around = [w for j, w in enumerate(window[lo: k + tuning.misplaced_half + 1], lo)
                  if w.frame - r.frame == j - k and not (
                      (starts > min(w.frame, r.frame)) & (starts <= max(w.frame, r.frame))
                  ).any()]
        if r.status in WITHIN and misplaced(around, gate, tuning)[
                next(j for j, w in enumerate(around) if w is r)]:
            return replace(r, status=Status.AMBIGUOUS)
        return r
    return _judged(results, tuning.misplaced_half, judge, before)


def flag_e_spikes(results: Iterable[FrameResult], ratio: float | None = None,
                  half: int | None = None, tuning: Tuning = TUNING) -> Iterator[FrameResult]:
    """``results`` (frames in order), each ``ok`` or ``reanalysed`` one whose E is above
    ``ratio`` (``Tuning.track_spike``) times the median E of the ``half``
    (``Tuning.track_spike_half``) consecutive frames on either side and itself, plus
    ``Tuning.track_jump_px`` per marker image with a residual, made ``ambiguous``; a result is
    yielded once ``half`` later ones are known. A frame with fewer than ``half`` + 1 such
    frames around it (a run of frames that short) is not flagged. A tracked frame has no
    candidates to compare; a wrong one stands out from its neighbours by E (fly 0:660: 16
    flagged of 660, 11 of them off by > 0.2 mm; 9 of the 10 frames off by > 0.3 mm)."""
    ratio = tuning.track_spike if ratio is None else ratio
    half = tuning.track_spike_half if half is None else half

    def judge(window: list[FrameResult], k: int) -> FrameResult:
        r = window[k]
        lo = max(0, k - half)  # the same run of consecutive frames only
        around = [w.error for j, w in enumerate(window[lo: k + half + 1], lo)
                  if np.isfinite(w.error) and w.frame - r.frame == j - k]
        images = (0 if r.marker_residuals is None
                  else int(np.isfinite(r.marker_residuals).sum()))
        if (r.status in WITHIN and np.isfinite(r.error) and len(around) > half
                and r.error > ratio * float(np.median(around)) + tuning.track_jump_px * images):
            return replace(r, status=Status.AMBIGUOUS)
        return r
    return _judged(results, half, judge)


def _judged(results: Iterable[FrameResult], half: int,
            judge: Callable[[list[FrameResult], int], FrameResult],
            before: Sequence[FrameResult] = ()) -> Iterator[FrameResult]:
    """``judge(window, k)`` of each of ``results``, in order, where ``window[k]`` is that
    result and ``window`` holds up to ``half`` results on either side of it; each is yielded
    once ``half`` later ones are known. ``before``: results just before the first, in the
    window but not judged."""
    window = list(before)[-half:] if half else []
    done = len(window)  # how many of ``window`` are yielded (or came before)
    for r in results:
        window.append(r)
        while len(window) - done > half:
            yield judge(window, done)
            done += 1
            if done > half:
                window.pop(0)
                done -= 1
    for k in range(done, len(window)):
        yield judge(window, k)
