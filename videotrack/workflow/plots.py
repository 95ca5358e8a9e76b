"""The angle plot of a run's results: ``<results>.png``, drawn when wanted and missing or
older than the results (:func:`videotrack.results.plots.plot_angles` draws it)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from videotrack.workflow.report import PLOT, ProjectRun
from videotrack.workflow.staleness import _older


def default_plot_path(results_path: Path) -> Path:
    """The angle plot of a results file: ``<results>.png``."""
    return Path(results_path).with_suffix(".png")


def _plot(run: ProjectRun, wanted: bool) -> ProjectRun:
    """The angle plot, when wanted and missing or older than the results."""
    png = default_plot_path(run.results_path)
    if not wanted or not (run.fitted or _older(png, run.results_path)):
        return run
    from videotrack.results.plots import plot_angles

    png = plot_angles(run.results, png, run.model.body.locked_mask())
    return replace(run, steps=(*run.steps, PLOT), plot_path=Path(png))
