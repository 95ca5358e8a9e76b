"""Project-level fitting: from a project config and its detections to a results file.

Used by the ``fit``/``run`` commands and the GUI: the model (chain + histograms + cameras per
view + annealing parameters) is loaded once by :func:`load_model`; :func:`fit_project`
drives the fitter's generator with progress and resumable, atomic writing.

Resuming: while fitting, finished frames are checkpointed every few seconds to
``<results>.partial`` (with its own sidecar). A run that is killed and started again with the
same inputs and parameters keeps those frames and fits only the rest; the final file is the
same as an uninterrupted run's because frames are fitted independently from their own random
streams (with ``start = "previous"`` the checkpoint is not used).
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from kinematics.anneal import AnnealParams, Fitter, FrameResult
from kinematics.model import Body
from videotrack.config import record_from_table
from videotrack.errors import VideoTrackError
from videotrack.results import (
    Results,
    file_sha256,
    frame_results,
    read_results,
    read_sidecar,
    results_from_fit,
    write_results,
)

CHECKPOINT_SECONDS = 5.0


@dataclass(frozen=True)
class ProjectModel:
    """Everything the fitter needs from a project, loaded and checked."""

    body: Body
    cameras: dict  # view name -> camera, in the order of the views
    params: AnnealParams
    chain_path: Path
    cameras_path: Path
    histograms_path: Path | None

    @property
    def view_names(self) -> list[str]:
        return list(self.cameras)

    def fitter(self) -> Fitter:
        return Fitter(self.body, self.cameras, self.params)

    def signature(self) -> dict:
        """What a results file depends on, for its sidecar (replay and staleness)."""
        sig = {
            "chain": str(self.chain_path), "chain_sha256": file_sha256(self.chain_path),
            "cameras": str(self.cameras_path),
            "cameras_sha256": file_sha256(self.cameras_path),
            "views": self.view_names, "axes": self.body.axis_labels,
            "markers": len(self.body.marker_names), "seed": self.params.seed,
            "anneal": _jsonable(self.params.to_dict()),
        }
        if self.histograms_path is not None:
            sig["histograms"] = str(self.histograms_path)
            sig["histograms_sha256"] = file_sha256(self.histograms_path)
        return sig


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def anneal_params(config, **overrides) -> AnnealParams:
    """:class:`AnnealParams` from the ``[anneal]`` section, with overrides (None: keep)."""
    params = record_from_table(AnnealParams, config["anneal"], file=config.path,
                               where="anneal")
    given = {k: v for k, v in overrides.items() if v is not None}
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
    cameras = {}
    for i, view in enumerate(config["views"]):
        name = view["camera"] or view["name"]
        if name not in all_cameras:
            raise VideoTrackError(f"camera '{name}' is not in {cameras_path} (it has "
                                  f"{', '.join(all_cameras)})", file=config.path,
                                  field=f"views[{i}].camera")
        cameras[view["name"]] = all_cameras[name]
    if not cameras:
        raise VideoTrackError("no views: add [[views]] tables", file=config.path, field="views")
    return ProjectModel(body, cameras, anneal_params(config, **overrides), Path(chain_path),
                        Path(cameras_path), Path(hist_path) if hist_path else None)


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


def checkpoint_paths(results_path: Path) -> tuple[Path, Path]:
    """The checkpoint of an unfinished fit and its sidecar."""
    partial = _partial_path(Path(results_path))
    return partial, partial.with_name(partial.name + ".json")


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


def results_sidecar(model: ProjectModel, detections_path: Path) -> dict:
    """What a results file records about its inputs and parameters (its sidecar, less the
    rows and the CSV's own hash): chain, cameras and detections with their hashes, views,
    axes, seed and every annealing parameter."""
    return {**model.signature(), "detections": str(detections_path),
            "detections_sha256": file_sha256(detections_path)}


def results_stale_reason(model: ProjectModel, detections_path: Path, results_path: Path,
                         n_rows: int) -> str | None:
    """Why ``results_path`` is not the complete fit of these detections with this model, or
    None when it is up to date (same inputs by content hash, same parameters, ``n_rows``
    rows, and a CSV matching its sidecar: a write cut between the two is caught)."""
    results_path = Path(results_path)
    if not results_path.exists():
        return "no results yet"
    try:
        meta = read_sidecar(results_path)
    except VideoTrackError as err:
        return err.message
    if not meta:
        return "no sidecar"
    expected = _jsonable(results_sidecar(model, detections_path))
    changed = [k.removesuffix("_sha256") for k in expected if meta.get(k) != expected[k]]
    if changed:
        return "changed: " + ", ".join(dict.fromkeys(changed))
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
) -> Results:
    """Fit ``frames`` (default all records) and write the results file and its sidecar.

    ``progress`` is called with each frame's result as it arrives. Finished frames are
    checkpointed so an interrupted run resumes (see the module docstring).
    """
    fitter = model.fitter()
    idx = np.arange(detections.n_records) if frames is None else np.asarray(list(frames))
    sidecar = results_sidecar(model, detections_path)
    partial = _partial_path(results_path)
    done = _resume(partial, sidecar) if model.params.start == "mean" else {}
    for r in done.values():
        if progress is not None:
            progress(r)
    todo = np.array([f for f in idx if int(f) not in done], dtype=np.int64)
    results: dict[int, FrameResult] = dict(done)
    last = time.monotonic()
    gen = fitter.iter_fit(detections, todo) if todo.size else iter(())
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
    write_results(results_path, table, sidecar)
    discard_checkpoint(results_path)
    return table


def _checkpoint(partial: Path, model: ProjectModel, results: dict, detections, sidecar):
    ordered = [results[k] for k in sorted(results)]
    write_results(partial, results_from_fit(model.body, ordered, model.view_names, detections),
                  sidecar)


def _resume(partial: Path, sidecar: dict) -> dict[int, FrameResult]:
    """Frames of a checkpoint made with the same inputs and parameters ({} otherwise)."""
    if not partial.exists():
        return {}
    try:
        meta = read_sidecar(partial)
        if {k: meta.get(k) for k in sidecar} != _jsonable(sidecar):
            return {}
        table = read_results(partial)
    except VideoTrackError:
        return {}
    return frame_results(table, int(meta["seed"]))
