"""One trial of a batch: :func:`run_trial` detects and fits it (each step skipped when its
outputs are up to date) and reports how it went as a :class:`TrialReport`, never raising for a
problem of the trial; :func:`plan_trial` says what a run would do, :func:`project_inputs` what
the trials read, :func:`remove_stray_temporaries` cleans up after a killed run.

:mod:`videotrack.batch` runs many trials and reports on them.
"""

from __future__ import annotations

import contextlib
import glob
import time
import traceback
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from kinematics.errors import LocatedError
from videotrack.errors import VideoTrackWarning
from videotrack.project.folders import Trial, TrialOutputs, trial_outputs

#: States of a finished trial.
DONE, UP_TO_DATE, FAILED = "done", "up to date", "failed"
DONE_WARNINGS, UP_TO_DATE_WARNINGS = "done-with-warnings", "up-to-date-with-warnings"
INCOMPLETE = "incomplete"
#: Every state, in the order counts are listed.
STATES = (DONE, DONE_WARNINGS, UP_TO_DATE, UP_TO_DATE_WARNINGS, INCOMPLETE, FAILED)

#: progress(frames done, frames added to the total) — the frames bar of a batch.
Progress = Callable[[int, int], object]


@dataclass(frozen=True)
class TrialReport:
    """How one trial went.

    Attributes
    ----------
    name : str
    state : str
        ``done`` or ``done-with-warnings`` (computed in this run), ``up to date`` or
        ``up-to-date-with-warnings`` (nothing to do), ``incomplete`` (the video(s) could not
        be read to the end, or no frame was fitted: ``message`` says why), ``failed``.
    frames : int
        Rows of the results file (0 when there is none).
    median_error : float
        Median view error E of the results, pixels (NaN without results).
    bad_pct : float
        Percentage of frames whose fit failed or that had no detections.
    seconds : float
        Time this run spent on the trial.
    message : str
        Why it failed or is incomplete, one line.
    steps : tuple of str
        What was computed: ``"detect"``, ``"fit"``, ``"plot"``.
    log : tuple of str
        Lines for the run's log file (notes, the traceback of an unexpected error).
    warnings : tuple of str
        Warnings of the trial (truncated video, view without markers, many failed frames,
        ...): those of this run and those stored with its detections and results.
    """

    name: str
    state: str
    frames: int = 0
    median_error: float = float("nan")
    bad_pct: float = float("nan")
    seconds: float = 0.0
    message: str = ""
    steps: tuple[str, ...] = ()
    log: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()


# -- one trial --------------------------------------------------------------------------------
def run_trial(trial: Trial, force: bool = False, threads: int = 1,
              progress: Progress | None = None) -> TrialReport:
    """Detect and fit one trial (each step skipped when its outputs are up to date).

    Parameters
    ----------
    trial : Trial
    force : bool
        Recompute although the outputs are up to date.
    threads : int
        numba threads for fitting, unless the trial's ``[fit] jobs`` sets them.
    progress : callable, optional
        ``progress(done, added_to_total)``: the frames to fit are announced once, then each
        fitted frame counts one.

    Returns
    -------
    TrialReport
        Problems of the trial (bad config, unreadable video, ...) are a ``failed`` report,
        never an exception; only KeyboardInterrupt passes. A trial with warnings is
        ``done-with-warnings`` / ``up-to-date-with-warnings``, one that could not be
        completed ``incomplete``.
    """
    t0 = time.perf_counter()
    lines: list[str] = []
    if trial.config is None:
        return TrialReport(trial.name, FAILED, message=trial.error or "no config")
    # (The warnings machinery is per process: on a Dask worker running several trials in
    # threads, a warning may be listed with another of its trials.)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", VideoTrackWarning)
        try:
            report = _run_trial(trial, force, threads, progress, lines)
        except LocatedError as err:
            report = TrialReport(trial.name, FAILED, message=str(err))
        except Exception as err:  # a bug must not stop the other trials; the log has it
            lines.append(traceback.format_exc().rstrip())
            report = TrialReport(trial.name, FAILED, message=f"{type(err).__name__}: {err}")
    notes = (*(f"VideoTrackWarning: {w}" for w in report.warnings),
             *(f"{w.category.__name__}: {w.message}" for w in caught))
    found = tuple(dict.fromkeys((*report.warnings, *(
        str(w.message) for w in caught if issubclass(w.category, VideoTrackWarning)))))
    return replace(report, state=_with_warnings(report.state, found),
                   seconds=time.perf_counter() - t0, log=(*lines, *notes), warnings=found)


