"""Project-level fitting: from a project config and its detections to a results file.

:func:`run_project` is the one workflow every front end runs (``fit``, ``run``, ``batch``,
``demo`` and the GUI): detect the markers when the detections are stale, load the model, skip
the fit when the results are up to date, else fit and write the results, and plot. It
returns a :class:`ProjectRun` and never prints: the commands print, the GUI shows it.
:func:`plan_project` says what it would do without doing it. Its steps are public too:
:func:`load_model` loads the model (chain + histograms + cameras per view + annealing
parameters) once; :func:`fit_project` drives the fitter's generator with progress and
resumable, atomic writing.

Resuming: while fitting, finished frames are checkpointed every few seconds to
``<results>.partial`` (with its own sidecar and the threshold that judged them). A run that is
killed and started again with the same inputs and parameters keeps those frames and fits only
the rest; the final file is the same as an uninterrupted run's because frames are fitted
independently from their own random streams, the rest is judged by the kept threshold, and
with the path through time only the leading whole windows (multiples of
``anneal.PATH_LAG``, 32 frames) are kept, so the rest is decided in the windows the whole run
decided it in (with ``start = "previous"`` the checkpoint is not used).

Fitting while detecting: when every record is fitted on its own (:func:`not_streamable`: one
candidate per frame, an absolute re-analysis threshold, start from the means, fixed roots),
:func:`run_project` hands the records to a fitting thread as they are detected
(:class:`FitAlongside`), so decoding, detection and fitting overlap; the results are those of
detecting first and fitting afterwards. Checkpoints start once the detections file is written
(their sidecar names it by content hash); a run that finds a checkpoint detects first and
resumes from it.

Identity: the results sidecar names its inputs by paths relative to the results file's
folder and identifies them by content hash (:mod:`videotrack.identity`); only the hashes and
the parameters decide whether results are up to date (:data:`IDENTITY_KEYS`), so a project
copied or moved elsewhere stays up to date and a changed input of the same size does not.

Warnings travel: what went wrong while detecting is kept in the detections file, and the
sidecar keeps every warning of the run that made the results, so a later run that finds them
up to date reports them again. :attr:`ProjectRun.incomplete` says when the results do not
cover the video(s) (a truncated file, an unreadable image) or no frame could be fitted.

Outputs never replace inputs (:func:`videotrack.outputs.guard_outputs`), checked before any
work is done.

The markerless route: a project whose ``[keypoints] files`` are set has no detections; its
keypoints are loaded by :func:`videotrack.markerless.load_keypoints` into a
:class:`~videotrack.markerless.KeypointInput`, which stands where the detections do (records,
video frames, times; the fitter gets its Observations), and the sidecar records the keypoint
files by content hash and the ``[keypoints]`` settings instead of the detections file.
"""

from __future__ import annotations

import contextlib
import os
import queue
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from kinematics import anneal
from kinematics.anneal import AnnealParams, Fitter, FrameResult
from kinematics.model import Body
from videotrack.config import anneal_from_table
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.identity import relative_message, relative_path
from videotrack.marker_colours import markers_matching
from videotrack.markerless import KeypointInput, fitting_model, is_markerless, load_keypoints
from videotrack.results import (
    Results,
    attach_candidates,
    candidates_path,
    file_sha256,
    frame_results,
    read_results,
    read_sidecar,
    results_from_fit,
    write_candidates,
    write_results,
)

CHECKPOINT_SECONDS = 5.0
#: A warning is raised when more than this share of the frames failed or had no detections.
BAD_SHARE_WARNING = 0.1
#: Sidecar keys that decide whether results are up to date (inputs by content hash, and
#: every parameter), in the order ``changed: ...`` lists them; paths are not among them.
IDENTITY_KEYS = ("chain_sha256", "cameras_sha256", "histograms_sha256", "views",
                 "view_cameras", "view_markers", "axes", "markers", "seed", "anneal",
                 "detections_sha256", "keypoints_sha256", "keypoints_options")
_KEY_NAMES = {"view_cameras": "view cameras", "view_markers": "the markers views show",
              "keypoints_options": "keypoint settings"}


