"""Trials of a batch run on a pool of worker processes on this machine
(:func:`videotrack.batch.run_batch` with ``jobs`` > 1): each worker reports its frames
progress through a queue and dies with the batch process; a crashed worker costs its trials
one retry.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading

from videotrack.batch_trial import FAILED, TrialReport, run_trial
from videotrack.cores import available_cores

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
