"""Batch processing of a project: every trial detected and fitted, locally or on Dask.

:func:`run_trial` does one trial from start to end with
:func:`videotrack.pipeline.run_project` — detection (skipped when up to date), fitting
(skipped when the results are up to date, resumed from its checkpoint when an earlier run was
killed), the plot — and never raises for a problem of the trial: it returns a
:class:`TrialReport` saying ``done``, ``up to date`` or ``failed``. :func:`run_batch` runs
trials in this process, in a pool of worker processes, or as tasks of a Dask cluster, and
reports each as it finishes; :func:`plan_trial` says what a run would do (``--dry-run``).

A trial's outputs are the same whichever way it runs: each frame's fit depends only on the
seed and the frame number, never on the thread count or on the other trials.

Every output is written atomically, so a killed run leaves complete files or none, plus
temporary files named like :func:`kinematics.fileio.atomic_write` names them, which
:func:`remove_stray_temporaries` deletes when the trial is run again.

A trial's warnings (stored with its detections and results, so reported again by every run)
make it ``done-with-warnings`` or ``up-to-date-with-warnings``; a trial whose video(s) could
not be read to the end, or of which no frame could be fitted, is ``incomplete``.
"""

from __future__ import annotations

import contextlib
import csv
import glob
import io
import os
import platform
import sys
import threading
import time
import traceback
import uuid
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from kinematics.errors import LocatedError
from kinematics.fileio import atomic_write_text
from videotrack.cores import available_cores
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.project import Project, Trial, TrialOutputs, trial_outputs
from videotrack.tables import text_table

#: States of a finished trial.
DONE, UP_TO_DATE, FAILED = "done", "up to date", "failed"
DONE_WARNINGS, UP_TO_DATE_WARNINGS = "done-with-warnings", "up-to-date-with-warnings"
INCOMPLETE = "incomplete"
#: Every state, in the order counts are listed.
STATES = (DONE, DONE_WARNINGS, UP_TO_DATE, UP_TO_DATE_WARNINGS, INCOMPLETE, FAILED)
#: Columns of the project summary table.
SUMMARY_COLUMNS = ("trial", "state", "frames", "median_error_px", "bad_frames_pct", "time_s",
                   "message", "warnings")
