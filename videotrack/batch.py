"""Batch processing of a project: every trial detected and fitted, locally or on Dask.

:func:`run_trial` does one trial from start to end with
:func:`videotrack.workflow.run.run_project` — detection (skipped when up to date), fitting
(skipped when the results are up to date, resumed from its checkpoint when an earlier run was
killed), the plot — and never raises for a problem of the trial: it returns a
:class:`TrialReport` saying ``done``, ``up to date`` or ``failed``. :func:`run_batch` runs
trials in this process, in a pool of worker processes, or as tasks of a Dask cluster, and
reports each as it finishes; :func:`plan_trial` says what a run would do (``--dry-run``).

A trial's outputs are the same whichever way it runs: each frame's fit depends only on the
seed and the frame number, never on the thread count or on the other trials.

Every output is written atomically, so a killed run leaves complete files or none, plus
temporary files named like :func:`kinematics.fileio.atomic_write` names them, which
:func:`~videotrack.batch_trial.remove_stray_temporaries` deletes when the trial is run again.

A trial's warnings (stored with its detections and results, so reported again by every run)
make it ``done-with-warnings`` or ``up-to-date-with-warnings``; a trial whose video(s) could
not be read to the end, of which no frame could be fitted, or more than half of whose frames
failed (:data:`videotrack.workflow.report.UNUSABLE_SHARE`), is ``incomplete``; one whose set-up
the checks refuse (``[anneal] accept_setup``) is ``failed``, with the cause.

One trial is :mod:`videotrack.batch_trial`; the worker processes :mod:`videotrack.batch_pool`,
the Dask tasks :mod:`videotrack.batch_dask`; here: running many, and the summary and log.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import io
import os
import platform
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from kinematics.fileio import atomic_write_text
from videotrack.batch_dask import (
    _run_dask,
    connect,  # noqa: F401  (public: a client of a Dask cluster)
)
from videotrack.batch_pool import _run_pool
from videotrack.batch_trial import (
    FAILED,
    INCOMPLETE,
    STATES,
    UP_TO_DATE,
    UP_TO_DATE_WARNINGS,
    Progress,
    TrialReport,
    plan_trial,  # noqa: F401  (public: what a run would do)
    project_inputs,  # noqa: F401  (public: what the trials read)
    run_trial,
)
from videotrack.cores import available_cores
from videotrack.errors import VideoTrackError
from videotrack.project.folders import Project, Trial
from videotrack.results.tables import text_table

#: Columns of the project summary table.
SUMMARY_COLUMNS = ("trial", "state", "frames", "median_error_px", "bad_frames_pct", "time_s",
                   "message", "warnings")
#: How the warnings of a trial are joined in one cell of the summary.
WARNINGS_SEPARATOR = " | "


# -- many trials --------------------------------------------------------------------------------
def run_batch(
    trials: Sequence[Trial],
    *,
    force: bool = False,
    jobs: int = 1,
    scheduler: str | None = None,
    on_report: Callable[[TrialReport], object] | None = None,
    progress: Progress | None = None,
) -> list[TrialReport]:
    """Run trials and return their reports in the order of ``trials``.

    Parameters
    ----------
    trials : sequence of Trial
    force : bool
        Recompute up-to-date outputs.
    jobs : int
        Trials at a time on this machine, each in its own process with
        ``cores // jobs`` numba threads (1: in this process, on every core).
    scheduler : str, optional
        Address (``tcp://host:8786``) or scheduler file (JSON) of a Dask cluster: each
        trial is a task there, on one thread unless its ``[fit] jobs`` says otherwise;
        ``jobs`` is then ignored. Workers need VideoTrack installed and the project's
        files at the same paths.
    on_report : callable, optional
        Called in this process with each report as its trial finishes.
    progress : callable, optional
        ``progress(done, added_to_total)`` for a frames bar (per finished trial with Dask).
    """
    reports: dict[str, TrialReport] = {}

    def finished(report: TrialReport) -> None:
        reports[report.name] = report
        if on_report is not None:
            on_report(report)

    if scheduler is not None:
        _run_dask(trials, force, scheduler, finished, progress)
    elif jobs <= 1 or len(trials) <= 1:
        threads = available_cores()
        for trial in trials:
            finished(run_trial(trial, force, threads, progress))
    else:
        _run_pool(trials, force, jobs, finished, progress)
    return [reports[t.name] for t in trials]


# -- reporting ----------------------------------------------------------------------------------
def _num(value: float, digits: int) -> str:
    return "" if value != value else f"{value:.{digits}f}"


def summary_rows(reports: Sequence[TrialReport]) -> list[tuple[str, ...]]:
    """One row per trial, the cells of :data:`SUMMARY_COLUMNS`."""
    return [(r.name, r.state, str(r.frames) if r.frames else "", _num(r.median_error, 3),
             _num(r.bad_pct, 1), f"{r.seconds:.1f}", _one_line(r.message),
             WARNINGS_SEPARATOR.join(_one_line(w) for w in r.warnings)) for r in reports]


def _one_line(text: str) -> str:
    return " ".join(text.split())


def summary_csv(reports: Sequence[TrialReport]) -> str:
    """The project summary table as CSV text."""
    return _csv_text(summary_rows(reports))


def _csv_text(rows: Sequence[Sequence[str]]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(SUMMARY_COLUMNS)
    writer.writerows(rows)
    return buf.getvalue()


def read_summary(path: str | os.PathLike) -> list[tuple[str, ...]]:
    """The rows of an existing summary table, cells in the order of
    :data:`SUMMARY_COLUMNS` (a column an older file lacks is empty); [] when absent.

    Raises
    ------
    VideoTrackError
        The file is not a summary table.
    """
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except FileNotFoundError:
        return []
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise VideoTrackError(f"cannot read the summary: {err}", file=path) from None
    if rows and not {"trial", "state"} <= set(rows[0]):
        raise VideoTrackError("not a batch summary (no trial and state columns)", file=path)
    return [tuple(row.get(c) or "" for c in SUMMARY_COLUMNS) for row in rows]


def write_summary(reports: Sequence[TrialReport], path: str | os.PathLike, *,
                  keep: Sequence[str] = (), order: Sequence[str] = ()) -> Path:
    """Write the summary table atomically: a row per report.

    ``keep``: trials not run now whose rows in the existing summary stay (a run of
    selected trials updates their rows and keeps the others'); ``order``: trial names in
    the order the rows are written (default: the reports', then the kept rows).
    """
    path = Path(path)
    rows = summary_rows(reports)
    others = set(keep) - {r.name for r in reports}
    if others:
        with contextlib.suppress(VideoTrackError):  # not a summary (replaced with --force)
            rows += [row for row in read_summary(path) if row[0] in others]
    if order:
        rank = {name: i for i, name in enumerate(order)}
        rows.sort(key=lambda row: rank.get(row[0], len(rank)))
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, _csv_text(rows))
    return path


def format_summary(reports: Sequence[TrialReport]) -> str:
    """The summary as a terminal table; below it why trials failed or are incomplete, and
    every trial's warnings."""
    head = ("trial", "state", "frames", "median E (px)", "bad (%)", "time (s)")
    table = text_table(head, [row[:6] for row in summary_rows(reports)], left=2)
    lines = [line.rstrip() for line in table.splitlines()]
    for state, title in ((FAILED, "failed"), (INCOMPLETE, "incomplete")):
        listed = [f"  {r.name}: {r.message}" for r in reports if r.state == state]
        if listed:
            lines += [f"{title}:", *listed]
    warned = [f"  {r.name}: {w}" for r in reports for w in r.warnings]
    if warned:
        lines += ["warnings:", *warned]
    return "\n".join(lines)


def count_states(reports: Sequence[TrialReport]) -> str:
    """``"3 done, 1 up to date, 1 failed"``."""
    counts = {s: sum(r.state == s for r in reports) for s in STATES}
    return ", ".join(f"{n} {s}" for s, n in counts.items() if n) or "nothing"


def nothing_ran(reports: Sequence[TrialReport]) -> bool:
    """Every trial was up to date (with or without stored warnings): the run changed
    nothing."""
    return all(r.state in (UP_TO_DATE, UP_TO_DATE_WARNINGS) or (
        r.state == INCOMPLETE and not r.steps) for r in reports)


#: Why a file cannot be written where the storage is read-only (a finished project on a
#: read-only share can still be checked: nothing to do, nothing written).
READ_ONLY = (errno.EROFS, errno.EACCES, errno.EPERM)


class RunLog:
    """The log of one batch run: ``PROJECT/logs/batch-<date>-<time>.log``, written as the
    run goes (so a killed run's log shows how far it got). On read-only storage there is
    none (:attr:`failed` says so): a run with work to do then fails in its trials, one that
    finds every trial up to date writes nothing."""

    def __init__(self, project: Project) -> None:
        project.logs.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        self._fh = None
        for k in range(1000):
            self.path = project.logs / f"batch-{stamp}{'' if not k else f'-{k}'}.log"
            try:
                self._fh = open(self.path, "x", encoding="utf-8", buffering=1)  # noqa: SIM115
                break
            except FileExistsError:
                continue
            except OSError as err:
                if err.errno in READ_ONLY:
                    self.failed = f"not written: {err.strerror}"
                    return
                raise VideoTrackError(f"cannot write the log: {err.strerror}",
                                      file=self.path) from None
        self.write(f"videotrack batch, {time.strftime('%Y-%m-%d %H:%M:%S')}: python "
                   f"{platform.python_version()}, {platform.node()}, {available_cores()} cores")

    #: Why the log could not be written to the end (a full disk), or None.
    failed: str | None = None

    def write(self, line: str) -> None:
        """Append a line; a log that cannot be written (disk full) stops the log, never the
        run (:attr:`failed` says why)."""
        if self.failed is not None:
            return
        try:
            self._fh.write(line + "\n")
        except OSError as err:
            self.failed = err.strerror or str(err)

    def report(self, r: TrialReport) -> None:
        what = f" ({', '.join(r.steps)})" if r.steps else ""
        text = (f"{r.name}: {r.state}{what} in {r.seconds:.1f} s" + (
            f": {r.message}" if r.message else
            f": {r.frames} frames, median E {r.median_error:.3f} px, {r.bad_pct:.1f} % bad"))
        self.write(f"[{time.strftime('%H:%M:%S')}] {text}")
        for line in r.log:
            self.write("    " + line.replace("\n", "\n    "))

    def close(self) -> None:
        if self._fh is None:
            return
        try:
            self._fh.close()
        except OSError as err:
            self.failed = self.failed or err.strerror or str(err)

    def discard(self) -> None:
        """Close and delete the log (a run that changed nothing leaves none)."""
        self.close()
        if self._fh is not None:
            with contextlib.suppress(OSError):
                self.path.unlink()


@contextlib.contextmanager
def project_lock(project: Project) -> Iterator[None]:
    """Hold the project for one batch run (two at once would undo each other's temporary
    files); the lock goes with the process, also when it is killed."""
    project.logs.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl
    except ImportError:  # no advisory locks on this platform
        yield
        return
    fd = os.open(project.logs, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise VideoTrackError("another 'videotrack batch' is running on this project",
                                  file=project.root) from None
        yield
    finally:
        os.close(fd)