@dataclass(frozen=True)
class ProjectModel:
    """Everything the fitter needs from a project, loaded and checked."""

    body: Body
    cameras: dict  # view name -> camera, in the order of the views
    params: AnnealParams
    chain_path: Path
    cameras_path: Path
    histograms_path: Path | None
    #: view name -> the chain's markers it shows (``[[views]] model_markers``); views not
    #: named show all
    view_markers: dict = field(default_factory=dict)

    @property
    def view_names(self) -> list[str]:
        return list(self.cameras)

    def fitter(self, body: Body | None = None, params: AnnealParams | None = None) -> Fitter:
        """The fitter of this project (optionally of an edited ``body`` with the same
        markers, or with other ``params``)."""
        return Fitter(body or self.body, self.cameras, params or self.params,
                      view_markers=self.view_markers)

    def signature(self, base: str | os.PathLike | None = None) -> dict:
        """What a results file depends on, for its sidecar (replay and staleness): the
        chain, cameras and histograms files (paths relative to the folder ``base`` when
        given, and content hashes), the views and the camera each uses, axes, markers,
        seed and every annealing parameter."""
        def where(path: Path) -> str:
            return relative_path(path, base) if base is not None else str(path)

        sig = {
            "chain": where(self.chain_path), "chain_sha256": file_sha256(self.chain_path),
            "cameras": where(self.cameras_path),
            "cameras_sha256": file_sha256(self.cameras_path),
            "views": self.view_names,
            "view_cameras": {view: cam.name for view, cam in self.cameras.items()},
            "axes": self.body.axis_labels,
            "markers": len(self.body.marker_names), "seed": self.params.seed,
            **({"view_markers": self.view_markers} if self.view_markers else {}),
            "anneal": _jsonable(self.params.to_dict()),
        }
        if self.histograms_path is not None:
            sig["histograms"] = where(self.histograms_path)
            sig["histograms_sha256"] = file_sha256(self.histograms_path)
        return sig

    def inputs(self) -> dict[Path, str]:
        """The files the model was read from, by what they are (never overwritten)."""
        found = {self.chain_path: "the chain", self.cameras_path: "the camera file"}
        if self.histograms_path is not None:
            found[self.histograms_path] = "the histogram archive"
        return found


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


#: The marker cap (px) of the 2D keypoint route unless a project sets ``cap_px``: 10 px (the
#: defaults, for blobs matched to their nearest marker) misses half the frames of the
#: synthetic keypoint session, 30 px fits them (bench/bench_markerless.py).
KEYPOINT_CAP_PX = 30.0


def anneal_params(config, **overrides) -> AnnealParams:
    """:class:`AnnealParams` from the ``[anneal]`` section, with overrides (None: keep;
    ``profile`` replaces the section's profile)."""
    given = {k: v for k, v in overrides.items() if v is not None}
    table = dict(config["anneal"])
    if "profile" in given:
        table["profile"] = given.pop("profile")
    set_keys = config.keys_given.get("anneal", ())
    params = anneal_from_table(table, set_keys, file=config.path)
    keypoints = config["keypoints"]
    if (keypoints.get("files") and keypoints.get("route") == "2d" and "cap_px" not in set_keys
            and params.error.cap_px is not None):
        # labelled keypoints: a frame starting far from its posture sees every keypoint
        # beyond a blob-sized cap and the annealing loses its way (docs/benchmarks.md)
        params = replace(params, error=replace(params.error, cap_px=KEYPOINT_CAP_PX))
    if "n_end" in given and "n_l" not in given and "n_tau" not in given:
        # a shorter schedule keeps the paper's proportions (Sect. 3.2 sensitivity analysis)
        params = params.with_schedule(given.pop("n_end"))
    return replace(params, **given) if given else params


