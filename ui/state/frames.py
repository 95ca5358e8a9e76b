"""What the open project has (views, cameras, records, the bar), the current frame, and
the posture drawn on it (a part of :class:`ui.state.Session`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from kinematics.model import Body
from ui import adapters
from videotrack.errors import VideoTrackError
from videotrack.markerless.route import DEFAULT_FPS

#: Video frames kept decoded for scrubbing back and forth.
FRAME_CACHE = 48


class FramesMixin:
    """The records, frame navigation, video images and the drawn posture."""

    # -- what there is ------------------------------------------------------------------
    @property
    def view_names(self) -> list[str]:
        return [v.name for v in self.views]

    @property
    def cameras(self) -> list:
        """The camera of each view, in view order (empty without a model)."""
        return [] if self.model is None else list(self.model.cameras.values())

    @property
    def error_views(self) -> list[str]:
        """The views of the fit's error columns: the views, or none when the fit is to
        triangulated 3D points (a keypoint project of route "3d")."""
        if self.keypoints is not None:
            return list(self.keypoints.view_names)
        return self.view_names

    @property
    def n_frames(self) -> int:
        """Records of the project: those of the detections (or keypoints), else the
        video's frames."""
        if self.keypoints is not None:
            return self.keypoints.n_records
        if self.detections is not None:
            return self.detections.n_records
        return 0 if self.videos is None else self.videos.n_frames

    @property
    def threshold(self) -> float:
        """The bar (pixels): frames above it are highlighted and need attention. It is the
        threshold the last fit used — with ``threshold_mode = "auto"`` the one it measured on
        the video — until the user sets one (:meth:`set_bar`)."""
        if self.params is None:
            return float("inf")
        if (self.params.threshold_mode == "auto" and not self.bar_typed
                and self.measured_threshold is not None):
            return self.measured_threshold
        return self.params.reanalysis_threshold

    def set_bar(self, value: float) -> None:
        """The user's bar: it replaces the fit's threshold in the window from now on."""
        self.set_params(replace(self.params, reanalysis_threshold=float(value)))
        self.bar_typed = True

    @property
    def display_body(self) -> Body | None:
        """The chain drawn: the chain editor's preview, else the session's chain."""
        return self.preview_body if self.preview_body is not None else self.body

    @property
    def fps(self) -> float:
        if self.keypoints is not None:
            return float(self.config["video"]["fps"] or DEFAULT_FPS)
        if self.detections is not None:
            return self.detections.frame_rate
        return 25.0 if self.videos is None else self.videos.fps

    def _records(self):
        """What numbers the records: the keypoints, the detections or None."""
        return self.keypoints if self.keypoints is not None else self.detections

    def video_frame(self, record: int) -> int:
        """Video frame of a record (records are half-frames when de-interlacing; a keypoint
        project's records are the frames its files have in common)."""
        records = self._records()
        if records is not None and 0 <= record < records.n_records:
            return int(records.video_frames[record])
        return int(record)

    def time_of(self, record: int) -> float:
        """Seconds of a record, as the results file writes them."""
        records = self._records()
        if records is not None and 0 <= record < records.n_records:
            return float(records.times[record])
        return record / self.fps if self.fps else 0.0

    # -- current frame ------------------------------------------------------------------
    def set_frame(self, frame: int) -> None:
        """Make ``frame`` (clipped to the records) the current one."""
        frame = int(np.clip(frame, 0, max(self.n_frames - 1, 0)))
        if frame != self.frame:
            self.frame = frame
            self.preview_angles = None
            self.frameChanged.emit(frame)

    def step(self, delta: int) -> None:
        self.set_frame(self.frame + delta)

    def view_images(self, record: int | None = None) -> list[np.ndarray]:
        """The image of each view of a record (ROI cut and mirrored as set), BGR or grey;
        a keypoint project without video gets its blank canvases."""
        if self.canvas is not None:
            return self.canvas
        if self.videos is None or not self.views:
            return []
        index = self.video_frame(self.frame if record is None else record)
        frames = self._frames.get(index)
        if frames is None:
            try:
                frames = self.videos.read(index)
            except VideoTrackError as err:
                self.status.emit(str(err))
                return []
            self._frames[index] = frames
            while len(self._frames) > FRAME_CACHE:
                self._frames.popitem(last=False)
        self._frames.move_to_end(index)
        return [v.cut(frames[v.video]) for v in self.views]

    def full_frames(self, record: int | None = None) -> tuple:
        """Whole video frames of a record, one per video (for drawing ROIs)."""
        self.view_images(record)
        index = self.video_frame(self.frame if record is None else record)
        return self._frames.get(index, ())


    def posture(self, record: int | None = None) -> tuple[np.ndarray, np.ndarray, str]:
        """``(angles_deg, roots, source)`` drawn for a record; source is ``preview``,
        ``fit`` (any result, corrected included) or ``start`` (the histogram means)."""
        record = self.frame if record is None else record
        body = self.display_body
        result = self.results.get(record)
        roots = (np.asarray(result.root_positions) if result is not None
                 else body.root_positions())
        mean, locked = self._mean_posture(body)
        if record == self.frame and self.preview_angles is not None:
            angles, source = self.preview_angles, "preview"
        elif result is not None and np.all(np.isfinite(result.angles_deg)):
            angles, source = np.asarray(result.angles_deg, float), "fit"
        else:
            return mean.copy(), roots, "start"
        # locked axes at the drawn chain's values (the chain editor may have moved a lock)
        return np.where(locked, mean, angles), roots, source

    def _mean_posture(self, body: Body) -> tuple[np.ndarray, np.ndarray]:
        """The histogram means and locked mask of a body, kept while the body is the same
        object (bodies are immutable; the means cost milliseconds, asked on every step)."""
        if self._means[0] is not body:
            self._means = (body, body.mean_posture_deg(), body.locked_mask())
        return self._means[1], self._means[2]

    def geometry(self, record: int | None = None) -> adapters.PostureGeometry | None:
        """3D points and skeleton of the drawn posture (None without a chain)."""
        if self.display_body is None:
            return None
        angles, roots, _ = self.posture(record)
        return adapters.posture_geometry(self.display_body, angles, roots)

    def overlays(self, record: int | None = None) -> list[adapters.ViewOverlay]:
        """Projected markers and skeleton of the drawn posture, one per view."""
        geometry = self.geometry(record)
        if geometry is None or not self.cameras:
            return []
        return adapters.project_geometry(geometry, self.cameras)

    def alternative_overlays(self, record: int | None = None) -> list[adapters.ViewOverlay]:
        """Projected other posture of an ``ambiguous`` frame, the one A swaps to, one per
        view; empty where the frame is not ambiguous, has no other candidate, or a preview
        is drawn."""
        record = self.frame if record is None else record
        result = self.results.get(record)
        if (result is None or result.status != "ambiguous" or len(result.candidates) < 2
                or self.display_body is None or not self.cameras
                or (record == self.frame and self.preview_angles is not None)):
            return []
        other = result.candidates[1]
        angles = np.asarray(other.angles_deg, float)
        if not np.all(np.isfinite(angles)):
            return []
        mean, locked = self._mean_posture(self.display_body)
        angles = np.where(locked, mean, angles)  # as posture() draws it once chosen
        geometry = adapters.posture_geometry(self.display_body, angles,
                                             np.asarray(other.root_positions))
        return adapters.project_geometry(geometry, self.cameras)

    # -- previews (chain editor, sliders) -----------------------------------------------
    def set_preview_body(self, body: Body | None) -> None:
        """Draw ``body`` instead of the session's chain (None: stop previewing)."""
        self.preview_body = body
        self.bodyChanged.emit()

    def set_preview_angles(self, angles_deg) -> None:
        """Draw this posture in the current frame until the frame changes (None: stop)."""
        self.preview_angles = None if angles_deg is None else np.asarray(angles_deg, float)
        self.postureChanged.emit()

