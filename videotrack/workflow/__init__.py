"""Project-level fitting: from a project config and its detections to a results file.

:func:`run_project` is the one workflow every front end runs (``fit``, ``run``, ``batch``,
``demo`` and the GUI); :func:`plan_project` says what it would do without doing it. The
package has one module per job:

- :mod:`~videotrack.workflow.run` — :func:`run_project` and :func:`plan_project`: detect when
  stale, fit when stale, plot, outputs checked against inputs before any work;
- :mod:`~videotrack.workflow.model` — :func:`load_model` and the :class:`ProjectModel` it
  returns (chain, cameras per view, annealing parameters), :func:`anneal_params`;
- :mod:`~videotrack.workflow.staleness` — up-to-date checks: the results sidecar's identity of
  inputs and parameters, :func:`results_stale_reason`, :func:`load_fresh_detections`;
- :mod:`~videotrack.workflow.fitting` — :func:`fit_project` (progress, resumable, atomic
  writing) and :func:`fit_warnings`;
- :mod:`~videotrack.workflow.checkpoint` — the checkpoints an interrupted fit resumes from;
- :mod:`~videotrack.workflow.streaming` — fitting while detecting (:class:`FitAlongside`);
- :mod:`~videotrack.workflow.report` — a run's steps, progress, :class:`Cancelled` and the
  :class:`ProjectRun` it returns;
- :mod:`~videotrack.workflow.plots` — the angle plot of a run's results;
- :mod:`~videotrack.workflow.calibrate` — :func:`calibrate_cameras` and
  :func:`convert_cameras` (``calibrate``);
- :mod:`~videotrack.workflow.triangulate` — :func:`triangulate_keypoints` (``triangulate``);
- :mod:`~videotrack.workflow.synthesize` — :func:`synthesize` (``synth``).

The settings :data:`~videotrack.workflow.checkpoint.CHECKPOINT_SECONDS` and
:data:`~videotrack.workflow.streaming.STREAM_CHUNK` are read from their own modules when used:
to change them, set them there (the names exported here are copies).
"""

from videotrack.workflow.calibrate import (
    Calibrated,
    Converted,
    Outputs,
    Refinement,
    calibrate_cameras,
    convert_cameras,
)
from videotrack.workflow.checkpoint import CHECKPOINT_SECONDS, checkpoint_paths, discard_checkpoint
from videotrack.workflow.fitting import BAD_SHARE_WARNING, fit_project, fit_warnings
from videotrack.workflow.model import (
    KEYPOINT_CAP_PX,
    ProjectModel,
    anneal_params,
    check_detection_views,
    load_model,
)
from videotrack.workflow.plots import default_plot_path
from videotrack.workflow.report import DETECT, FIT, PLOT, Cancelled, ProjectRun, StepProgress
from videotrack.workflow.run import default_results_path, plan_project, run_project
from videotrack.workflow.staleness import (
    IDENTITY_KEYS,
    changed_inputs,
    load_fresh_detections,
    results_sidecar,
    results_stale_reason,
    threshold_entry,
)
from videotrack.workflow.streaming import STREAM_CHUNK, FitAlongside, not_streamable
from videotrack.workflow.synthesize import Synthesized, synthesize
from videotrack.workflow.triangulate import (
    Triangulated,
    assign_keypoints,
    load_any_cameras,
    triangulate_keypoints,
)

__all__ = [
    "BAD_SHARE_WARNING",
    "CHECKPOINT_SECONDS",
    "DETECT",
    "FIT",
    "IDENTITY_KEYS",
    "KEYPOINT_CAP_PX",
    "PLOT",
    "STREAM_CHUNK",
    "Calibrated",
    "Cancelled",
    "Converted",
    "FitAlongside",
    "Outputs",
    "ProjectModel",
    "ProjectRun",
    "Refinement",
    "StepProgress",
    "Synthesized",
    "Triangulated",
    "anneal_params",
    "assign_keypoints",
    "calibrate_cameras",
    "changed_inputs",
    "check_detection_views",
    "checkpoint_paths",
    "convert_cameras",
    "default_plot_path",
    "default_results_path",
    "discard_checkpoint",
    "fit_project",
    "fit_warnings",
    "load_any_cameras",
    "load_fresh_detections",
    "load_model",
    "not_streamable",
    "plan_project",
    "results_sidecar",
    "results_stale_reason",
    "run_project",
    "synthesize",
    "threshold_entry",
    "triangulate_keypoints",
]