def load_model(config, **overrides) -> ProjectModel:
    """Chain (+ archive), cameras of the views and annealing parameters of a project."""
    from kinematics.camera_io import load_cameras
    from kinematics.chain_xml import load_body
    from kinematics.histogram_xml import apply_archive, load_archive

    chain_path = config["chain"]["path"]
    if not chain_path:
        raise VideoTrackError("no chain file: set [chain] path", file=config.path,
                              field="chain.path")
    cameras_path = config["cameras"]["path"]
    if not cameras_path:
        raise VideoTrackError("no camera file: set [cameras] path", file=config.path,
                              field="cameras.path")
    body = load_body(chain_path)
    hist_path = config["chain"]["histograms"] or None
    if hist_path:
        body = apply_archive(body, load_archive(hist_path))
    all_cameras = load_cameras(cameras_path)
    views = config["views"]
    if not views and is_markerless(config):  # keypoint files: one per camera, in file order
        views = [{"name": name, "camera": name} for name in all_cameras]
    cameras, shown = {}, {}
    for i, view in enumerate(views):
        name = view["camera"] or view["name"]
        if name not in all_cameras:
            raise VideoTrackError(f"camera '{name}' is not in {cameras_path} (it has "
                                  f"{', '.join(all_cameras)})", file=config.path,
                                  field=f"views[{i}].camera")
        cameras[view["name"]] = all_cameras[name]
        patterns = view.get("model_markers") or []
        if patterns:
            shown[view["name"]] = markers_matching(patterns, body.marker_names, config.path,
                                                   f"views[{i}].model_markers")
    if not cameras:
        raise VideoTrackError("no views: add [[views]] tables", file=config.path, field="views")
    if shown and len(shown) == len(cameras):  # every view lists its markers: any left out?
        nowhere = [m for m in body.marker_names if not any(m in s for s in shown.values())]
        if nowhere:
            warnings.warn(f"{config.path}: views.model_markers: no view shows "
                          f"{', '.join(nowhere)}; the fit never places them",
                          VideoTrackWarning, stacklevel=2)
    return ProjectModel(body, cameras, anneal_params(config, **overrides), Path(chain_path),
                        Path(cameras_path), Path(hist_path) if hist_path else None, shown)



def default_results_path(config, detections_path: Path) -> Path:
    """``[fit] results``, else ``<detections name>.results.csv`` beside the detections."""
    given = config["fit"]["results"]
    if given:
        return Path(given)
    name = detections_path.name.removesuffix(".npz").removesuffix(".detections")
    return detections_path.with_name(f"{name}.results.csv")


def default_plot_path(results_path: Path) -> Path:
    """The angle plot of a results file: ``<results>.png``."""
    return Path(results_path).with_suffix(".png")


def _partial_path(results_path: Path) -> Path:
    return results_path.with_name(results_path.name + ".partial")


def checkpoint_paths(results_path: Path) -> tuple[Path, ...]:
    """The checkpoint of an unfinished fit, its sidecar and its candidates file."""
    partial = _partial_path(Path(results_path))
    return partial, partial.with_name(partial.name + ".json"), candidates_path(partial)


def discard_checkpoint(results_path: Path) -> None:
    """Remove the checkpoint of a fit whose results file is complete."""
    for p in checkpoint_paths(results_path):
        with contextlib.suppress(FileNotFoundError):
            os.unlink(p)


def check_detection_views(model: ProjectModel, detections, detections_path: Path) -> None:
    """Refuse detections whose views are not the project's (detect again)."""
    if list(detections.view_names) != model.view_names:
        raise VideoTrackError(f"detections are for views {detections.view_names}, the project "
                              f"has {model.view_names}: detect again", file=detections_path)
    meta = getattr(detections, "metadata", None) or {}
    if "settings" in meta and "videos" in meta:  # each view against its camera's image size
        from videotrack.views import View, check_camera_sizes

        check_camera_sizes([View.from_dict(v) for v in meta["settings"]["views"]],
                           [(v["width"], v["height"]) for v in meta["videos"]], model.cameras)


def results_sidecar(model: ProjectModel, detections_path: Path | KeypointInput,
                    results_path: str | os.PathLike | None = None) -> dict:
    """What a results file records about its inputs and parameters (its sidecar, less the
    rows, the warnings and the CSV's own hash): chain, cameras and detections (or, given a
    :class:`~videotrack.markerless.KeypointInput`, the keypoint files and settings) with
    their hashes, views and their cameras, axes, seed and every annealing parameter. Paths
    are relative to the folder of ``results_path`` when given (so the project can move)."""
    base = None if results_path is None else Path(results_path).absolute().parent
    if isinstance(detections_path, KeypointInput):
        return {**model.signature(base), **detections_path.sidecar(base)}
    where = str(detections_path) if base is None else relative_path(detections_path, base)
    return {**model.signature(base), "detections": where,
            "detections_sha256": file_sha256(detections_path)}


