"""Fitting a project's records and writing its results file: :func:`fit_project` drives the
fitter's generator with progress, checkpoints (:mod:`videotrack.workflow.checkpoint`, so an
interrupted fit resumes) and atomic writing; :func:`fit_warnings` says what looks wrong in
the results, kept in their sidecar.

Warnings travel: the sidecar keeps every warning of the run that made the results, so a
later run that finds them up to date reports them again.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from kinematics.fit import FrameResult
from kinematics.fit.noise import NoiseModel
from videotrack.markerless.route import KeypointInput
from videotrack.project.identity import relative_message
from videotrack.results.files import Results, results_from_fit, write_results
from videotrack.workflow import checkpoint
from videotrack.workflow.model import ProjectModel
from videotrack.workflow.staleness import _source, results_sidecar, threshold_entry
from videotrack.workflow.streaming import FitAlongside

#: A warning is raised when more than this share of the frames failed or had no detections.
BAD_SHARE_WARNING = 0.1


def fit_project(
    model: ProjectModel,
    detections,
    detections_path: Path,
    results_path: Path,
    frames=None,
    progress: Callable[[FrameResult], None] | None = None,
    *,
    notes: Sequence[str] = (),
    resumed: Callable[[int, int], object] | None = None,
    stream: FitAlongside | None = None,
    match: str | None = None,
) -> Results:
    """Fit ``frames`` (default all records) and write the results file and its sidecar.

    ``progress`` is called with each frame's result as it arrives. Finished frames are
    checkpointed so an interrupted run resumes (see the module docstring); ``resumed`` is
    called with (frames kept from a checkpoint, frames in all) when it does. The sidecar's
    ``warnings`` are ``notes`` (e.g. the detections' warnings) followed by
    :func:`fit_warnings` of the results. ``stream``: a :class:`FitAlongside` that has been
    fitting every record while they were detected; its results are taken (when there is no
    checkpoint to resume from) instead of fitting them again. ``match``: where the markers
    of these detections are matched, when the caller has decided it already
    (:meth:`Fitter.match_why`, for ``match = "auto"``), so it is not decided again; the
    sidecar keeps the project's setting.
    """
    results_path = Path(results_path)
    idx = np.arange(detections.n_records) if frames is None else np.asarray(list(frames))
    sidecar = results_sidecar(model, _source(detections, detections_path), results_path)
    partial = checkpoint._partial_path(results_path)
    done, threshold, noise = (checkpoint._resume(partial, sidecar)
                              if model.params.start == "mean" else ({}, None, None))
    done = checkpoint._resumable(done, idx, model.params)
    if threshold is not None:  # the sidecar's threshold, as the whole run's, if all is kept
        done = {k: replace(r, threshold=threshold) for k, r in done.items()}
    params = model.params
    if done and params.threshold_mode == "auto" and threshold is not None:
        # the threshold the checkpoint's frames were judged by, not one measured again on
        # the frames left (another sample: another threshold)
        params = replace(params, threshold_mode="absolute", reanalysis_threshold=threshold)
    if match is not None:
        params = replace(params, match=match)
    fitter = model.fitter(params=params)
    if done and noise is not None:  # the rest judged by the noise that judged the frames kept
        fitter.fixed_noise = NoiseModel.from_record(noise, len(model.view_names),
                                                   len(model.body.marker_names))
    if done and resumed is not None:
        resumed(len(done), len(idx))
    for r in done.values():
        if progress is not None:
            progress(r)
    todo = np.array([f for f in idx if int(f) not in done], dtype=np.int64)
    results: dict[int, FrameResult] = dict(done)
    last = time.monotonic()
    # the path through time continues from the last frames kept from the checkpoint
    before = [int(f) for f in idx[: len(idx) - len(todo)]]
    previous = [results[f] for f in before] if before and len(todo) and all(
        int(f) in done for f in before) else None
    observed = detections.observations if isinstance(detections, KeypointInput) else detections
    streamed = stream is not None and not done and frames is None
    if streamed:
        stream.fitter.check_setup(observed)  # on every record, now they are detected
        gen = stream.results(len(todo))
    else:
        gen = fitter.iter_fit(observed, todo, previous=previous) if todo.size else iter(())
    with contextlib.closing(gen):
        for r in gen:
            results[r.frame] = r
            if progress is not None:
                progress(r)
            if (time.monotonic() - last > checkpoint.CHECKPOINT_SECONDS
                    and model.params.start == "mean"):
                checkpoint._checkpoint(partial, model, results, detections,
                                       {**sidecar, **noise_entry(fitter)})
                last = time.monotonic()
    ordered = [results[int(f)] for f in idx]
    table = results_from_fit(model.body, ordered, model.view_names, detections)
    base = results_path.absolute().parent
    used = stream.fitter if streamed else fitter  # the fitter whose checks and noise judged
    found = [relative_message(w, base) for w in (*notes, *used.setup_warnings,
                                                 *fit_warnings(table, detections))]
    write_results(results_path, table, {**sidecar, **threshold_entry(ordered),
                                        **noise_entry(used),
                                        "warnings": list(dict.fromkeys(found))},
                  candidates=(model.body, ordered))
    checkpoint.discard_checkpoint(results_path)
    return table


def fit_warnings(table: Results, detections=None) -> list[str]:
    """What looks wrong in fitted results: detections with non-finite coordinates, and more
    than :data:`BAD_SHARE_WARNING` of the frames failed or without detections (naming the
    first of them)."""
    found = []
    if detections is not None and len(getattr(detections, "points", ())):
        bad = ~np.isfinite(detections.points).all(axis=1)
        if bad.any():
            rows = np.searchsorted(detections.offsets, np.flatnonzero(bad), side="right") - 1
            records = sorted({int(k) // max(detections.n_views, 1) for k in rows})
            found.append(f"{int(bad.sum())} detection(s) with coordinates that are not finite "
                         f"(records {_listing(records)}); check the detections file")
    n = len(table)
    if n:
        failed = np.flatnonzero(~table.ok_mask())
        if failed.size > BAD_SHARE_WARNING * n:
            frames = [int(table.video_frames[i]) for i in failed]
            kinds = {s: table.status.count(s) for s in ("failed", "no-detections")
                     if s in table.status}
            what = ", ".join(f"{v} {k}" for k, v in kinds.items())
            found.append(f"{failed.size} of {n} frames ({100 * failed.size / n:.1f} %) have "
                         f"no fit to trust ({what}): video frames {_listing(frames)}")
        empty = [i for i, s in enumerate(table.status) if s == "no-detections"]
        if empty and hasattr(detections, "counts") and detections.n_records == n:
            seen = [i for i in empty if detections.counts()[i].sum() > 0]
            if seen:  # only matching in 3D leaves a frame with detections unfitted
                found.append(f"{len(seen)} frame(s) have detections but no 3D point (video "
                             f"frames {_listing([int(table.video_frames[i]) for i in seen])}): "
                             "matching in 3D needs a marker seen by 3 or more views; set "
                             "[anneal] match = \"views\" to match per view")
        unsure = [i for i, s in enumerate(table.status) if s == "ambiguous"]
        if len(unsure) > BAD_SHARE_WARNING * n:
            frames = [int(table.video_frames[i]) for i in unsure]
            found.append(f"{len(unsure)} of {n} frames ({100 * len(unsure) / n:.1f} %) are "
                         "ambiguous (another posture fits about as well, see the candidates "
                         "file; or a limb has a marker nothing places): video frames "
                         f"{_listing(frames)}")
    return found


def noise_entry(fitter) -> dict:
    """The sidecar's record of the noise model a fit judged its frames by: σ per view
    (pixels) and how it was found; nothing where there was none."""
    return {} if fitter.noise is None else {"noise": fitter.noise.to_record()}


def _listing(values: Sequence[int], most: int = 8) -> str:
    shown = ", ".join(str(v) for v in values[:most])
    return shown + (f", ... ({len(values)} in all)" if len(values) > most else "")
