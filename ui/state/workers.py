"""Background work: threads that run the fitter's generator, marker detection or any call.

A worker never touches the session: it reports through signals, which Qt delivers in the
thread that owns the receiver (the GUI thread), so all state changes happen there.
"""

from __future__ import annotations

import sys
import time
import traceback
from collections.abc import Callable

from PySide6.QtCore import QThread, Signal

from kinematics.errors import LocatedError
from ui.state import backend


def error_text(err: BaseException) -> str:
    """The one-line message shown for an error: ``path:line: field: message`` for the errors
    a user can cause, the exception's name and text for anything else (whose traceback goes
    to stderr for a bug report)."""
    if isinstance(err, LocatedError):
        return str(err)
    traceback.print_exception(err, file=sys.stderr)
    return f"internal error: {type(err).__name__}: {err}"


#: Raised inside a task when its worker was asked to stop (the project workflow's own).
Cancelled = backend.Cancelled


class TaskWorker(QThread):
    """Runs ``fn(worker)`` in a thread; ``done(result)`` or ``failed(message)`` follows.

    ``fn`` may call :meth:`report` to announce progress, :meth:`publish` to hand on partial
    results (e.g. each frame of a re-fit that runs frame after frame) and should call
    :meth:`check_cancel` now and then (it raises :class:`Cancelled`). It may set
    :attr:`summary`, a line for the status bar when it ends.
    """

    done = Signal(object)
    failed = Signal(str)
    progressed = Signal(int, int, float)  # done, total, items per second
    published = Signal(object)  # a list of partial results

    def __init__(self, fn: Callable[[TaskWorker], object], parent=None) -> None:
        super().__init__(parent)
        self._fn = fn
        self._cancel = False
        self._t0 = time.perf_counter()
        self.cancelled = False
        self.count = 0  # items published
        self.summary = ""
        self.released = False  # only fits are let go (Session._let_go)

    def cancel(self) -> None:
        self._cancel = True

    def publish(self, items: list) -> None:
        self.count += len(items)
        self.published.emit(list(items))

    def cancel_requested(self) -> bool:
        return self._cancel

    def check_cancel(self) -> None:
        if self._cancel:
            raise Cancelled

    def report(self, done: int, total: int) -> None:
        elapsed = max(time.perf_counter() - self._t0, 1e-9)
        self.progressed.emit(done, total, done / elapsed)

    def run(self) -> None:
        self._t0 = time.perf_counter()
        try:
            result = self._fn(self)
        except Cancelled:
            self.cancelled = True
            self.done.emit(None)
        except Exception as err:  # every error reaches the user as one line
            self.failed.emit(error_text(err))
        else:
            self.done.emit(result)


class FitWorker(QThread):
    """Drives the fitter's generator over frames, handing results on in small batches.

    Cancelling stops the fitter before its next chunk (``iter_fit``'s ``cancel``: the path
    through time and its flags would otherwise hold up to 96 frames back) and closes the
    generator; the results that arrived before are kept. ``chunk_size`` frames are computed
    per parallel batch, so a cancel takes effect within one batch.
    """

    resultsReady = Signal(object)  # list[FrameResult]
    progressed = Signal(int, int, float)  # frames done, total, frames per second
    failed = Signal(str)

    #: Seconds between two batches handed to the GUI (keeps the event queue short).
    BATCH_SECONDS = 0.1

    def __init__(self, fitter, detections, frames, chunk_size: int, parent=None) -> None:
        super().__init__(parent)
        self.fitter = fitter  # its noise model, once measured, is the video's
        self._detections = detections
        self._frames = list(frames)
        self._chunk = chunk_size
        self._cancel = False
        self.cancelled = False
        self.released = False  # the session let go of it at a cancel (Session._let_go)
        self.count = 0

    def cancel(self) -> None:
        self._cancel = True

    def run(self) -> None:
        total = len(self._frames)
        t0 = time.perf_counter()
        last = t0 - self.BATCH_SECONDS  # the first result is shown at once
        batch = []
        gen = None
        try:
            gen = backend.iter_fit(self.fitter, self._detections, self._frames, self._chunk,
                                   cancel=lambda: self._cancel)
            for result in gen:
                batch.append(result)
                self.count += 1
                now = time.perf_counter()
                if now - last >= self.BATCH_SECONDS or self._cancel:
                    self.resultsReady.emit(batch)
                    self.progressed.emit(self.count, total, self.count / max(now - t0, 1e-9))
                    batch, last = [], now
                if self._cancel:
                    self.cancelled = self.count < total
                    break
        except Exception as err:  # every error reaches the user as one line
            self.failed.emit(error_text(err))
        finally:
            if gen is not None:
                gen.close()
            if batch:
                self.resultsReady.emit(batch)
            self.progressed.emit(self.count, total,
                                 self.count / max(time.perf_counter() - t0, 1e-9))