def _with_warnings(state: str, found: Sequence[str]) -> str:
    """``done`` / ``up to date`` become their ``-with-warnings`` states when there are."""
    if not found:
        return state
    return {DONE: DONE_WARNINGS, UP_TO_DATE: UP_TO_DATE_WARNINGS}.get(state, state)


def _run_trial(trial: Trial, force: bool, threads: int, progress: Progress | None,
               lines: list[str]) -> TrialReport:
    from videotrack.workflow import run_project

    config = trial.config
    for path in remove_stray_temporaries(trial_outputs(config)):
        lines.append(f"removed {path.name}, left by an interrupted run")
    run = run_project(config, force=force, threads=config["fit"]["jobs"] or threads,
                      progress=_frames_progress(progress), log=lines.append)
    err = run.results.error[np.isfinite(run.results.error)]
    state = INCOMPLETE if run.incomplete else DONE if run.steps else UP_TO_DATE
    return TrialReport(trial.name, state, frames=run.n_frames,
                       median_error=float(np.median(err)) if err.size else float("nan"),
                       bad_pct=100.0 * run.n_bad / run.n_frames if run.n_frames
                       else float("nan"), message=run.incomplete, steps=run.steps,
                       warnings=run.warnings)


def _frames_progress(progress: Progress | None):
    """A run's progress as the batch's frames bar: the frames to fit are announced when the
    fit starts, then each fitted frame counts one."""
    if progress is None:
        return None

    def on_step(p) -> None:
        if p.step == "fit":
            progress(*((0, p.total) if p.done == 0 else (1, 0)))

    return on_step


def remove_stray_temporaries(outputs: TrialOutputs) -> list[Path]:
    """Delete the temporary files a killed run left beside a trial's outputs.

    :func:`kinematics.fileio.atomic_write` writes ``NAME`` through ``.NAME.<random>.tmp``;
    only such files of this trial's outputs are removed. Returns the paths removed.
    """
    removed = []
    for path in outputs.files():
        for tmp in path.parent.glob(f".{glob.escape(path.name)}.*.tmp"):
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
                removed.append(tmp)
    return removed


def plan_trial(trial: Trial, force: bool = False) -> tuple[str, str]:
    """What :func:`run_trial` would do, without doing it: ``(action, why)``.

    Actions: ``"detect + fit"``, ``"fit"``, ``"plot"``, ``"up to date"``, ``"fails"``
    (:func:`videotrack.workflow.run.plan_project`). Reads the videos' headers, the detections
    and the results' sidecars; writes nothing.
    """
    from videotrack.workflow import plan_project

    if trial.config is None:
        return "fails", trial.error or "no config"
    try:
        return plan_project(trial.config, force=force)
    except LocatedError as err:
        return "fails", str(err)


def project_inputs(trials: Sequence[Trial]) -> dict[Path, str]:
    """Every file the trials read, by what it is (config files, chains, camera files,
    histogram archives, videos): what no output of a batch may replace."""
    from videotrack.detect.run import detection_inputs

    found: dict[Path, str] = {}
    for trial in trials:
        if trial.config is None:
            continue
        config = trial.config
        found.update(detection_inputs(config))
        for section, key, what in (("chain", "path", "a chain"),
                                   ("chain", "histograms", "a histogram archive"),
                                   ("cameras", "path", "a camera file")):
            if config[section][key]:
                found[Path(config[section][key])] = what
    return found
