"""Trials of a batch run as tasks of a Dask cluster (:func:`videotrack.batch.run_batch` with
a ``scheduler``). The only module that imports Dask (when it runs): VideoTrack works without
it.
"""

from __future__ import annotations

import time
import uuid
from pathlib import Path

from videotrack.batch_trial import FAILED, TrialReport, run_trial
from videotrack.errors import VideoTrackError


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