#: How the warnings of a trial are joined in one cell of the summary.
WARNINGS_SEPARATOR = " | "

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
    from videotrack.pipeline import run_project

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
    (:func:`videotrack.pipeline.plan_project`). Reads the videos' headers, the detections
    and the results' sidecars; writes nothing.
    """
    from videotrack.pipeline import plan_project

    if trial.config is None:
        return "fails", trial.error or "no config"
    try:
        return plan_project(trial.config, force=force)
    except LocatedError as err:
        return "fails", str(err)


def project_inputs(trials: Sequence[Trial]) -> dict[Path, str]:
    """Every file the trials read, by what it is (config files, chains, camera files,
    histogram archives, videos): what no output of a batch may replace."""
    from videotrack.detect import detection_inputs

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


#: The frames-progress queue of a pool worker (set by :func:`_init_worker`).
_QUEUE = None


def _init_worker(queue, parent: int) -> None:
    """Pool worker start: report progress through ``queue``; die with the batch process."""
    global _QUEUE
    _QUEUE = queue
    if sys.platform.startswith("linux"):  # a killed batch must not leave workers writing
        import ctypes
        import signal

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        if os.getppid() != parent:  # the parent died before prctl took effect
            os._exit(1)


def _queue_progress(done: int, total: int) -> None:
    _QUEUE.put((done, total))


def _run_pool(trials, force, jobs, finished, progress) -> None:
    """Trials on ``jobs`` worker processes; a crashed worker costs its trials one retry."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    # spawn: fork would copy the locks of this process's threads (progress bars, queues)
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.SimpleQueue()
    threads = max(1, available_cores() // jobs)
    drain = None
    if progress is not None:
        def pump() -> None:
            while (item := queue.get()) is not None:
                progress(*item)

        drain = threading.Thread(target=pump, daemon=True)
        drain.start()
    order = {t.name: i for i, t in enumerate(trials)}
    pending, crashes = list(trials), dict.fromkeys(order, 0)
    try:
        while pending:
            pool = ProcessPoolExecutor(min(jobs, len(pending)), mp_context=ctx,
                                       initializer=_init_worker, initargs=(queue, os.getpid()))
            try:
                futures = {pool.submit(run_trial, t, force, threads,
                                       _queue_progress if progress else None): t
                           for t in pending}
                pending = []
                for future in as_completed(futures):
                    trial = futures[future]
                    try:
                        finished(future.result())
                    except BrokenProcessPool:
                        crashes[trial.name] += 1
                        if crashes[trial.name] < 2:
                            pending.append(trial)
                        else:
                            finished(TrialReport(trial.name, FAILED, message=(
                                "its worker process died twice (killed, or out of memory?)")))
            except BaseException:  # Ctrl-C: stop the workers now, not after their trials
                workers = list((getattr(pool, "_processes", None) or {}).values())
                pool.shutdown(wait=False, cancel_futures=True)
                for proc in workers:
                    with contextlib.suppress(OSError):
                        proc.kill()
                raise
            pool.shutdown()
            pending.sort(key=lambda t: order[t.name])
    finally:
        if drain is not None:
            queue.put(None)
            drain.join(timeout=5)


def connect(address: str, timeout: float = 30.0):
    """A Dask client for a scheduler address or a scheduler file (waits for the file, as
    when the scheduler has just been started beside).

    Raises
    ------
    VideoTrackError
        dask.distributed missing, no scheduler file after ``timeout``, scheduler unreachable.
    """
    try:
        from dask.distributed import Client
    except ImportError:
        raise VideoTrackError("needs dask.distributed: python -m pip install "
                              "'videotrack[dask]'", field="--scheduler") from None
    is_file = "://" not in address and (address.endswith(".json") or Path(address).is_file())
    try:
        if is_file:
            deadline = time.monotonic() + timeout
            while not Path(address).is_file():
                if time.monotonic() > deadline:
                    raise VideoTrackError(f"no scheduler file after {timeout:g} s",
                                          file=address, field="--scheduler")
                time.sleep(0.1)
            return Client(scheduler_file=address, timeout=timeout)
        return Client(address, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as err:
        raise VideoTrackError(f"cannot connect to the Dask scheduler {address}: {err}",
                              field="--scheduler") from None


def _run_dask(trials, force, address, finished, progress) -> None:
    """Trials as tasks of a Dask cluster; a lost task is a failed trial."""
    from dask.distributed import as_completed

    client = connect(address)
    batch = uuid.uuid4().hex[:8]
    with client:
        futures = {client.submit(run_trial, t, force, 1, None, pure=False,
                                 key=f"videotrack-{batch}-{i}"): t
                   for i, t in enumerate(trials)}
        try:
            for future in as_completed(futures):
                trial = futures[future]
                try:
                    report = future.result()
                except Exception as err:  # a worker died, or the cluster lost the task
                    report = TrialReport(trial.name, FAILED,
                                         message=f"Dask task failed: {type(err).__name__}: "
                                                 f"{err}")
                if progress is not None and "fit" in report.steps:
                    progress(report.frames, report.frames)
                finished(report)
        except BaseException:
            client.cancel(list(futures))
            raise


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


class RunLog:
    """The log of one batch run: ``PROJECT/logs/batch-<date>-<time>.log``, written as the
    run goes (so a killed run's log shows how far it got)."""

    def __init__(self, project: Project) -> None:
        project.logs.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        for k in range(1000):
            self.path = project.logs / f"batch-{stamp}{'' if not k else f'-{k}'}.log"
            try:
                self._fh = open(self.path, "x", encoding="utf-8", buffering=1)  # noqa: SIM115
                break
            except FileExistsError:
                continue
            except OSError as err:
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
        try:
            self._fh.close()
        except OSError as err:
            self.failed = self.failed or err.strerror or str(err)

    def discard(self) -> None:
        """Close and delete the log (a run that changed nothing leaves none)."""
        self.close()
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
