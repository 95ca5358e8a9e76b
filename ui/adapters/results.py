"""Results as the error table, the re-analysis highlight, the frames to check, the
timeline and the postures histograms learn from (no Qt)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from kinematics.fit.result import ATTENTION, SCORED, TRUSTED, Status

#: Table text of a frame that has not been fitted.
NOT_FITTED = "not fitted"
#: Statuses whose posture the user can trust (within the threshold, or set by hand).
GOOD_STATUSES = TRUSTED

# -- error table and timeline ---------------------------------------------------------------
@dataclass(frozen=True)
class FrameTable:
    """Columns of the per-frame error table, one row per record (NaN where not fitted)."""

    frame: np.ndarray  # (n,) int64
    error: np.ndarray  # (n,)
    error_per_view: np.ndarray  # (n, n_views)
    runs: np.ndarray  # (n,) int64, 0 where not fitted
    sd: np.ndarray  # (n,) the largest axis sd, degrees (NaN without one)
    status: list[str]  # (n,)


def frame_table(results: Mapping, n_frames: int, n_views: int) -> FrameTable:
    """The error table of all ``n_frames`` records from ``{frame: FrameResult}``."""
    error = np.full(n_frames, np.nan)
    per_view = np.full((n_frames, n_views), np.nan)
    runs = np.zeros(n_frames, np.int64)
    sd = np.full(n_frames, np.nan)
    status = [NOT_FITTED] * n_frames
    for f, r in results.items():
        if 0 <= f < n_frames:
            error[f], per_view[f], runs[f], sd[f], status[f] = table_row(r, n_views)
    return FrameTable(np.arange(n_frames, dtype=np.int64), error, per_view, runs, sd, status)


def largest_sd(result) -> float:
    """How unsure a frame is: the largest standard deviation of its axes, degrees (NaN
    without one)."""
    sd = getattr(result, "sd_deg", None)
    if sd is None or not np.isfinite(sd).any():
        return float("nan")
    return float(np.nanmax(sd))


def table_row(result, n_views: int) -> tuple:
    """One row ``(error, errors per view, runs, largest sd, status)`` of a result (or of
    None)."""
    if result is None:
        return np.nan, np.full(n_views, np.nan), 0, np.nan, NOT_FITTED
    return float(result.error), np.asarray(result.error_per_view, float), int(result.runs), \
        largest_sd(result), result.status


def is_bad(error, threshold: float):
    """The highlight rule: error above the re-analysis threshold (NaN is not bad)."""
    e = np.asarray(error, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(e), e > threshold, False)


def bad_frames(results: Mapping, threshold: float) -> list[int]:
    """Frames whose error exceeds ``threshold``, ascending."""
    return sorted(f for f, r in results.items() if bool(is_bad(r.error, threshold)))


#: Statuses that need a look even within the threshold.
ATTENTION_STATUSES = ATTENTION


def frames_to_check(results: Mapping, threshold: float) -> list[int]:
    """Frames a person should look at, ascending: those above the threshold or whose fit
    failed, needed re-runs or is ambiguous (see FrameResult.status); never
    the ones corrected or accepted by hand."""
    return sorted(f for f, r in results.items() if r.status != Status.CORRECTED and (
        bool(is_bad(r.error, threshold)) or r.status in ATTENTION_STATUSES))


def next_to_check(results: Mapping, threshold: float, frame: int, direction: int
                  ) -> int | None:
    """The nearest frame after (``direction`` > 0) or before ``frame`` that needs a look."""
    todo = frames_to_check(results, threshold)
    later = [f for f in todo if (f - frame) * direction > 0]
    if not later:
        return None
    return later[0] if direction > 0 else later[-1]


@dataclass(frozen=True)
class Timeline:
    """Arrays of the timeline plot over all records."""

    frames: np.ndarray  # (n,)
    angles_deg: np.ndarray  # (n, n_axes), NaN where not fitted
    error: np.ndarray  # (n,)
    sd_deg: np.ndarray  # (n, n_axes), NaN without a standard deviation


def timeline(results: Mapping, n_frames: int, n_axes: int) -> Timeline:
    """Angles, their sd and the error of every record from ``{frame: FrameResult}``."""
    angles = np.full((n_frames, n_axes), np.nan)
    sd = np.full((n_frames, n_axes), np.nan)
    error = np.full(n_frames, np.nan)
    for f, r in results.items():
        if 0 <= f < n_frames:
            angles[f], error[f] = r.angles_deg, r.error
            if getattr(r, "sd_deg", None) is not None:
                sd[f] = r.sd_deg
    return Timeline(np.arange(n_frames, dtype=float), angles, error, sd)


def learning_angles(results: Mapping, statuses: Sequence[str] | None = GOOD_STATUSES,
                    threshold: float | None = None) -> np.ndarray:
    """Postures to learn histograms from (Eq. 4), shape (n, n_axes), in frame order.

    ``statuses`` None takes every fitted frame. With a ``threshold`` the frames are judged by
    it instead of by their stored statuses (set by the fit's threshold): :func:`trusted`.
    Frames without a finite posture are skipped.
    """
    if threshold is not None:
        keep = [f for f in sorted(results) if trusted(results[f], threshold)]
    else:
        keep = [f for f in sorted(results) if statuses is None or results[f].status in statuses]
    rows = [np.asarray(results[f].angles_deg, float) for f in keep]
    rows = [a for a in rows if np.all(np.isfinite(a))]
    return np.array(rows).reshape(len(rows), -1) if rows else np.empty((0, 0))


#: Statuses of fitted frames whose trust the error threshold decides.
FITTED_STATUSES = SCORED


def trusted(result, threshold: float) -> bool:
    """A frame within the threshold now: corrected by hand, or fitted with E ≤ ``threshold``
    (whatever status the fit gave it under its own threshold; ambiguous frames are not)."""
    if result.status == Status.CORRECTED:
        return True
    error = float(result.error)
    return result.status in FITTED_STATUSES and np.isfinite(error) and error <= threshold


