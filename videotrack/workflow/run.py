"""The project workflow: from a project config to its detections, results file and plot.

:func:`run_project` is the one workflow every front end runs (``fit``, ``run``, ``batch``,
``demo`` and the GUI): detect the markers when the detections are stale, load the model, skip
the fit when the results are up to date, else fit and write the results, and plot. It
returns a :class:`~videotrack.workflow.report.ProjectRun` and never prints: the commands
print, the GUI shows it. :func:`plan_project` says what it would do without doing it. Its
steps are public too: :func:`~videotrack.workflow.model.load_model` loads the model (chain +
histograms + cameras per view + annealing parameters) once;
:func:`~videotrack.workflow.fitting.fit_project` drives the fitter's generator with progress
and resumable, atomic writing (:mod:`videotrack.workflow.checkpoint`); when the settings allow
it the records are fitted while the next are detected (:mod:`videotrack.workflow.streaming`).

Outputs never replace inputs (:func:`videotrack.project.outputs.guard_outputs`), checked before any
work is done.

The markerless route: a project whose ``[keypoints] files`` are set has no detections; its
keypoints are loaded by :func:`videotrack.markerless.route.load_keypoints` into a
:class:`~videotrack.markerless.route.KeypointInput`, which stands where the detections do (records,
video frames, times; the fitter gets its Observations), and the sidecar records the keypoint
files by content hash and the ``[keypoints]`` settings instead of the detections file.
"""

from __future__ import annotations

import contextlib
import os
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path

from kinematics.fit import FrameResult
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.markerless.route import KeypointInput, fitting_model, is_markerless, load_keypoints
from videotrack.results.files import candidates_path, read_results
from videotrack.workflow.checkpoint import checkpoint_paths, discard_checkpoint
from videotrack.workflow.fitting import fit_project
from videotrack.workflow.model import ProjectModel, check_detection_views, load_model
from videotrack.workflow.plots import _plot, default_plot_path
from videotrack.workflow.report import (
    DETECT,
    FIT,
    ProjectRun,
    StepProgress,
    _recorded_warnings,
    _reported,
    _reporter,
    _with_results,
)
from videotrack.workflow.staleness import (
    _older,
    _source,
    load_fresh_detections,
    results_stale_reason,
)
from videotrack.workflow.streaming import FitAlongside, not_streamable


def default_results_path(config, detections_path: Path) -> Path:
    """``[fit] results``, else ``<detections name>.results.csv`` beside the detections."""
    given = config["fit"]["results"]
    if given:
        return Path(given)
    name = detections_path.name.removesuffix(".npz").removesuffix(".detections")
    return detections_path.with_name(f"{name}.results.csv")


