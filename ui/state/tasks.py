"""Background tasks: one worker thread at a time, cancelling, waiting (a part of
:class:`ui.state.Session`). Workers report through signals, handled in the GUI thread."""

from __future__ import annotations

from collections.abc import Callable

from ui.state import backend
from ui.state.workers import FitWorker, TaskWorker


class TasksMixin:
    """Running, cancelling and waiting for the background task."""

    # -- background tasks ---------------------------------------------------------------
    @property
    def busy(self) -> bool:
        return self._task is not None

    def _start(self, worker, what: str) -> None:
        if self.closed:  # e.g. a correction timer firing after the window closed
            worker.deleteLater()
            return
        self._task = worker
        self._measuring = False  # fit() says when its task measures the threshold
        worker.finished.connect(lambda: self._task_finished(worker))
        self.busyChanged.emit(True)
        self.undoChanged.emit()
        self.status.emit(what)
        worker.start()

    def _task_finished(self, worker) -> None:
        worker.deleteLater()
        if worker in self._released:
            self._released.remove(worker)
            return  # let go at a cancel: the session has moved on
        self._task = None
        self.busyChanged.emit(False)
        self.undoChanged.emit()

    def cancel(self, wait: bool = False) -> None:
        """Stop the running task. A fit is let go at once where threads allow it
        (:meth:`_let_go`); other tasks stop at their next check (a frame)."""
        task = self._task
        if task is None:
            return
        task.cancel()
        self.status.emit("cancelling …")
        if wait:
            task.wait()
        elif isinstance(task, FitWorker) and backend.concurrent_fits():
            self._let_go(task)

    def _let_go(self, worker: FitWorker) -> None:
        """End a cancelled fit now, keeping the results that arrived (one undo step).

        The fitter can only be stopped where it hands results over, which with candidates
        is every 32 frames along the path through time; rather than wait for that, the
        window moves on and the worker finishes the frames in hand in the background, its
        results discarded. Only where numba runs parallel kernels of two threads at once
        (:func:`ui.state.backend.concurrent_fits`), since a new fit may start meanwhile.
        """
        worker.released = True
        self._released.append(worker)
        self._task = None
        self._fit_done(worker)
        self.busyChanged.emit(False)
        self.undoChanged.emit()

    def wait(self, timeout_ms: int = 60000) -> bool:
        """Block until the running task ends (tests and closing); True when it ended."""
        task = self._task
        return True if task is None else task.wait(timeout_ms)

    def wait_released(self) -> None:
        """Block until fits let go at a cancel have finished (closing)."""
        for worker in list(self._released):
            worker.wait()

    def run_task(self, fn: Callable, on_done: Callable[[object], None], what: str) -> bool:
        """Run ``fn(worker)`` in a thread and ``on_done(result)`` in the GUI thread."""
        if self.busy:
            self.error.emit("another task is running; wait for it or cancel it")
            return False
        worker = TaskWorker(fn)
        worker.done.connect(lambda result: None if worker.cancelled else on_done(result))
        worker.failed.connect(self._failed)
        worker.progressed.connect(self.progress)
        self._start(worker, what)
        return True

    def _failed(self, message: str) -> None:
        self.status.emit("failed")
        self.error.emit(message)

