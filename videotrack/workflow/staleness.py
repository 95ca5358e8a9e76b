"""Up-to-date checks: whether results (and the detections, and a plot) are those of the
project's inputs and parameters.

Identity: the results sidecar names its inputs by paths relative to the results file's
folder and identifies them by content hash (:mod:`videotrack.project.identity`); only the hashes and
the parameters decide whether results are up to date (:data:`IDENTITY_KEYS`), so a project
copied or moved elsewhere stays up to date and a changed input of the same size does not.

The markerless route: a project whose ``[keypoints] files`` are set has no detections; the
sidecar records its keypoint files (a :class:`~videotrack.markerless.route.KeypointInput`) by
content hash and the ``[keypoints]`` settings instead of the detections file.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.markerless.route import KeypointInput
from videotrack.project.identity import relative_path
from videotrack.results.files import candidates_path, file_sha256, read_sidecar
from videotrack.workflow.model import ProjectModel, _jsonable

#: Sidecar keys that decide whether results are up to date (inputs by content hash, and
#: every parameter), in the order ``changed: ...`` lists them; paths are not among them.
IDENTITY_KEYS = ("chain_sha256", "cameras_sha256", "histograms_sha256", "views",
                 "view_cameras", "view_markers", "axes", "markers", "seed", "anneal",
                 "detections_sha256", "keypoints_sha256", "keypoints_options")
_KEY_NAMES = {"view_cameras": "view cameras", "view_markers": "the markers views show",
              "keypoints_options": "keypoint settings"}


def results_sidecar(model: ProjectModel, detections_path: Path | KeypointInput,
                    results_path: str | os.PathLike | None = None) -> dict:
    """What a results file records about its inputs and parameters (its sidecar, less the
    rows, the warnings and the CSV's own hash): chain, cameras and detections (or, given a
    :class:`~videotrack.markerless.route.KeypointInput`, the keypoint files and settings) with
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
    if "candidates_sha256" in meta:  # (sidecars of earlier versions do not record it)
        found = candidates_path(results_path)
        if meta["candidates_sha256"] != (file_sha256(found) if found.exists() else None):
            return "the candidates file does not match the results"
    return None


def _source(detections, detections_path: Path | None) -> Path | KeypointInput:
    """What results are fitted from, as their sidecar names it: the keypoints of a
    markerless project, else the detections file."""
    return detections if isinstance(detections, KeypointInput) else detections_path


def load_fresh_detections(config, path: str | os.PathLike):
    """The detections file ``path`` of a project, refused when missing or made from other
    video(s) or with other detection settings (a missing video is only a warning)."""
    from videotrack.detect.detections import check_fresh, load_detections
    from videotrack.detect.run import settings_from_config, video_paths
    from videotrack.detect.video import open_videos

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


def _older(path: Path, than: Path) -> bool:
    """True when ``path`` is missing or older than ``than`` (e.g. a plot of earlier results)."""
    return not path.exists() or path.stat().st_mtime_ns < than.stat().st_mtime_ns
