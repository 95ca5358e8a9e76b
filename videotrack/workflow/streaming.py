"""Fitting while detecting.

When every record is fitted on its own (:func:`not_streamable`: one candidate per frame, an
absolute re-analysis threshold, no noise model to measure, start from the means, fixed roots),
:func:`~videotrack.workflow.run_project` hands the records to a fitting thread as they are
detected (:class:`FitAlongside`), so decoding, detection and fitting overlap; the results are
those of detecting first and fitting afterwards. Checkpoints start once the detections file
is written (their sidecar names it by content hash); a run that finds a checkpoint detects
first and resumes from it.
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

from kinematics.fit import FrameResult
from videotrack.workflow.model import ProjectModel

#: Records handed to the fitting thread at a time while detecting; None: four times as many
#: as fill the lanes of every thread (:meth:`Fitter.lane_frames`). 64 (when 'auto' wanted
#: full lanes) left the streamed fit to the scalar kernel, 2-2.5x slower than the lanes; 128
#: filled them once, and each block's last runs and re-analyses ran in half-empty lanes
#: (2 threads, docs/benchmarks.md "End to end": Table 1 schedule 576 frames/s with 128,
#: 734 with 256, 696 with 512; short schedule 897, 1038, 1084).
STREAM_CHUNK: int | None = None


def not_streamable(model: ProjectModel) -> str | None:
    """Why a project's records cannot be fitted while later ones are still being detected
    (the fit of a record would then differ from fitting all records at once), or None when
    they can: each record is fitted on its own, from its own random streams."""
    p = model.params
    if p.candidates > 1:
        return "candidates > 1: the path through time looks 32 frames ahead"
    if p.threshold_mode != "absolute":
        return f"threshold_mode {p.threshold_mode!r}: measured on frames of the whole video"
    if p.start != "mean":
        return f"start {p.start!r}: a frame starts from the one before"
    if any(c.root.mode != "fixed" for c in model.body.chains):
        return "a root that is tracked or placed from the detections"
    if model.fitter().match_measured:
        return "match 'auto': decided on the detections of the whole video"
    if p.noise_floor_px is not None and p.noise_px is None:
        return "the noise model: σ measured on frames of the whole video"
    return None


class FitAlongside:
    """Fits records in a thread of its own while the caller detects the next ones.

    Decoding (in FFmpeg's threads, or threads decoding MJPEG packets) and detection run in
    the caller's thread, annealing (numba kernels that release the GIL) in this one, so the
    two overlap and the slower sets the pace. Detection stays in the caller's thread because
    the warnings it records into the detections file are caught with
    :func:`warnings.catch_warnings`, which is process-wide, and because progress and cancel
    belong to the caller.

    Give it every record with :meth:`add` as it is detected, then take the results in record
    order with :meth:`results`; :meth:`close` (or leaving the ``with`` block) stops the thread
    and drops what it fitted. Only for models where :func:`not_streamable` is None: the
    results are then those of one :meth:`Fitter.iter_fit` over all records.
    """

    def __init__(self, model: ProjectModel, chunk: int | None = None) -> None:
        import numba

        self.fitter = model.fitter()
        self.n_views = len(model.view_names)
        self.chunk = chunk or STREAM_CHUNK or 4 * self.fitter.lane_frames()
        self.started = time.perf_counter()
        self._threads = numba.get_num_threads()  # numba's setting is per thread
        self._gathered: list[tuple[np.ndarray, ...]] = []
        self._added = 0  # records handed to the thread
        # unbounded: records are small, and the detection should never wait for the fit
        self._todo: queue.SimpleQueue = queue.SimpleQueue()
        self._done: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._work, name="videotrack-fit", daemon=True)
        self._thread.start()

    def add(self, record) -> None:
        """A detected record (:class:`videotrack.detect.run.FrameDetections`), the next in order."""
        self._gathered.append(record.points)
        if len(self._gathered) >= self.chunk:
            self._hand_on()

    def results(self, n: int) -> Iterator[FrameResult]:
        """The results of the ``n`` records added (all of them), in order, as they come."""
        self._hand_on()
        self._todo.put(None)
        if n != self._added:
            raise RuntimeError(f"{n} records to fit, {self._added} were detected")
        for _ in range(n):
            item = self._done.get()
            if isinstance(item, BaseException):
                raise item
            yield item

    def close(self) -> None:
        self._stop.set()
        self._todo.put(None)
        self._thread.join()

    def __enter__(self) -> FitAlongside:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _hand_on(self) -> None:
        if self._gathered:
            self._todo.put((self._added, self._gathered))
            self._added += len(self._gathered)
            self._gathered = []

    def _work(self) -> None:
        import numba

        numba.set_num_threads(self._threads)
        try:
            while (item := self._todo.get()) is not None and not self._stop.is_set():
                first, records = item
                # the set-up is checked on every record once they are detected
                gen = self.fitter.iter_fit(_records(first, records, self.n_views),
                                           range(first, first + len(records)),
                                           cancel=self._stop.is_set, check_setup=False)
                with contextlib.closing(gen):
                    for r in gen:
                        if self._stop.is_set():
                            return
                        self._done.put(r)
        except BaseException as err:  # raised again in the caller's thread by results()
            self._done.put(err)


class _Records(NamedTuple):
    points: np.ndarray
    offsets: np.ndarray


def _records(first: int, records: list[tuple[np.ndarray, ...]], n_views: int) -> _Records:
    """Records ``first, first + 1, ...`` (per-view points each) as detections the fitter
    takes, preceded by ``first`` empty records: a record's random streams are keyed by its
    index, so it must keep it, and the empty ones are not fitted."""
    views = [v for rec in records for v in rec]
    offsets = np.zeros((first + len(records)) * n_views + 1, np.int64)
    np.cumsum([len(v) for v in views], out=offsets[first * n_views + 1:])
    points = np.concatenate(views).astype(np.float64).reshape(-1, 2) if views else \
        np.empty((0, 2))
    return _Records(points, offsets)