def run_project(
    config,
    *,
    detect: bool = True,
    fit: bool = True,
    force: bool = False,
    anneal: Mapping[str, object] | None = None,
    frames: slice | None = None,
    results: str | os.PathLike | None = None,
    plot: bool | None = None,
    threads: int | None = None,
    progress: Callable[[StepProgress], object] | None = None,
    cancel: Callable[[], bool] | None = None,
    log: Callable[[str], object] | None = None,
) -> ProjectRun:
    """Detect, fit and plot a project (or trial), each step skipped when its outputs are up
    to date; every file is written atomically and an interrupted fit resumes.

    Parameters
    ----------
    config : Config
        A loaded project (or trial) config.
    detect : bool
        Detect the markers when the detections file is missing or stale. False: use the
        file as it is; it must exist and have been made from the project's video(s) with
        its settings (``videotrack fit``).
    fit : bool
        False: stop after the detections (no model is needed).
    force : bool
        Recompute the steps run although their outputs are up to date.
    anneal : mapping, optional
        Overrides of ``[anneal]`` (``n_end``, ``seed``, ``refine``, ``start``, ...; None
        values keep the file's), as :func:`anneal_params`.
    frames : slice, optional
        Records of the detections to fit (clipped to them); such a subset is always fitted.
    results : path, optional
        Results file; default :func:`default_results_path`.
    plot : bool, optional
        Write ``<results>.png`` when the results are new or newer than it; default
        ``[fit] plot``.
    threads : int, optional
        numba threads for fitting; default ``[fit] jobs``; 0 keeps numba's setting.
    progress : callable, optional
        Called with a :class:`StepProgress` after each video frame detected and each
        record fitted (and once with ``done=0`` when a fit starts).
    cancel : callable, optional
        Asked after each progress step; when it returns True the run raises
        :class:`Cancelled`.
    log : callable, optional
        Receives one-line notes (stale detections detected again, why a fit runs).

    Returns
    -------
    ProjectRun

    Raises
    ------
    LocatedError
        Anything the user can get wrong: config, video, chain, cameras, parameters,
        detections of other views, stale detections with ``detect=False``, an output path
        that is one of the inputs or an existing file of another kind (unless ``force``).
    Cancelled
    """
    from videotrack.detect.run import default_output, detection_inputs

    report = _reporter(progress, cancel)
    plot = config["fit"]["plot"] if plot is None else plot
    if is_markerless(config) and not fit:
        raise VideoTrackError("the project is fitted to keypoint files: there are no markers "
                              "to detect ('videotrack fit' fits it)", file=config.path,
                              field="keypoints.files")
    with _recorded_warnings() as caught:
        with _recorded_warnings(pass_on=True) as loading:
            model = load_model(config, **(anneal or {})) if fit else None  # fails before work
        if is_markerless(config):
            run = _markerless_run(config, model, force=force, results=results, plot=plot)
            with _recorded_warnings(pass_on=True) as reading:
                data = load_keypoints(config, model)
            model = fitting_model(model, data)
            run = _fit(replace(run, detections=data), model, frames, force,
                       config["fit"]["jobs"] if threads is None else threads, report, log,
                       [*loading, *reading])
            return _reported(_plot(run, plot), caught)
        det_out = default_output(config)
        results_path = (Path(results) if results is not None else
                        default_results_path(config, det_out))
        _guard(config, model, det_out, results_path, detect=detect, fit=fit, plot=plot,
               force=force, results_given=results is not None,
               inputs=detection_inputs(config))
        threads = config["fit"]["jobs"] if threads is None else threads
        # records fitted while the next are detected, when that gives the same results and
        # there is no checkpoint to resume from (else the detection finishes first)
        alongside = (fit and detect and frames is None and not_streamable(model) is None
                     and not checkpoint_paths(results_path)[0].exists())
        if alongside:
            _set_threads(threads)
        with FitAlongside(model) if alongside else contextlib.nullcontext() as stream:
            t0 = time.perf_counter()
            detections, det_path, detected = _detections(
                config, detect, force, report, log, each=stream.add if stream else None)
            run = ProjectRun(det_path, results_path, steps=(DETECT,) if detected else (),
                             detect_seconds=time.perf_counter() - t0 if detected else 0.0,
                             detections=detections)
            if fit:
                notes = [*loading, *detections.metadata.get("warnings", [])]
                run = _fit(run, model, frames, force, threads, report, log, notes,
                           stream=stream if detected else None)
                run = _plot(run, plot)
    return _reported(run, caught)


def _markerless_run(config, model: ProjectModel, *, force: bool, results, plot: bool
                    ) -> ProjectRun:
    """The start of a markerless project's run: its results path, outputs checked against
    its inputs (the keypoint files among them) before any work."""
    from videotrack.markerless.route import default_results_path as keypoints_results_path
    from videotrack.markerless.route import keypoint_inputs

    results_path = (Path(results) if results is not None else
                    keypoints_results_path(config))
    _guard(config, model, None, results_path, detect=False, fit=True, plot=plot,
           force=force, results_given=results is not None, inputs=keypoint_inputs(config))
    return ProjectRun(None, results_path)


def _guard(config, model, det_out: Path | None, results_path: Path, *, detect: bool,
           fit: bool,
           plot: bool, force: bool, results_given: bool, inputs: dict) -> None:
    """Refuse outputs that are inputs, or existing files of another kind (unless force),
    before any work is done (:func:`videotrack.project.outputs.guard_outputs`)."""
    from videotrack.project.outputs import guard_outputs
    from videotrack.results.files import sidecar_path

    if model is not None:
        inputs = {**inputs, **model.inputs()}
    if detect:
        guard_outputs({det_out: "detections"}, inputs, force=force,
                      field="output.detections" if config["output"]["detections"] else None)
    if not fit:
        return
    outputs = {results_path: "results", sidecar_path(results_path): "sidecar",
               candidates_path(results_path): "csv"}
    partial, partial_side, partial_candidates = checkpoint_paths(results_path)
    outputs.update({partial: "results", partial_side: "sidecar", partial_candidates: "csv"})
    if plot:
        outputs[default_plot_path(results_path)] = "png"
    field = "--results" if results_given else "fit.results" if config["fit"]["results"] else None
    if det_out is not None:
        inputs = {**inputs, det_out: "the detections file"}
    guard_outputs(outputs, inputs, force=force, field=field)


