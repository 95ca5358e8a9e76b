"""What the main window's keys, buttons and mouse do to the session besides playing and
opening dialogs: marker drags, nudges and hiding, detection edits, the bar, fitting some
frames, going to the frames that need attention, accepting, re-fitting from a frame and
interpolating."""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QInputDialog

from kinematics.errors import LocatedError
from ui import adapters

#: One marker nudge key moves the selected model marker this far (view pixels).
MARKER_NUDGE_PX = 0.5


class ActionsMixin:
    """The correcting actions of :class:`~ui.views.main_window.MainWindow`."""

    # -- interaction --------------------------------------------------------------------
    def _marker_dragged(self, view: int, marker: int, x: float, y: float,
                        frame: int | None = None) -> None:
        self.session.drag_marker(view, marker, (x, y), refit=self.correction.refit.isChecked(),
                                 frame=frame)

    def select_marker(self, view: int, marker: int) -> None:
        """The model marker the marker nudge keys move (ringed in its view)."""
        self.flush_marker_nudge()
        self.selected_marker = (view, marker)
        for k, v in enumerate(self.video_views):
            v.select_marker(marker if k == view else None)
        s = self.session
        if s.display_body is not None and marker < len(s.display_body.marker_names):
            s.status.emit(f"Alt+arrows move {s.display_body.marker_names[marker]} in "
                          f"{s.view_names[view]} by {MARKER_NUDGE_PX:g} px")

    def toggle_hidden(self) -> None:
        """Mark the selected model marker hidden in its view, or seen again: in the frames
        selected in the table if the frame shown is one of several, else in this frame."""
        s = self.session
        if self.selected_marker is None or self.selected_marker[0] >= len(self.video_views):
            s.status.emit("click a model marker in a video view first (H hides it there)")
            return
        self.correction.flush()
        self.flush_marker_nudge()
        frames = self.table.selected_frames()
        view, marker = self.selected_marker
        s.toggle_hidden(view, marker, frames if len(frames) > 1 and s.frame in frames
                        else None)

    def nudge_marker(self, dx: int, dy: int) -> None:
        """Move the selected model marker by (dx, dy) nudges: drawn at once, then, once the
        keys rest for the panel's settle time, corrected as a drag to that point."""
        s = self.session
        if self.selected_marker is None or self.selected_marker[0] >= len(self.video_views):
            s.status.emit("click a model marker in a video view first (Alt+arrows move it)")
            return
        view, marker = self.selected_marker
        pending = self._marker_nudge
        if pending is not None and pending[:3] != (s.frame, view, marker):
            self.flush_marker_nudge()
            pending = None
        x, y = pending[3:] if pending is not None else self.video_views[view].marker_xy(marker)
        if not np.isfinite(x + y):
            return
        x, y = x + dx * MARKER_NUDGE_PX, y + dy * MARKER_NUDGE_PX
        self._marker_nudge = (s.frame, view, marker, x, y)
        self.video_views[view].show_marker_at(marker, x, y)
        self._marker_settle.start()  # restarted by every key

    def flush_marker_nudge(self) -> None:
        """Correct the frame for the pending marker nudges now (after a running task)."""
        if self._marker_nudge is None or self.session.closed:
            self._marker_nudge = None
            return
        if self.session.busy:
            self._marker_settle.start()
            return
        self._marker_settle.stop()
        (frame, view, marker, x, y), self._marker_nudge = self._marker_nudge, None
        self._marker_dragged(view, marker, x, y, frame=frame)

    def _snapped(self, view: int, x: float, y: float) -> tuple[float, float]:
        """A click moved to the intensity centroid of the marker under it."""
        from videotrack.detect.edits import snap_to_centroid

        images = self.session.view_images()
        return snap_to_centroid(images[view], (x, y)) if view < len(images) else (x, y)

    def _detection_removed(self, view: int, x: float, y: float) -> None:
        self.session.edit_detection(view, remove=(x, y))

    def _detection_added(self, view: int, x: float, y: float) -> None:
        self.session.edit_detection(view, add=self._snapped(view, x, y))

    def _detection_moved(self, view: int, x0: float, y0: float, x: float, y: float) -> None:
        self.session.edit_detection(view, remove=(x0, y0), add=self._snapped(view, x, y))

    def _threshold_changed(self, value: float) -> None:
        s = self.session
        if s.params is not None and value > 0:
            s.set_bar(value)
            self.table.source.reset()
            self.refresh_timeline()

    def _show_threshold(self) -> None:
        """The bar box shows the session's bar (e.g. the threshold a fit just measured)."""
        s = self.session
        value = round(s.threshold if np.isfinite(s.threshold) else 0.0,
                      self.threshold.decimals())
        if self.threshold.value() != value:
            self.threshold.blockSignals(True)
            self.threshold.setValue(value)
            self.threshold.blockSignals(False)
            self.table.source.reset()

    def fit_range(self) -> None:
        from videotrack.detect.video import parse_frame_range, resolve_frames

        s = self.session
        text, ok = QInputDialog.getText(self, "Fit range", "Frames A:B (B excluded):",
                                        text=f"{s.frame}:{s.n_frames}")
        if not ok:
            return
        try:
            frames = resolve_frames(parse_frame_range(text), s.n_frames)
        except (ValueError, LocatedError) as err:
            self.show_error(f"frames '{text}': {err}")
            return
        s.fit(frames, "fit range")

    def fit_selected(self) -> None:
        frames = self.table.selected_frames()
        if frames:
            self.session.fit(frames, "fit selected")

    def next_attention(self, direction: int) -> bool:
        """Go to the next (``direction`` > 0) or previous frame needing attention."""
        s = self.session
        frame = adapters.next_to_check(s.results, s.threshold, s.frame, direction)
        if frame is None:
            s.status.emit("no frame needing attention "
                          + ("after" if direction > 0 else "before") + " this one")
            return False
        s.set_frame(frame)
        return True

    def accept_and_next(self) -> None:
        """Accept the frame shown (status corrected) and go to the next needing attention."""
        s = self.session
        result = s.results.get(s.frame)
        set_by_hand = (self.correction.pending is not None or self._marker_nudge is not None
                       or (result is not None and result.status == "corrected"))
        self.correction.flush()  # pending steps are re-fitted as a correction: set by hand
        self.flush_marker_nudge()
        if not set_by_hand:
            s.accept()
        self.next_attention(1)

    def accept_selected(self) -> None:
        self.session.accept(self.table.selected_frames() or [self.session.frame])

    def refit_from(self, direction: int) -> None:
        self.correction.flush()
        self.flush_marker_nudge()
        self.session.refit_from(direction)

    def interpolate(self) -> None:
        """Interpolate over the table selection, or from the previous corrected frame to
        the frame shown."""
        s = self.session
        frames = self.table.selected_frames()
        if len(frames) >= 2:
            first, last = frames[0], frames[-1]
        else:
            before = [f for f, r in s.results.items()
                      if f < s.frame and r.status == "corrected"]
            if not before:
                s.error.emit("interpolation needs a corrected frame before this one (or "
                             "select the range in the table)")
                return
            first, last = max(before), s.frame
        s.interpolate(first, last, refit=self.correction.refit.isChecked())

