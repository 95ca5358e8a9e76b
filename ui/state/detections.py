"""Detections and keypoints of a record, the user's edits of them (moved, added, removed,
hidden markers) and detecting markers (a part of :class:`ui.state.Session`)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

import numpy as np

from kinematics.errors import LocatedError
from kinematics.observe.observations import Observations
from ui import adapters
from ui.state import backend
from ui.state.history import Edit
from ui.state.workers import TaskWorker
from videotrack.detect import edits as detection_edits


class DetectionsMixin:
    """What the fit takes from the detections, and editing them."""

    @property
    def fit_detections(self):
        """What the fit and E use: the detections file with the user's edits, or a keypoint
        project's :class:`~kinematics.observe.observations.Observations`; Observations with the
        marks where markers are marked hidden in a view (None: nothing to fit)."""
        return self._edited_now()[1]

    def _edited_now(self) -> tuple:
        """(the detections with the user's edits, what the fit takes of them), cached."""
        source = self.keypoints.observations if self.keypoints is not None else self.detections
        key = (source, self.detection_edits, self.body)  # marks name the chain's markers
        if any(a is not b for a, b in zip(self._edited[:3], key, strict=True)):
            edited = obs = None
            if self.keypoints is not None:
                obs = source
                marks = self._hidden_marks(obs.n_frames)
                if marks is not None and obs.kind == "keypoints":
                    obs = obs.with_hidden(marks)
            elif source is not None:
                edited = obs = detection_edits.edited_detections(source, self.detection_edits)
                marks = self._hidden_marks(source.n_records)
                if marks is not None:
                    obs = Observations.unlabelled(edited.points, edited.offsets,
                                                  self.view_names).with_hidden(marks)
            self._edited = (*key, edited, obs)
        return self._edited[3:]

    def _hidden_marks(self, n_records: int) -> np.ndarray | None:
        """(records, views, markers) of the chain's markers hidden in a view, or None."""
        if self.body is None:
            return None
        return detection_edits.hidden_marks(self.detection_edits, n_records, len(self.views),
                                            self.body.marker_names)

    def hidden_in_frame(self, record: int | None = None) -> np.ndarray:
        """(n_views, n_markers) of the drawn chain's markers hidden in each view of a record
        (the GUI's H)."""
        record = self.frame if record is None else record
        body = self.display_body
        names = () if body is None else body.marker_names
        out = np.zeros((len(self.views), len(names)), bool)
        observed = self.keypoints.observations if self.keypoints is not None else None
        if observed is not None and observed.kind == "points3d":
            return out  # fitted to 3D points: a mark in a view means nothing there
        marks = self._marks_of(self.detection_edits, record, names)
        out = out if marks is None else marks
        shown = {} if self.model is None else self._fit_model().view_markers
        if shown and len(names) and len(self.views) == len(self.model.view_names):
            # a view of one colour of markers: the others are not matched there either
            out = out | backend.unseen_markers(
                {v: [m for m in ms if m in names] for v, ms in shown.items()},
                self.model.view_names, names)
        return out

    def frame_detections(self, record: int | None = None) -> list[np.ndarray]:
        """Detected centroids of a record, one (n, 2) array per view (none in a keypoint
        project: see :meth:`frame_keypoints`)."""
        record = self.frame if record is None else record
        edited = None if self.keypoints is not None else self._edited_now()[0]
        return adapters.frame_detections(edited, record, len(self.views))

    def frame_input(self, record: int | None = None):
        """What the fitter takes for one record (:func:`ui.state.backend.frame_input`)."""
        record = self.frame if record is None else record
        return backend.frame_input(self.fit_detections, record, len(self.views))

    def frame_keypoints(self, record: int | None = None) -> list[np.ndarray] | None:
        """A keypoint project's 2D keypoints of a record, one (n_markers, 3) array (x, y,
        score; NaN where missing) per view in the chain's marker order; None otherwise."""
        if self.mapped is None or self.display_body is None:
            return None
        record = self.frame if record is None else record
        return adapters.frame_keypoints(self.mapped, record,
                                        self.display_body.marker_names)


    # -- detection edits ----------------------------------------------------------------
    def edit_detection(self, view: int, remove=None, add=None, frame: int | None = None
                       ) -> bool:
        """Remove the detection at ``remove``, add one at ``add`` (both: move it) in a view
        of a frame (undoable). The fit and E use the edited detections at once: the frame's
        error is computed again for its posture (status kept)."""
        frame = self.frame if frame is None else int(frame)
        if self.keypoint_project:  # a keypoint is its tracker's label, not a blob
            self.status.emit("keypoints are not edited here: correct the posture instead "
                             "(sliders, drag a model marker), or fix the labels in the "
                             "tracker")
            return False
        if self.detections is None or not 0 <= frame < self.detections.n_records:
            self.error.emit("no detections to edit: run Detect markers first")
            return False
        if self.busy:  # a running fit has taken the detections as they were
            self.status.emit("wait for the running task to finish (or cancel it) first")
            return False
        edits = self.detection_edits
        if remove is not None:
            edits = detection_edits.remove_point(edits, frame, view, remove)
        if add is not None:
            edits = detection_edits.add_point(edits, frame, view, add)
        what = "move" if remove is not None and add is not None else (
            "remove" if remove is not None else "add")
        edit = Edit(f"{what} a detection in {self.view_names[view]}, frame {frame}",
                    detection_edits=(self.detection_edits, edits))
        return self._commit_edits(edit, edits, [frame])

    def _commit_edits(self, edit: Edit, edits, frames: list[int]) -> bool:
        """Apply detection edits ``edits`` as the undo step ``edit``: each of ``frames`` with a
        posture gets its E under them (status kept). The status bar shows the first frame's
        error."""
        for f in frames:
            result = self.results.get(f)
            if result is None or self.model is None or not np.all(
                    np.isfinite(result.angles_deg)):
                continue
            if self.keypoints is not None:  # the record's keypoints
                frame_input = self.keypoints.observations.take([f])
            else:
                frame_input = [detection_edits.apply_edit(self.detections.points_of(f, v),
                                                          edits.get((f, v)))
                               for v in range(len(self.views))]
            try:
                error, per_view = self._fitter().error(
                    result.angles_deg, frame_input, result.root_positions,
                    self._marks_of(edits, f, self.body.marker_names))
            except LocatedError as err:
                self.error.emit(str(err))
                return False
            edit.record_result(f, result, replace(result, error=error,
                                                  error_per_view=per_view,
                                                  marker_residuals=None))
        self._apply(edit, 1)
        self._push(edit)
        self.status.emit(edit.label + (f": error {self.results[frames[0]].error:.2f} px"
                                       if frames[0] in self.results else ""))
        return True

    def _marks_of(self, edits, frame: int, names) -> np.ndarray | None:
        """(n_views, len(names)) the markers ``names`` hidden in each view of one record under
        ``edits``, or None when none is."""
        marks = detection_edits.hidden_marks({k: e for k, e in edits.items() if k[0] == frame},
                                             frame + 1, len(self.views), names)
        return None if marks is None else marks[frame]

    def toggle_hidden(self, view: int, marker: int, frames: Iterable[int] | None = None
                      ) -> bool:
        """Mark a model marker hidden in a view (occluded, or its blob merged with another's)
        or seen again, in the frame shown or in ``frames`` (undoable, one step): the fit and
        E leave it out of that view at once. The frames' errors are computed again for their
        postures (status kept). In a keypoint project the marker's keypoint there counts as
        missing (a label the tracker put on the wrong spot)."""
        observed = self.fit_detections
        if observed is None or self.body is None:
            self.error.emit("no detections to mark: run Detect markers first"
                            if not self.keypoint_project else "no keypoints to mark")
            return False
        if isinstance(observed, Observations) and observed.kind == "points3d":
            self.error.emit("this project fits triangulated 3D points: a keypoint cannot be "
                            "hidden in one view ([keypoints] route = '2d' can)")
            return False
        if self.busy:
            self.status.emit("wait for the running task to finish (or cancel it) first")
            return False
        fitter = self._fitter_or_report()
        if fitter is None:
            return False
        if not self.keypoint_project and fitter.match_for(observed) == "3d":
            self.error.emit("markers are matched in 3D here (match): a marker cannot be hidden "
                            "in one view; set match = 'views' in the fitting settings first")
            return False
        shown = self.display_body.marker_names  # what was clicked: the drawn chain
        name = shown[marker] if 0 <= marker < len(shown) else None
        if name not in self.body.marker_names:
            self.status.emit("that marker is not in the chain yet: apply the chain edit first")
            return False
        unseen = fitter.unseen
        if unseen is not None and 0 <= view < len(unseen) and unseen[view][
                self.body.marker_names.index(name)]:
            self.status.emit(f"view {self.view_names[view]} does not show {name} ([[views]] "
                             f"model_markers): it is never matched there")
            return False
        frames = [self.frame] if frames is None else sorted({int(f) for f in frames})
        n_records = (observed.n_frames if isinstance(observed, Observations)
                     else observed.n_records)
        frames = [f for f in frames if 0 <= f < n_records]
        if not frames:
            self.status.emit("no detections in this frame to mark a marker hidden in")
            return False
        lead = self.frame if self.frame in frames else frames[0]  # the frame looked at
        hide = not detection_edits.is_hidden(self.detection_edits, lead, view, name)
        edits = self.detection_edits
        for f in frames:
            if detection_edits.is_hidden(edits, f, view, name) != hide:
                edits = detection_edits.toggle_hidden(edits, f, view, name)
        where = f"frame {frames[0]}" if len(frames) == 1 else \
            f"frames {frames[0]}–{frames[-1]}"
        edit = Edit(f"{'hide' if hide else 'show'} {name} in {self.view_names[view]}, {where}",
                    detection_edits=(self.detection_edits, edits))
        return self._commit_edits(edit, edits, frames)


    # -- detection ----------------------------------------------------------------------
    def detect(self) -> bool:
        """Detect markers in every frame (background) and save the detections file."""
        if self.keypoint_project:
            self.status.emit("a keypoint project has no markers to detect")
            return False
        if self.settings is None:
            self.error.emit("the project's views or filters are not valid")
            return False
        config = self.config

        def work(worker: TaskWorker):
            return backend.detect_markers(config, worker.report, worker.cancel_requested)

        def finish(run) -> None:
            self.detections, self.detections_path = run.detections, run.detections_path
            self._frames.clear()
            self.set_frame(min(self.frame, max(self.n_frames - 1, 0)))
            self.status.emit(f"wrote {run.detections_path}: {len(run.detections.points)} "
                             f"markers in {run.detections.n_records} frames")
            for message in run.warnings:
                self.status.emit(f"warning: {message}")
            self.detectionsChanged.emit()
            self.frameChanged.emit(self.frame)

        return self.run_task(work, finish, "detecting markers …")