def threshold_entry(results) -> dict:
    """The sidecar's ``threshold``: the re-analysis threshold that decided the statuses of
    these results (measured on the video with the defaults), so a front end that opens them
    shows the same bar; empty when no result came from a fit."""
    used = [r.threshold for r in results if np.isfinite(r.threshold)]
    return {"threshold": float(used[-1])} if used else {}


def changed_inputs(meta: Mapping, expected: Mapping) -> list[str]:
    """The inputs and parameters (:data:`IDENTITY_KEYS`) in which a sidecar ``meta``
    differs from ``expected``, named as ``changed: ...`` lists them."""
    expected = _jsonable(dict(expected))
    return list(dict.fromkeys(
        _KEY_NAMES.get(k, k.removesuffix("_sha256")) for k in IDENTITY_KEYS
        if meta.get(k) != expected.get(k)))


def results_stale_reason(model: ProjectModel, detections_path: Path | KeypointInput,
                         results_path: Path,
                         n_rows: int) -> str | None:
    """Why ``results_path`` is not the complete fit of these detections with this model, or
    None when it is up to date (same inputs by content hash, same parameters, ``n_rows``
    rows, and a CSV matching its sidecar: a write cut between the two is caught). Where the
    files are does not matter."""
    results_path = Path(results_path)
    if not results_path.exists():
        return "no results yet"
    try:
        meta = read_sidecar(results_path)
    except VideoTrackError as err:
        return err.message
    if not meta:
        return "no sidecar"
    changed = changed_inputs(meta, results_sidecar(model, detections_path))
    if changed:
        return "changed: " + ", ".join(changed)
    if meta.get("rows") != n_rows:
        return f"{meta.get('rows')} rows, {n_rows} wanted"
    if meta.get("csv_sha256") != file_sha256(results_path):
        return "the results file does not match its sidecar"
    return None


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
    partial = _partial_path(results_path)
    done, threshold = _resume(partial, sidecar) if model.params.start == "mean" else ({}, None)
    done = _resumable(done, idx, model.params)
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
    if stream is not None and not done and frames is None:
        gen = stream.results(len(todo))
    else:
        gen = fitter.iter_fit(observed, todo, previous=previous) if todo.size else iter(())
    with contextlib.closing(gen):
        for r in gen:
            results[r.frame] = r
            if progress is not None:
                progress(r)
            if time.monotonic() - last > CHECKPOINT_SECONDS and model.params.start == "mean":
                _checkpoint(partial, model, results, detections, sidecar)
                last = time.monotonic()
    ordered = [results[int(f)] for f in idx]
    table = results_from_fit(model.body, ordered, model.view_names, detections)
    base = results_path.absolute().parent
    found = [relative_message(w, base) for w in (*notes, *fit_warnings(table, detections))]
    write_results(results_path, table, {**sidecar, **threshold_entry(ordered),
                                        "warnings": list(dict.fromkeys(found))})
    write_candidates(results_path, model.body, ordered)
    discard_checkpoint(results_path)
    return table


#: Records handed to the fitting thread at a time while detecting; None: four times as many
#: as fill the lanes of every thread (:meth:`Fitter.lane_frames`). 64 (when 'auto' wanted
#: full lanes) left the streamed fit to the scalar kernel, 2-2.5x slower than the lanes; 128
#: filled them once, and each block's last runs and re-analyses ran in half-empty lanes
#: (2 threads, docs/benchmarks.md "End to end": Table 1 schedule 576 frames/s with 128,
#: 734 with 256, 696 with 512; short schedule 897, 1038, 1084).
STREAM_CHUNK: int | None = None


