"""The GUI's one door to the fitter, the results files and the project model (no Qt).

Everything the GUI uses from :mod:`kinematics.fit`, :mod:`videotrack.workflow` and
:mod:`videotrack.results.files` goes through this module, so a rename there is a one-line change
here. Nothing in it computes anything itself: it forwards and converts. Detecting markers is
the project workflow :func:`videotrack.workflow.run.run_project` without its fit; fitting is
interactive (frames chosen, results shown as they arrive, undoable) and saved by
:func:`save_project_results`.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from kinematics.errors import LocatedError
from kinematics.fit import (
    AnnealParams,
    Fitter,
    FrameResult,
    Status,
    concurrent_fits,  # noqa: F401 (whether two fits may run at once)
)
from kinematics.fit import unseen_markers as _unseen_markers
from kinematics.model import Body
from kinematics.observe.observations import Observations
from ui.adapters import frame_detections
from videotrack.markerless.route import (
    KeypointInput,
    MappedKeypoints,
    fitting_model,
    is_markerless,
    keypoint_input,
    read_mapped_keypoints,
)
from videotrack.project.folders import command_config, trial_outputs
from videotrack.results.files import (
    STATUSES,
    attach_candidates,
    frame_results,
    read_results,
    read_sidecar,
    results_from_fit,
)
from videotrack.results.files import write_results as _write_results
from videotrack.workflow import (
    Cancelled,
    ProjectModel,
    ProjectRun,
    anneal_params,
    check_detection_views,
    load_model,
    results_sidecar,
    run_project,
    threshold_entry,
)

__all__ = [
    "STATUSES",
    "AnnealParams",
    "Cancelled",
    "Fitter",
    "FrameResult",
    "KeypointInput",
    "MappedKeypoints",
    "ProjectModel",
    "ProjectRun",
    "anneal_params",
    "attach_candidates",
    "check_detection_views",
    "detect_markers",
    "fitting_model",
    "frame_input",
    "frame_results",
    "has_observations",
    "is_markerless",
    "keypoint_input",
    "load_model",
    "load_project_config",
    "output_paths",
    "posture_error",
    "read_mapped_keypoints",
    "read_project_results",
    "recorded_noise",
    "save_project_results",
    "unseen_markers",
    "with_status",
]

#: Status of a frame whose posture was set by hand (the results files know it).
CORRECTED = Status.CORRECTED


def unseen_markers(view_markers: Mapping, view_names, marker_names) -> np.ndarray:
    """(n_views, n_markers) bool: the markers a view does not show (``[[views]]
    model_markers``), all False when every view shows every marker."""
    out = _unseen_markers(view_markers, list(view_names), list(marker_names))
    return np.zeros((len(view_names), len(marker_names)), bool) if out is None else out


def detect_markers(config, progress: Callable[[int, int], object],
                   cancel: Callable[[], bool]) -> ProjectRun:
    """Detect the markers of a project (or trial) and save the detections file: the
    project workflow without its fit, run although the file is up to date (the user asked).

    ``progress(done, total)`` follows the video frames; when ``cancel()`` returns True the
    run raises :class:`Cancelled`. The run's ``detections``, ``detections_path`` and
    ``warnings`` are what the GUI shows.
    """
    return run_project(config, fit=False, force=True, cancel=cancel,
                       progress=lambda p: progress(p.done, p.total))


def fit_chunk_size() -> int:
    """Frames per parallel batch of a GUI fit: two per thread, so a cancel or a new result
    never waits long."""
    import numba

    return 2 * numba.get_num_threads()


def manual_result(frame: int, angles_deg, roots, error: float, error_per_view, seed: int
                  ) -> FrameResult:
    """A :data:`CORRECTED` result for a posture set by hand without re-fitting."""
    return FrameResult(frame=int(frame), angles_deg=np.asarray(angles_deg, float),
                       error=float(error), error_per_view=np.asarray(error_per_view, float),
                       runs=0, iterations=0, seed=int(seed), status=CORRECTED,
                       root_positions=np.asarray(roots, float))


def iter_fit(fitter: Fitter, detections, frames: Sequence[int], chunk_size: int,
             cancel=None) -> Iterator[FrameResult]:
    """The fitter's generator over ``frames``; ``cancel`` (asked before each chunk) or
    closing it stops it between chunks."""
    return fitter.iter_fit(detections, np.asarray(frames, dtype=np.int64),
                           chunk_size=chunk_size, cancel=cancel)


def with_status(result: FrameResult, status: str) -> FrameResult:
    """A copy of ``result`` with another status (e.g. :data:`CORRECTED`)."""
    return replace(result, status=status)


def load_project_config(path: str | os.PathLike, trial: str | None = None):
    """A project file, or with ``trial`` the merged config of that trial of the project
    folder ``path`` (as ``videotrack fit PATH --trial NAME``)."""
    return command_config(path, trial)


def output_paths(config) -> tuple[Path | None, Path]:
    """Where the project's (or trial's) detections and results files live (no detections
    for a project of keypoint files)."""
    if is_markerless(config):
        from videotrack.markerless.route import default_results_path

        return None, default_results_path(config)
    outputs = trial_outputs(config)
    return outputs.detections, outputs.results


def frame_input(data, record: int, n_views: int):
    """What the fitter takes for one record of ``data``: the detected points of each view
    (detections), or that record's :class:`Observations` (keypoints, 3D points)."""
    if not isinstance(data, Observations):
        return frame_detections(data, record, n_views)
    return data.take([record])