def plan_project(config, *, force: bool = False, plot: bool | None = None) -> tuple[str, str]:
    """What :func:`run_project` would do, without doing it: ``(action, why)``.

    Actions: ``"detect + fit"``, ``"fit"``, ``"plot"``, ``"up to date"``. Reads the videos'
    headers, the detections and the results' sidecars; writes nothing.

    Raises
    ------
    LocatedError
        What would make the run fail (config, video, chain, cameras, views).
    """
    from videotrack.detect.run import default_output, detection_inputs, detections_status

    wanted = config["fit"]["plot"] if plot is None else plot
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VideoTrackWarning)
        model = load_model(config)
        if is_markerless(config):
            results = _markerless_run(config, model, force=force, results=None,
                                      plot=wanted).results_path
            if force:
                return "fit", "--force"
            data = load_keypoints(config, model)
            reason = results_stale_reason(fitting_model(model, data), data, results,
                                          data.n_records)
            if reason is not None:
                return "fit", reason
            if wanted and _older(default_plot_path(results), results):
                return "plot", "no plot of the current results"
            return "up to date", ""
        det_path = default_output(config)
        results = default_results_path(config, det_path)
        _guard(config, model, det_path, results, detect=True, fit=True, plot=wanted,
               force=force, results_given=False, inputs=detection_inputs(config))
        if force:
            return "detect + fit", "--force"
        reason, detections = detections_status(config)
        if reason is not None:
            return "detect + fit", reason
        check_detection_views(model, detections, det_path)
        reason = results_stale_reason(model, det_path, results, detections.n_records)
        if reason is not None:
            return "fit", reason
        if wanted and _older(default_plot_path(results), results):
            return "plot", "no plot of the current results"
        return "up to date", ""


def _detections(config, detect: bool, force: bool, report, log, each=None):
    """``(detections, path, made now)``: detected when stale (or forced), else as on disk;
    ``each`` gets every record detected (:func:`~videotrack.detect.run.detect_project`)."""
    from videotrack.detect.run import default_output, detect_project

    if not detect:
        path = default_output(config)
        return load_fresh_detections(config, path), path, False
    detections, path, up_to_date = detect_project(
        config, force=force, progress=lambda done, total: report(DETECT, done, total),
        log=log, each=each)
    if not up_to_date and log is not None:
        log(f"detected {detections.n_records} records into {path.name}")
    return detections, path, not up_to_date


def _set_threads(threads: int) -> None:
    """numba threads for fitting (0: keep numba's setting)."""
    import numba

    if threads:
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def _selected(frames: slice, n: int, log) -> range:
    """The records of ``frames`` among ``n``: refused where it selects none, said where it
    runs past the end."""
    idx = range(*frames.indices(n))
    asked = f"{frames.start or 0}:{'' if frames.stop is None else frames.stop}"
    if len(idx) == 0:
        raise VideoTrackError(f"{asked} selects no record: the detections have {n} records "
                              f"(0:{n})", field="frames")
    if frames.stop is not None and frames.stop > n and log is not None:
        log(f"frames {asked}: the detections have {n} records; fitting "
            f"{idx.start}:{idx.stop}")
    return idx


def _fit(run: ProjectRun, model: ProjectModel, frames: slice | None, force: bool,
         threads: int, report, log, notes: Sequence[str] = (),
         stream: FitAlongside | None = None) -> ProjectRun:
    """The fit step: results read when up to date, else fitted and written (taking the
    results of ``stream``, which fitted the records while they were detected)."""
    import numba

    detections, out = run.detections, run.results_path
    check_detection_views(model, detections, run.detections_path)
    n = detections.n_records
    idx = None if frames is None else _selected(frames, n, log)
    why = ("--force" if force else
           f"records {idx.start}:{idx.stop}" if idx is not None else
           results_stale_reason(model, _source(detections, run.detections_path), out, n))
    if why is None:
        discard_checkpoint(out)  # left if a run was killed right after its last write
        return _with_results(replace(run, model=model), read_results(out))
    _set_threads(threads)
    total = n if idx is None else len(idx)
    if log is not None:
        log(f"fitting {total} records ({why}), {numba.get_num_threads()} thread(s)"
            + (", begun while detecting" if stream is not None else ""))
    how = None
    fitter = model.fitter()
    if fitter.match_measured and not isinstance(detections, KeypointInput):
        # decided once, on this video's detections: said, and handed to the fit
        how, why_match = fitter.match_why(detections)
        if log is not None:
            log(f"markers matched {'in 3D' if how == '3d' else 'per view'} (match 'auto'): "
                f"{why_match}")
    out.parent.mkdir(parents=True, exist_ok=True)
    counts = {"done": 0, "bad": 0}

    def fitted(r: FrameResult) -> None:
        counts["done"] += 1
        counts["bad"] += not r.ok
        report(FIT, counts["done"], total, counts["bad"])

    kept = []

    def resumed(n: int, of: int) -> None:
        kept.append(n)
        if log is not None:
            log(f"resumed an interrupted fit: {n} of {of} records kept from "
                f"{checkpoint_paths(out)[0].name}")

    t0 = time.perf_counter() if stream is None else stream.started
    report(FIT, 0, total)
    table = fit_project(model, detections, run.detections_path, out, idx, fitted,
                        notes=notes, resumed=resumed, stream=stream, match=how)
    return _with_results(replace(run, model=model, steps=(*run.steps, FIT), fit_reason=why,
                                 fit_seconds=time.perf_counter() - t0,
                                 resumed=sum(kept), overlapped=stream is not None), table)