def not_streamable(model: ProjectModel) -> str | None:
    """Why a project's records cannot be fitted while later ones are still being detected
    (the fit of a record would then differ from fitting all records at once), or None when
    they can: each record is fitted on its own, from its own random streams."""
    p = model.params
    if p.candidates > 1:
        return "candidates > 1: the path through time looks 32 frames ahead"
    if p.threshold_mode != "absolute":
        return f"threshold_mode {p.threshold_mode!r}: measured on frames of the whole video"
    if p.start != "mean":
        return f"start {p.start!r}: a frame starts from the one before"
    if any(c.root.mode != "fixed" for c in model.body.chains):
        return "a root that is tracked or placed from the detections"
    if model.fitter().match_measured:
        return "match 'auto': decided on the detections of the whole video"
    return None


class FitAlongside:
    """Fits records in a thread of its own while the caller detects the next ones.

    Decoding (in FFmpeg's threads, or threads decoding MJPEG packets) and detection run in
    the caller's thread, annealing (numba kernels that release the GIL) in this one, so the
    two overlap and the slower sets the pace. Detection stays in the caller's thread because
    the warnings it records into the detections file are caught with
    :func:`warnings.catch_warnings`, which is process-wide, and because progress and cancel
    belong to the caller.

    Give it every record with :meth:`add` as it is detected, then take the results in record
    order with :meth:`results`; :meth:`close` (or leaving the ``with`` block) stops the thread
    and drops what it fitted. Only for models where :func:`not_streamable` is None: the
    results are then those of one :meth:`Fitter.iter_fit` over all records.
    """

    def __init__(self, model: ProjectModel, chunk: int | None = None) -> None:
        import numba

        self.fitter = model.fitter()
        self.n_views = len(model.view_names)
        self.chunk = chunk or STREAM_CHUNK or 4 * self.fitter.lane_frames()
        self.started = time.perf_counter()
        self._threads = numba.get_num_threads()  # numba's setting is per thread
        self._gathered: list[tuple[np.ndarray, ...]] = []
        self._added = 0  # records handed to the thread
        # unbounded: records are small, and the detection should never wait for the fit
        self._todo: queue.SimpleQueue = queue.SimpleQueue()
        self._done: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._work, name="videotrack-fit", daemon=True)
        self._thread.start()

    def add(self, record) -> None:
        """A detected record (:class:`videotrack.detect.FrameDetections`), the next in order."""
        self._gathered.append(record.points)
        if len(self._gathered) >= self.chunk:
            self._hand_on()

    def results(self, n: int) -> Iterator[FrameResult]:
        """The results of the ``n`` records added (all of them), in order, as they come."""
        self._hand_on()
        self._todo.put(None)
        if n != self._added:
            raise RuntimeError(f"{n} records to fit, {self._added} were detected")
        for _ in range(n):
            item = self._done.get()
            if isinstance(item, BaseException):
                raise item
            yield item

    def close(self) -> None:
        self._stop.set()
        self._todo.put(None)
        self._thread.join()

    def __enter__(self) -> FitAlongside:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _hand_on(self) -> None:
        if self._gathered:
            self._todo.put((self._added, self._gathered))
            self._added += len(self._gathered)
            self._gathered = []

    def _work(self) -> None:
        import numba

        numba.set_num_threads(self._threads)
        try:
            while (item := self._todo.get()) is not None and not self._stop.is_set():
                first, records = item
                gen = self.fitter.iter_fit(_records(first, records, self.n_views),
                                           range(first, first + len(records)),
                                           cancel=self._stop.is_set)
                with contextlib.closing(gen):
                    for r in gen:
                        if self._stop.is_set():
                            return
                        self._done.put(r)
        except BaseException as err:  # raised again in the caller's thread by results()
            self._done.put(err)


class _Records(NamedTuple):
    points: np.ndarray
    offsets: np.ndarray


def _records(first: int, records: list[tuple[np.ndarray, ...]], n_views: int) -> _Records:
    """Records ``first, first + 1, ...`` (per-view points each) as detections the fitter
    takes, preceded by ``first`` empty records: a record's random streams are keyed by its
    index, so it must keep it, and the empty ones are not fitted."""
    views = [v for rec in records for v in rec]
    offsets = np.zeros((first + len(records)) * n_views + 1, np.int64)
    np.cumsum([len(v) for v in views], out=offsets[first * n_views + 1:])
    points = np.concatenate(views).astype(np.float64).reshape(-1, 2) if views else \
        np.empty((0, 2))
    return _Records(points, offsets)


