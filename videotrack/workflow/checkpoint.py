"""Checkpoints of an unfinished fit, so that an interrupted fit resumes.

Resuming: while fitting, finished frames are checkpointed every few seconds
(:data:`CHECKPOINT_SECONDS`) to ``<results>.partial`` (with its own sidecar, the threshold
and the noise model that judged them). A run that is killed and started again with the same
inputs and parameters keeps those frames and fits only the rest; the final file is the same
as an uninterrupted run's because frames are fitted independently from their own random
streams, the rest is judged by the kept threshold and noise model, and with the path through
time only the leading whole windows (multiples of ``Tuning.path_lag``, 32 frames) are kept,
so the rest is decided in the windows the whole run decided it in (with ``start =
"previous"`` the checkpoint is not used). :func:`videotrack.workflow.fitting.fit_project`
writes and reads them through this module's attributes, so a test may replace
:data:`CHECKPOINT_SECONDS` or :func:`_checkpoint` here.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np

from kinematics.fit import AnnealParams, FrameResult, tuning
from videotrack.errors import VideoTrackError
from videotrack.results.files import (
    attach_candidates,
    candidates_path,
    frame_results,
    read_results,
    read_sidecar,
    results_from_fit,
    write_results,
)
from videotrack.workflow.model import ProjectModel
from videotrack.workflow.staleness import changed_inputs, threshold_entry

#: Seconds between two checkpoints of a fit.
CHECKPOINT_SECONDS = 5.0


def _partial_path(results_path: Path) -> Path:
    return results_path.with_name(results_path.name + ".partial")


def checkpoint_paths(results_path: Path) -> tuple[Path, ...]:
    """The checkpoint of an unfinished fit, its sidecar and its candidates file."""
    partial = _partial_path(Path(results_path))
    return partial, partial.with_name(partial.name + ".json"), candidates_path(partial)


def discard_checkpoint(results_path: Path) -> None:
    """Remove the checkpoint of a fit whose results file is complete (nothing to do, and
    nothing written, where there is none: a finished project on read-only storage)."""
    for p in checkpoint_paths(results_path):
        if p.exists():  # unlink on a read-only file system fails even for a missing file
            with contextlib.suppress(FileNotFoundError):
                os.unlink(p)


def _checkpoint(partial: Path, model: ProjectModel, results: dict, detections, sidecar):
    ordered = [results[k] for k in sorted(results)]
    write_results(partial, results_from_fit(model.body, ordered, model.view_names, detections),
                  {**sidecar, **threshold_entry(ordered)}, candidates=(model.body, ordered))


def _resume(partial: Path, sidecar: dict
            ) -> tuple[dict[int, FrameResult], float | None, dict | None]:
    """Frames of a checkpoint made with the same inputs and parameters ({} otherwise), the
    re-analysis threshold that judged them (None if it has none) and the noise model's
    record (``noise``; None if it has none)."""
    if not partial.exists():
        return {}, None, None
    try:
        meta = read_sidecar(partial)
        if changed_inputs(meta, sidecar):
            return {}, None, None
        table = read_results(partial)
        threshold = meta.get("threshold")
        usable = (isinstance(threshold, int | float) and not isinstance(threshold, bool)
                  and 0 < threshold < float("inf"))  # else measured again
        return (attach_candidates(frame_results(table, int(meta["seed"])), partial),
                float(threshold) if usable else None, meta.get("noise"))
    except VideoTrackError:
        return {}, None, None


def _resumable(done: dict[int, FrameResult], idx: np.ndarray,
               params: AnnealParams) -> dict[int, FrameResult]:
    """The checkpoint's frames a resumed fit keeps: those of ``idx``; with the path through
    time (``candidates`` > 1), only the leading whole windows' (multiples of
    ``Tuning.path_lag`` frames of ``idx``, all kept), so the rest is decided in the windows
    the whole fit decided it in."""
    wanted = set(idx.tolist())
    done = {k: r for k, r in done.items() if k in wanted}
    if params.candidates <= 1 or not done:
        return done
    lead = next((i for i, f in enumerate(idx) if int(f) not in done), len(idx))
    keep = lead - lead % tuning.TUNING.path_lag
    return {int(f): done[int(f)] for f in idx[:keep]}
