"""Fitting frames in the background: the fitter of the session's chain and settings, and
results stored as they arrive (a part of :class:`ui.state.Session`)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import replace

import numpy as np

from kinematics.errors import LocatedError
from kinematics.model import Body
from ui import adapters
from ui.state import backend
from ui.state.history import Edit
from ui.state.workers import FitWorker, TaskWorker
from videotrack.errors import VideoTrackError

#: A fit of some frames also fits this many frames before and after each (not kept), so that
#: the path through time chooses with the movement around them (Session._with_context). One
#: was enough where three frames alone chose a mirror posture (docs/gui.md, "A scripted
#: correction session"); two keep F6 at 5 frames' cost.
FIT_CONTEXT = 2


class FittingMixin:
    """The fitter, fits of frames and their results as they arrive."""

    # -- fitting ------------------------------------------------------------------------
    def _fit_model(self):
        """The project model the fit uses: a keypoint project of route "3d" is fitted to
        its triangulated points without cameras (:func:`videotrack.markerless.route.fitting_model`);
        the views keep the cameras to draw."""
        if self.keypoints is None:
            return self.model
        return backend.fitting_model(self.model, self.keypoints)

    def _fitter(self, body: Body | None = None, whole_video: bool = False):
        """The fitter of the session's chain, cameras and settings. Only a fit of the whole
        video measures the threshold on it (``threshold_mode = "auto"``); any other (some
        frames, a re-fit, a correction) decides statuses by the bar the window shows: a
        threshold measured on a few frames would be noise, and it would move the bar."""
        if self.model is None or self.body is None:
            raise VideoTrackError("no chain and cameras: set them under Project ▸ Settings",
                                  file=self.config_path)
        params = self.params
        if not whole_video and params.threshold_mode == "auto":
            params = replace(params, threshold_mode="absolute",
                             reanalysis_threshold=self.threshold)
        if not whole_video and params.noise_floor_px is not None and params.noise_px is None:
            # judged by the video's noise; without a fit of the whole video, by E alone
            params = (replace(params, noise_px=max(self.measured_noise)) if self.measured_noise
                      else replace(params, noise_floor_px=None))
        fitter = replace(self._fit_model(), params=params).fitter(body or self.body)
        observed = self.fit_detections
        if observed is None or not fitter.match_measured:
            return fitter
        # decided on the whole video, so that a re-fit or a correction of one frame is matched
        # as the fit of every frame was ('auto' would decide on that one frame); once per
        # video, chain and settings (it triangulates a sample of frames)
        key = (observed, self.model, body or self.body, self.params)
        if any(a is not b for a, b in zip(self._matched[:4], key, strict=True)):
            self._matched = (*key, *fitter.match_why(observed))
        return replace(self._fit_model(), params=replace(params, match=self._matched[4])
                       ).fitter(body or self.body)

    def _match_note(self) -> str:
        """Where 'auto' matched the markers of this video and why (for the status line of a
        fit), or "" where the settings or the views decide."""
        if self._matched[0] is not self.fit_detections or self._matched[3] is not self.params:
            return ""
        how = "in 3D" if self._matched[4] == "3d" else "per view"
        return f"; markers matched {how}: {self._matched[5]}"

    def _fitter_or_report(self, whole_video: bool = False):
        """The fitter for the next task, or None after reporting on :attr:`error` why there
        is none (one line)."""
        try:
            return self._fitter(whole_video=whole_video)
        except LocatedError as err:
            self.error.emit(str(err))
            return None

    def _missing_input(self) -> str | None:
        """Why there is nothing to fit, or None."""
        if self.fit_detections is not None:
            return None
        if self.keypoint_project:
            return "no keypoints: the project's [keypoints] files could not be read"
        return "no detections: run Detect markers first"

    def fit(self, frames: Iterable[int] | None = None, label: str = "fit") -> bool:
        """Fit frames in the background (default: every frame not corrected by hand).

        Results replace those frames' results as they arrive; the whole run is one undo
        step. Returns False when it could not start.
        """
        if self.busy:
            self.error.emit("another task is running; wait for it or cancel it")
            return False
        missing = self._missing_input()
        if missing:
            self.error.emit(missing)
            return False
        some = frames is not None  # not Fit all: these frames get neighbours as context
        if frames is None:
            frames = [f for f in range(self.n_frames)
                      if self.results.get(f) is None or self.results[f].status
                      != backend.CORRECTED]
        frames = sorted({int(f) for f in frames if 0 <= int(f) < self.n_frames})
        if not frames:
            self.status.emit("nothing to fit")
            return False
        fitter = self._fitter_or_report(whole_video=not some)
        if fitter is None:
            return False
        wanted = set(frames)
        if some and self.params.candidates > 1:
            frames = self._with_context(frames)
        self._edit = Edit(f"{label} ({len(wanted)} frames)")
        worker = FitWorker(fitter, self.fit_detections, frames, backend.fit_chunk_size())
        # a fit let go at a cancel (_let_go) reports nothing more; context frames are not kept
        worker.resultsReady.connect(lambda b: None if worker.released else self._fit_results(
            [r for r in b if r.frame in wanted]))
        worker.progressed.connect(lambda *a: None if worker.released else self.progress.emit(*a))
        worker.failed.connect(lambda m: None if worker.released else self._failed(m))
        worker.finished.connect(lambda: None if worker.released else self._fit_done(worker))
        self._start(worker, f"fitting {len(frames)} frames{self._match_note()} …")
        self._measuring = not some  # only a fit of the whole video measures the threshold
        return True

    def _with_context(self, frames: list[int]) -> list[int]:
        """The frames to fit for a fit of some frames: with up to :data:`FIT_CONTEXT` frames
        before and after each stretch, fitted but not kept, so that the path through time
        sees the movement around it (after a marker is hidden in a view, a few frames alone
        cannot tell a posture from its mirror; with their neighbours they can)."""
        out = set(frames)
        for f in frames:
            out.update(range(max(0, f - FIT_CONTEXT), min(self.n_frames, f + FIT_CONTEXT + 1)))
        return sorted(out)

    def _fit_results(self, batch: list) -> None:
        """Store results as they arrive (part of the running task's undo step). An item is a
        result (a fit: the frame's pins are released) or ``(result, pins)`` (a correction
        that pins those axes)."""
        edit = self._edit
        for item in batch:
            r, pins = item if isinstance(item, tuple) else (item, None)
            edit.record_result(r.frame, self.results.get(r.frame), r)
            self.results[r.frame] = r
            if self._measuring and np.isfinite(r.threshold):
                self.measured_threshold = float(r.threshold)
            if pins or r.frame in self.pins:
                edit.record_pins(r.frame, self.pins.pop(r.frame, None), pins)
                if pins:
                    self.pins[r.frame] = dict(pins)
        frames = [(i[0] if isinstance(i, tuple) else i).frame for i in batch]
        self._freshen(edit, frames)
        self._mark("results")
        self.resultsChanged.emit(frames)

    def _fit_done(self, worker) -> None:
        noise = getattr(getattr(worker, "fitter", None), "noise", None)
        if self._measuring and noise is not None and noise.source == "measured":
            self.measured_noise = [float(s) for s in noise.sigma_px]
        edit, self._edit = self._edit, None
        if edit is not None:
            self._push(edit)
        verb = "cancelled after" if worker.cancelled or worker.released else "fitted"
        count = worker.count if edit is None else len(edit.results)
        summary = getattr(worker, "summary", "")
        self.status.emit(f"{verb} {count} frames" + (f"; {summary}" if summary else ""))

    def _run_frames(self, work: Callable, label: str, what: str) -> bool:
        """Run ``work(worker)``, which publishes results frame by frame (items as in
        :meth:`_fit_results`), in the background: results show as they arrive, the run is
        one undo step, a cancel keeps what arrived."""
        if self.busy:
            self.error.emit("another task is running; wait for it or cancel it")
            return False
        self._edit = Edit(label)
        worker = TaskWorker(work)
        worker.published.connect(self._fit_results)
        worker.progressed.connect(self.progress)
        worker.failed.connect(self._failed)
        worker.finished.connect(lambda: self._fit_done(worker))
        self._start(worker, what)
        return True

    def fit_bad(self) -> bool:
        """Fit again the frames whose error is above the threshold."""
        return self.fit(adapters.bad_frames(self.results, self.threshold), "re-fit bad frames")