def _source(detections, detections_path: Path | None) -> Path | KeypointInput:
    """What results are fitted from, as their sidecar names it: the keypoints of a
    markerless project, else the detections file."""
    return detections if isinstance(detections, KeypointInput) else detections_path


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
            found.append(f"{failed.size} of {n} frames ({100 * failed.size / n:.1f} %) were "
                         f"not fitted ({what}): video frames {_listing(frames)}")
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


def _listing(values: Sequence[int], most: int = 8) -> str:
    shown = ", ".join(str(v) for v in values[:most])
    return shown + (f", ... ({len(values)} in all)" if len(values) > most else "")


def _checkpoint(partial: Path, model: ProjectModel, results: dict, detections, sidecar):
    ordered = [results[k] for k in sorted(results)]
    # candidates first: a checkpoint's results never go without them
    write_candidates(partial, model.body, ordered)
    write_results(partial, results_from_fit(model.body, ordered, model.view_names, detections),
                  {**sidecar, **threshold_entry(ordered)})


def _resume(partial: Path, sidecar: dict) -> tuple[dict[int, FrameResult], float | None]:
    """Frames of a checkpoint made with the same inputs and parameters ({} otherwise), and
    the re-analysis threshold that judged them (None if it has none)."""
    if not partial.exists():
        return {}, None
    try:
        meta = read_sidecar(partial)
        if changed_inputs(meta, sidecar):
            return {}, None
        table = read_results(partial)
        threshold = meta.get("threshold")
        usable = (isinstance(threshold, int | float) and not isinstance(threshold, bool)
                  and 0 < threshold < float("inf"))  # else measured again
        return (attach_candidates(frame_results(table, int(meta["seed"])), partial),
                float(threshold) if usable else None)
    except VideoTrackError:
        return {}, None


def _resumable(done: dict[int, FrameResult], idx: np.ndarray,
               params: AnnealParams) -> dict[int, FrameResult]:
    """The checkpoint's frames a resumed fit keeps: those of ``idx``; with the path through
    time (``candidates`` > 1), only the leading whole windows' (multiples of
    ``anneal.PATH_LAG`` frames of ``idx``, all kept), so the rest is decided in the windows
    the whole fit decided it in."""
    wanted = set(idx.tolist())
    done = {k: r for k, r in done.items() if k in wanted}
    if params.candidates <= 1 or not done:
        return done
    lead = next((i for i, f in enumerate(idx) if int(f) not in done), len(idx))
    keep = lead - lead % anneal.PATH_LAG
    return {int(f): done[int(f)] for f in idx[:keep]}


# -- the workflow -----------------------------------------------------------------------------
#: The steps of :func:`run_project`, as :attr:`ProjectRun.steps` and
#: :attr:`StepProgress.step` name them.
DETECT, FIT, PLOT = "detect", "fit", "plot"


class Cancelled(Exception):
    """:func:`run_project` stopped because its ``cancel`` callback asked it to (a fit keeps
    its last checkpoint and resumes from it)."""


@dataclass(frozen=True)
class StepProgress:
    """Where a step of :func:`run_project` stands: ``done`` of ``total`` video frames
    (``"detect"``) or records (``"fit"``); ``bad`` counts fitted records that are not ok."""

    step: str
    done: int
    total: int
    bad: int = 0


