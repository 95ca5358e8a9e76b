"""What a run of :func:`~videotrack.workflow.run_project` is made of and reports: its steps
(:data:`DETECT`, :data:`FIT`, :data:`PLOT`), their progress (:class:`StepProgress`), the
:class:`Cancelled` exception, and the :class:`ProjectRun` it returns, with the warnings met on
the way.

Warnings travel: what went wrong while detecting is kept in the detections file, and the
results sidecar keeps every warning of the run that made the results, so a later run that
finds them up to date reports them again. :attr:`ProjectRun.incomplete` says when the results
do not cover the video(s) (a truncated file, an unreadable image), no frame could be fitted, or
more than :data:`UNUSABLE_SHARE` of the frames failed.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from kinematics.fit import Status
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.project.identity import relative_message
from videotrack.results.files import Results, read_sidecar
from videotrack.workflow.model import ProjectModel

#: A run whose share of frames ``failed`` or without detections is above this is incomplete
#: (exit status 3 of fit, run and batch, unless --allow-incomplete): its results say little
#: of the animal and much of a set-up or video to look at.
UNUSABLE_SHARE = 0.5
#: The statuses counted for that share.
UNUSABLE = frozenset({Status.FAILED, Status.NO_DETECTIONS})

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


def _reported(run: ProjectRun, caught: Sequence[str]) -> ProjectRun:
    """The run with its warnings (this run's, and those stored with its detections and
    results) and why it is incomplete."""
    from videotrack.detect.run import incomplete_reason

    base = run.results_path.absolute().parent
    stored = list(run.detections.metadata.get("warnings", [])) if run.detections else []
    if run.results is not None:
        with contextlib.suppress(VideoTrackError):
            stored += read_sidecar(run.results_path).get("warnings", [])
    found = [relative_message(w, base) for w in (*caught, *stored)]
    why = [incomplete_reason(run.detections)] if run.detections is not None else []
    if run.results is not None and run.n_frames and not run.n_ok:
        why.append(f"not one of the {run.n_frames} frames has a fit to trust (failed or "
                   "no detections)")
    elif run.results is not None and run.n_frames:
        bad = sum(s in UNUSABLE for s in run.results.status)
        if bad > UNUSABLE_SHARE * run.n_frames:
            why.append(f"{bad} of {run.n_frames} frames ({100 * bad / run.n_frames:.0f} %) "
                       "failed or had no detections, more than "
                       f"{100 * UNUSABLE_SHARE:.0f} %: the results cannot be used as they are")
    return replace(run, warnings=tuple(dict.fromkeys(found)),
                   incomplete="; ".join(w for w in why if w))


def _with_results(run: ProjectRun, table: Results) -> ProjectRun:
    n_ok = int(table.ok_mask().sum())
    return replace(run, results=table, n_frames=len(table), n_ok=n_ok,
                   n_bad=len(table) - n_ok)