def has_observations(frame) -> bool:
    """Whether one record's fitting input (:func:`frame_input`) observes anything."""
    if not isinstance(frame, Observations):
        return any(len(d) for d in frame)
    if frame.kind == "points3d":
        return bool((frame.points3d[..., 3] > 0).any())
    return bool((frame.conf > 0).any())


def posture_error(fitter: Fitter, angles_deg, frame, root_positions=None
                  ) -> tuple[float, np.ndarray]:
    """E of a posture for one record's fitting input (:func:`frame_input`) and E per view
    (none for 3D points): the objective the fit uses (Eq. 5 for detections)."""
    error, per_view = fitter.error(angles_deg, frame, root_positions)
    if isinstance(frame, Observations) and frame.kind == "points3d":
        return error, np.empty(0)
    return error, per_view


def read_project_results(path: str | os.PathLike, body: Body,
                         view_names: Sequence[str]) -> dict[int, FrameResult]:
    """Read a results file made for ``body`` and these views.

    Raises
    ------
    VideoTrackError
        Unreadable file, or axes or views that are not the project's.
    """
    from videotrack.errors import VideoTrackError

    table = read_results(path)
    if list(table.axis_labels) != body.axis_labels:
        raise VideoTrackError(f"results are for the axes {list(table.axis_labels)}, the chain "
                              f"has {body.axis_labels}", file=path)
    if list(table.view_names) != list(view_names):
        raise VideoTrackError(f"results are for the views {list(table.view_names)}, the "
                              f"project has {list(view_names)}", file=path)
    sidecar = read_sidecar(path)
    results = frame_results(table, int(sidecar.get("seed", 0)))
    threshold = sidecar.get("threshold")  # the one that decided the statuses
    if isinstance(threshold, int | float) and np.isfinite(threshold):
        results = {k: replace(r, threshold=float(threshold)) for k, r in results.items()}
    return results


def save_project_results(path: str | os.PathLike, model: ProjectModel, body: Body,
                         results: Mapping[int, FrameResult], detections,
                         detections_path: str | os.PathLike | None,
                         noise_px: Sequence[float] | None = None) -> Path:
    """Write the fitted frames (in frame order) and the sidecar, atomically.

    ``body`` is the session's chain (it may carry learned histograms or edits); the sidecar
    records the files of ``model`` as the command line does, so save the chain first.
    ``detections`` may be a :class:`KeypointInput` (with ``model`` the one it is fitted
    with, :func:`fitting_model`); the sidecar then records the keypoint files. ``noise_px``:
    σ per view of the noise model that judged the statuses (:func:`recorded_noise` reads it).
    """
    ordered = [results[k] for k in sorted(results)]
    table = results_from_fit(body, ordered, model.view_names, detections)
    source = detections if isinstance(detections, KeypointInput) else Path(detections_path)
    sidecar = {**results_sidecar(model, source), **threshold_entry(ordered),
               "source": "videotrack gui"}
    if noise_px:
        sidecar["noise"] = {"sigma_px": [float(s) for s in noise_px], "source": "measured"}
    return _write_results(path, table, sidecar, candidates=(body, ordered))


def recorded_noise(results_path: str | os.PathLike) -> list[float] | None:
    """σ per view of the noise model a results file's statuses were judged by (its sidecar's
    ``noise``), or None where it records none."""
    try:
        entry = read_sidecar(results_path).get("noise") or {}
    except LocatedError:
        return None
    sigma = entry.get("sigma_px") if isinstance(entry, dict) else None
    if not isinstance(sigma, list) or not sigma:
        return None
    try:
        return [float(s) for s in sigma]
    except (TypeError, ValueError):
        return None