@dataclass(frozen=True)
class ProjectRun:
    """What :func:`run_project` did.

    Attributes
    ----------
    detections_path, results_path : Path
        (``detections_path`` is None for a project fitted to keypoint files)
    steps : tuple of str
        What was computed: ``"detect"``, ``"fit"``, ``"plot"`` (none: all was up to date).
    fit_reason : str
        Why the fit ran (``"no results yet"``, ``"changed: seed"``, ``"--force"``,
        ``"records 0:100"``); ``""`` when it did not.
    plot_path : Path or None
        The plot this run wrote.
    n_frames, n_ok, n_bad : int
        Rows of the results; those whose fit is ok (ok, re-analysed, corrected) and the
        others (failed, no detections).
    detect_seconds, fit_seconds : float
        Time spent detecting and fitting (0 for a step that was skipped).
    warnings : tuple of str
        Messages of the :class:`~videotrack.errors.VideoTrackWarning` s of the run, and
        those stored with the detections and the results when these were up to date (so
        a warning is reported by every run, not only the one that met it); paths relative
        to the results' folder.
    incomplete : str
        Why the results are incomplete, or ``""``: the video(s) could not be read to the
        end (truncated, an unreadable image), or not one frame was fitted.
    resumed : int
        Frames kept from the checkpoint of an interrupted fit (0: none).
    overlapped : bool
        The records were fitted while the next ones were being detected
        (:class:`FitAlongside`); ``fit_seconds`` then counts from the detection's start.
    model, detections, results
        The model, the detections and the results table (model and results are None with
        ``fit=False``).
    """

    detections_path: Path | None
    results_path: Path
    steps: tuple[str, ...] = ()
    fit_reason: str = ""
    plot_path: Path | None = None
    n_frames: int = 0
    n_ok: int = 0
    n_bad: int = 0
    detect_seconds: float = 0.0
    fit_seconds: float = 0.0
    warnings: tuple[str, ...] = ()
    incomplete: str = ""
    resumed: int = 0
    overlapped: bool = False
    model: ProjectModel | None = field(default=None, repr=False, compare=False)
    detections: object = field(default=None, repr=False, compare=False)
    results: Results | None = field(default=None, repr=False, compare=False)

    @property
    def detected(self) -> bool:
        """The detections were made by this run (else they were up to date)."""
        return DETECT in self.steps

    @property
    def fitted(self) -> bool:
        """The results were fitted by this run (else they were up to date)."""
        return FIT in self.steps

    @property
    def up_to_date(self) -> bool:
        """Nothing had to be computed."""
        return not self.steps


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
    from videotrack.detect import default_output, detection_inputs

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
    from videotrack.markerless import default_results_path as keypoints_results_path
    from videotrack.markerless import keypoint_inputs

    results_path = (Path(results) if results is not None else
                    keypoints_results_path(config))
    _guard(config, model, None, results_path, detect=False, fit=True, plot=plot,
           force=force, results_given=results is not None, inputs=keypoint_inputs(config))
    return ProjectRun(None, results_path)


def _guard(config, model, det_out: Path | None, results_path: Path, *, detect: bool,
           fit: bool,
           plot: bool, force: bool, results_given: bool, inputs: dict) -> None:
    """Refuse outputs that are inputs, or existing files of another kind (unless force),
    before any work is done (:func:`videotrack.outputs.guard_outputs`)."""
    from videotrack.outputs import guard_outputs
    from videotrack.results import sidecar_path

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


def _reported(run: ProjectRun, caught: Sequence[str]) -> ProjectRun:
    """The run with its warnings (this run's, and those stored with its detections and
    results) and why it is incomplete."""
    from videotrack.detect import incomplete_reason

    base = run.results_path.absolute().parent
    stored = list(run.detections.metadata.get("warnings", [])) if run.detections else []
    if run.results is not None:
        with contextlib.suppress(VideoTrackError):
            stored += read_sidecar(run.results_path).get("warnings", [])
    found = [relative_message(w, base) for w in (*caught, *stored)]
    why = [incomplete_reason(run.detections)] if run.detections is not None else []
    if run.results is not None and run.n_frames and not run.n_ok:
        why.append(f"not one of the {run.n_frames} frames was fitted")
    return replace(run, warnings=tuple(dict.fromkeys(found)),
                   incomplete="; ".join(w for w in why if w))


def plan_project(config, *, force: bool = False, plot: bool | None = None) -> tuple[str, str]:
    """What :func:`run_project` would do, without doing it: ``(action, why)``.

    Actions: ``"detect + fit"``, ``"fit"``, ``"plot"``, ``"up to date"``. Reads the videos'
    headers, the detections and the results' sidecars; writes nothing.

    Raises
    ------
    LocatedError
        What would make the run fail (config, video, chain, cameras, views).
    """
    from videotrack.detect import default_output, detection_inputs, detections_status

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


def load_fresh_detections(config, path: str | os.PathLike):
    """The detections file ``path`` of a project, refused when missing or made from other
    video(s) or with other detection settings (a missing video is only a warning)."""
    from videotrack.detect import settings_from_config, video_paths
    from videotrack.detections import check_fresh, load_detections
    from videotrack.video import open_videos

    path = Path(path)
    if not path.exists():
        raise VideoTrackError("no detections yet: run 'videotrack detect' first (or use "
                              "'videotrack run')", file=path)
    detections = load_detections(path)
    videos = video_paths(config)
    if not all(p.exists() for p in videos):
        warnings.warn(f"{videos[0]}: video not found; cannot check that {path.name} was "
                      "made from it", VideoTrackWarning, stacklevel=2)
        return detections
    with open_videos(videos) as opened:
        try:
            check_fresh(detections, opened, settings_from_config(config))
        except VideoTrackError as err:  # said once: "stale detections: <why>; <what to do>"
            why = err.message.removeprefix("stale detections: ").split("; run ")[0]
            raise VideoTrackError(f"stale detections: {why}; run 'videotrack detect' again "
                                  "(or 'videotrack run')", file=path) from None
    return detections


def _reporter(progress, cancel) -> Callable[..., None]:
    """``report(step, done, total, bad=0)``: hand on the progress, then honour a cancel."""
    def report(step: str, done: int, total: int, bad: int = 0) -> None:
        if progress is not None:
            progress(StepProgress(step, done, total, bad))
        if cancel is not None and cancel():
            raise Cancelled
    return report


@contextlib.contextmanager
def _recorded_warnings(pass_on: bool = False):
    """Collect the messages of VideoTrack's warnings into the yielded list (once the block
    has ended); other warnings, and all of a block that raises, are passed on (with
    ``pass_on`` VideoTrack's too, after being collected)."""
    kept: list[str] = []
    caught: list = []
    ok = False
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", VideoTrackWarning)
            yield kept
            ok = True
    finally:
        for w in caught:
            mine = issubclass(w.category, VideoTrackWarning)
            if ok and mine:
                kept.append(str(w.message))
            if not (ok and mine) or pass_on:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _detections(config, detect: bool, force: bool, report, log, each=None):
    """``(detections, path, made now)``: detected when stale (or forced), else as on disk;
    ``each`` gets every record detected (:func:`~videotrack.detect.detect_project`)."""
    from videotrack.detect import default_output, detect_project

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


def _fit(run: ProjectRun, model: ProjectModel, frames: slice | None, force: bool,
         threads: int, report, log, notes: Sequence[str] = (),
         stream: FitAlongside | None = None) -> ProjectRun:
    """The fit step: results read when up to date, else fitted and written (taking the
    results of ``stream``, which fitted the records while they were detected)."""
    import numba

    detections, out = run.detections, run.results_path
    check_detection_views(model, detections, run.detections_path)
    n = detections.n_records
    idx = None if frames is None else range(*frames.indices(n))
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


def _with_results(run: ProjectRun, table: Results) -> ProjectRun:
    n_ok = int(table.ok_mask().sum())
    return replace(run, results=table, n_frames=len(table), n_ok=n_ok,
                   n_bad=len(table) - n_ok)


def _plot(run: ProjectRun, wanted: bool) -> ProjectRun:
    """The angle plot, when wanted and missing or older than the results."""
    png = default_plot_path(run.results_path)
    if not wanted or not (run.fitted or _older(png, run.results_path)):
        return run
    from videotrack.plots import plot_angles

    png = plot_angles(run.results, png, run.model.body.locked_mask())
    return replace(run, steps=(*run.steps, PLOT), plot_path=Path(png))


def _older(path: Path, than: Path) -> bool:
    """True when ``path`` is missing or older than ``than`` (e.g. a plot of earlier results)."""
    return not path.exists() or path.stat().st_mtime_ns < than.stat().st_mtime_ns
