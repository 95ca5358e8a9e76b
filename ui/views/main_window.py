"""The main window, laid out as the paper's Fig. 4.

Left (1): the control panel, fitting buttons and the per-frame error table. Middle (2): one
video view per view with the detected centroids and the model's projection. Right (3): the
3D posture and the manual correction sliders. Bottom: playback, the frame slider and the
timeline of angles and error. The status bar says what the program is doing.

Its widgets are built in :mod:`ui.views.window_layout` and its correcting actions are in
:mod:`ui.views.window_actions`; here are what it redraws on the session's signals,
playback, its dialogs and closing.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import (
    QFileDialog,
    QMainWindow,
    QMessageBox,
    QStyle,
)

from ui import adapters
from ui.state import Session
from ui.views import style
from ui.views.correction_panel import SETTLE_MS
from ui.views.video_view import VideoView
from ui.views.window_actions import ActionsMixin
from ui.views.window_layout import WindowLayoutMixin

#: Playback never asks for more frames per second than this.
MAX_PLAY_FPS = 50.0


class MainWindow(WindowLayoutMixin, ActionsMixin, QMainWindow):
    """VideoTrack's main window around one :class:`~ui.state.Session`."""

    def __init__(self, session: Session | None = None, use_opengl: bool | None = None,
                 parent=None) -> None:
        super().__init__(parent)
        style.configure()
        self.session = session or Session(self)
        self.errors: list[str] = []  # every message shown, newest last
        self.video_views: list[VideoView] = []
        self._views_of: tuple | None = None  # (project file, view names) of the video views
        self.setWindowTitle("VideoTrack")
        self.resize(1500, 900)
        self._build_actions()
        self._build_menus()
        self._build_layout(use_opengl)
        self._build_status_bar()
        self._timeline_timer = QTimer(self, singleShot=True, interval=250)
        self._timeline_timer.timeout.connect(self.refresh_timeline)
        self._play_timer = QTimer(self)
        self._play_timer.timeout.connect(self._next_play_frame)
        #: (view, marker) the marker nudge keys move, or None
        self.selected_marker: tuple[int, int] | None = None
        #: marker nudges not yet re-fitted: (frame, view, marker, x, y)
        self._marker_nudge: tuple[int, int, int, float, float] | None = None
        self._marker_settle = QTimer(self, singleShot=True, interval=SETTLE_MS)
        self._marker_settle.timeout.connect(self.flush_marker_nudge)
        self._connect()
        self._update_actions()

    # -- signals (the widgets are built by WindowLayoutMixin) -------------------------
    def _connect(self) -> None:
        s = self.session
        s.projectChanged.connect(self._project_changed)
        s.frameChanged.connect(lambda *_: self.flush_marker_nudge())
        s.frameChanged.connect(self.refresh_frame)
        s.bodyChanged.connect(self.refresh_overlays)
        s.bodyChanged.connect(self._schedule_timeline)
        s.postureChanged.connect(self.refresh_overlays)
        s.resultsChanged.connect(self._results_changed)
        s.detectionsChanged.connect(self._project_changed)
        s.busyChanged.connect(self._busy_changed)
        s.progress.connect(self._progress)
        s.status.connect(lambda msg: self.statusBar().showMessage(msg))
        s.error.connect(self.show_error)
        s.dirtyChanged.connect(lambda *_: self._update_title())
        s.undoChanged.connect(self._update_actions)
        for sig in (s.projectChanged, s.bodyChanged, s.resultsChanged, s.undoChanged):
            sig.connect(self._update_stale)

    def _update_stale(self, *_) -> None:
        """Warn while shown errors are of an earlier chain (after a chain edit)."""
        n = len(self.session.stale)
        self.stale_label.setVisible(n > 0)
        self.stale_label.setText(
            f"⚠ errors of {n} frame{'s' if n != 1 else ''} are of the previous chain: "
            "fit them again (F5; F7 for corrected frames)" if n else "")

    # -- project ------------------------------------------------------------------------
    def open_project(self, path, trial: str | None = None) -> bool:
        """Open a project file (or a trial of a project folder)."""
        return self.session.open_project(path, trial)

    def choose_project(self) -> None:
        if not self._may_discard():
            return
        path, _ = QFileDialog.getOpenFileName(self, "Open project", "",
                                              "Project files (*.toml);;All files (*)")
        if path:
            self.open_project(path)

    def choose_chain_file(self) -> None:
        s = self.session
        if s.config is None:
            return
        path, _ = QFileDialog.getOpenFileName(self, "Chain file", str(s.config.folder),
                                              "Chain XML (*.xml);;All files (*)")
        if path:
            raw = dict(s.raw_config)
            raw["chain"] = {**raw.get("chain", {}),
                            "path": adapters.relative_path(path, s.config.folder)}
            s.apply_config(raw)

    def _project_changed(self) -> None:
        s = self.session
        views_of = (s.config_path, tuple(s.view_names))
        if views_of != self._views_of:  # the same views keep their zoom and pan (settings OK)
            self._views_of = views_of
            for v in self.video_views:
                v.setParent(None)
                v.deleteLater()
            self.video_views = []
            self.selected_marker = self._marker_nudge = None
            for k, name in enumerate(s.view_names):
                view = VideoView(k, name)
                view.markerDragged.connect(self._marker_dragged)
                view.markerSelected.connect(self.select_marker)
                view.detectionRemoved.connect(self._detection_removed)
                view.detectionAdded.connect(self._detection_added)
                view.detectionMoved.connect(self._detection_moved)
                view.set_marker_colours(s.mapped is not None)
                if s.mapped is not None:  # start where the animal is
                    view.home = adapters.keypoint_box(s.mapped.xy[k])
                self.views_splitter.addWidget(view)
                self.video_views.append(view)
        n = s.n_frames
        for w in (self.slider, self.frame_box):
            w.blockSignals(True)
            w.setRange(0, max(n - 1, 0))
            w.blockSignals(False)
        # the 3D route's error is a distance in the chain's length units
        units = s.body.units if (s.body is not None and s.keypoints is not None
                                 and not s.error_views) else "px"
        self.threshold.setSuffix(f" {units}")
        self._show_threshold()
        if s.body is not None:
            self.posture_view.set_extent(s.body.root_positions().mean(axis=0),
                                         adapters.body_reach(s.body))
        if s.config is not None:
            body = s.body.name if s.body is not None else "no chain"
            self.project_label.setText(f"{self._project_name()}\n{n} frames · "
                                       f"{len(s.view_names)} views · {body}")
        self._update_title()
        self._update_actions()
        self.refresh_timeline()
        self.refresh_frame(s.frame)

    def _project_name(self) -> str:
        """The project file's name, or the trial folder of a merged trial config."""
        s = self.session
        if s.config is None:
            return "no project"
        return s.config.path.name if s.editable else f"trial {s.config.folder.name}"

    def _update_title(self) -> None:
        s = self.session
        self.setWindowTitle(f"VideoTrack — {self._project_name()}{' *' if s.dirty else ''}")

    def _update_actions(self) -> None:
        s = self.session
        has_project = s.config is not None
        ready = has_project and not s.busy
        markerless = s.keypoint_project
        can_fit = ready and s.model is not None and s.fit_detections is not None
        for act in (self.act_fit_all, self.act_fit_current, self.act_fit_range,
                    self.act_fit_selected, self.act_fit_bad, self.act_refit_forward,
                    self.act_refit_backward, self.act_interpolate):
            act.setEnabled(can_fit)
        self.act_accept_selected.setEnabled(ready)
        self.act_swap.setEnabled(ready)  # its edit of several frames waits for a task
        self.act_detect.setEnabled(ready and not markerless)
        # the settings dialog edits views and filters of marker videos; a keypoint
        # project's [keypoints] are edited in its file
        self.act_settings.setEnabled(ready and s.editable and not markerless)
        self.act_chain_file.setEnabled(ready and s.editable)
        for act in (self.act_chain_editor, self.act_histograms):
            act.setEnabled(ready and s.body is not None)
        self.act_save.setEnabled(has_project and not s.busy)
        self.act_open.setEnabled(not s.busy)
        self.act_cancel.setEnabled(s.busy)
        self.act_undo.setEnabled(s.can_undo)
        self.act_redo.setEnabled(s.can_redo)
        self.act_undo.setText(f"&Undo {s.undo_label}".rstrip())
        self.act_redo.setText(f"&Redo {s.redo_label}".rstrip())

    # -- drawing ------------------------------------------------------------------------
    def refresh_frame(self, frame: int | None = None) -> None:
        """Draw the current frame: images, detections, model, 3D posture, controls."""
        s = self.session
        frame = s.frame
        for w in (self.slider, self.frame_box):
            w.blockSignals(True)
            w.setValue(frame)
            w.blockSignals(False)
        self.timeline.set_frame(frame)
        images = s.view_images()
        detections = s.frame_detections()
        keypoints = s.frame_keypoints()
        for k, view in enumerate(self.video_views):
            view.set_image(images[k] if k < len(images) else None)
            view.set_detections(detections[k])
            view.set_keypoints(keypoints[k] if keypoints is not None else None)
        self.time_label.setText(f"{s.time_of(frame):.3f} s")
        self.refresh_overlays()

    def refresh_overlays(self) -> None:
        """Re-project the drawn posture into every view and the 3D view."""
        s = self.session
        overlays = s.overlays()
        names = s.display_body.marker_names if s.display_body is not None else []
        detections = s.frame_detections()
        keypoints = s.frame_keypoints()
        result = s.results.get(s.frame)
        hidden = s.hidden_in_frame()
        alternatives = s.alternative_overlays()
        for k, view in enumerate(self.video_views):
            view.set_hidden(hidden[k] if k < len(hidden) else ())
            view.set_overlay(overlays[k] if k < len(overlays) else None, names)
            view.set_alternative(alternatives[k] if k < len(alternatives) else None)
            if keypoints is None:
                lines = [f"{len(detections[k])} detected"]
            else:
                lines = [f"{int(np.isfinite(keypoints[k][:, 0]).sum())} keypoints"]
            per_view = np.asarray(result.error_per_view) if result is not None else ()
            if k < len(per_view) and np.isfinite(per_view[k]):
                lines.append(f"error {per_view[k]:.2f} px"
                             + (" (previous chain)" if s.frame in s.stale else ""))
            if s.canvas is not None:
                lines.append("(no video)")
            view.set_info("  ".join(lines))
        self.posture_view.set_geometry(s.geometry())
        matched = (adapters.matched_points(overlays, detections) if keypoints is None
                   else adapters.own_keypoints(overlays, keypoints))
        if hidden.size and matched.size:  # no residual where a marker is hidden
            h = hidden[:matched.shape[0], :matched.shape[1]]
            matched[:h.shape[0], :h.shape[1]][h] = np.nan
        for k, view in enumerate(self.video_views):
            view.set_residuals(matched[k] if k < len(matched) else None)
        self.marker_table.set_residuals(adapters.residuals_of(overlays, matched), names,
                                        s.view_names, hidden)

    def _results_changed(self, frames) -> None:
        if self.session.frame in frames:
            self.refresh_overlays()
        self._show_threshold()
        self._schedule_timeline()

    def _schedule_timeline(self) -> None:
        if not self._timeline_timer.isActive():
            self._timeline_timer.start()

    def refresh_timeline(self) -> None:
        """Redraw the timeline and the summary (throttled while results stream in)."""
        s = self.session
        if s.body is None:
            return
        line = adapters.timeline(s.results, s.n_frames, s.body.n_axes)
        labels = [(k, s.body.axis_labels[k]) for k in adapters.free_axes(s.body)]
        self.timeline.set_data(line, labels, s.threshold)
        self.timeline.set_frame(s.frame)
        n_bad = len(adapters.bad_frames(s.results, s.threshold))
        n_corr = sum(r.status == "corrected" for r in s.results.values())
        n_todo = len(adapters.frames_to_check(s.results, s.threshold))
        self.summary.setText(f"{len(s.results)} of {s.n_frames} frames fitted · {n_bad} above "
                             f"threshold · {n_corr} corrected · {n_todo} to check")

    def show_shortcuts(self):
        """The shortcut sheet, made from :data:`ui.views.shortcuts.COMMANDS`."""
        from ui.dialogs.shortcut_sheet import ShortcutSheet

        dialog = ShortcutSheet(self)
        dialog.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        dialog.show()
        return dialog

    def toggle_play(self) -> None:
        if self._play_timer.isActive():
            self._play_timer.stop()
            self.act_play.setIcon(self.style().standardIcon(QStyle.StandardPixmap.SP_MediaPlay))
            return
        if self.session.frame >= self.session.n_frames - 1:
            self.session.set_frame(0)
        self._play_timer.start(int(1000 / min(max(self.session.fps, 1.0), MAX_PLAY_FPS)))
        self.act_play.setIcon(self.style().standardIcon(QStyle.StandardPixmap.SP_MediaPause))

    @property
    def playing(self) -> bool:
        return self._play_timer.isActive()

    def _next_play_frame(self) -> None:
        s = self.session
        if s.frame >= s.n_frames - 1:
            self.toggle_play()
        else:
            s.step(1)

    def _busy_changed(self, busy: bool) -> None:
        for view in self.video_views:
            view.editable = not busy
        self.progress.setVisible(busy)
        self.cancel_button.setVisible(busy)
        self.progress.setRange(0, 0)  # busy indicator until the first progress report
        if not busy:
            self.rate.setText("")
            self.table.source.reset()
            self.refresh_timeline()
            self.refresh_overlays()
        self.setCursor(Qt.CursorShape.BusyCursor if busy else Qt.CursorShape.ArrowCursor)
        self._update_actions()

    def _progress(self, done: int, total: int, rate: float) -> None:
        self.progress.setRange(0, max(total, 1))
        self.progress.setValue(done)
        self.rate.setText(f"{rate:.1f} frames/s")

    # -- dialogs ------------------------------------------------------------------------
    def show_error(self, message: str) -> None:
        """Show a one-line error in a (non-blocking) dialog and the status bar."""
        self.errors.append(message)
        self.statusBar().showMessage(message)
        box = QMessageBox(QMessageBox.Icon.Critical, "VideoTrack", message,
                          QMessageBox.StandardButton.Ok, self)
        box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        box.open()

    def open_chain_editor(self):
        from ui.dialogs.chain_editor import ChainEditor

        dialog = ChainEditor(self.session, self)
        dialog.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        dialog.open()
        return dialog

    def open_histograms(self):
        from ui.dialogs.histogram_dialog import HistogramDialog

        dialog = HistogramDialog(self.session, self)
        dialog.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        dialog.show()
        return dialog

    def open_project_dialog(self):
        from ui.dialogs.project_dialog import ProjectDialog

        dialog = ProjectDialog(self.session, self)
        dialog.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        dialog.open()
        return dialog

    # -- closing ------------------------------------------------------------------------
    def ask_unsaved(self) -> QMessageBox.StandardButton:
        """Ask what to do with unsaved changes: Save, Discard or Cancel."""
        parts = ", ".join(self.session.unsaved)
        return QMessageBox.question(
            self, "Unsaved changes", f"The project has unsaved changes ({parts}). Save them?",
            QMessageBox.StandardButton.Save | QMessageBox.StandardButton.Discard
            | QMessageBox.StandardButton.Cancel, QMessageBox.StandardButton.Save)

    def _may_discard(self) -> bool:
        if not self.session.dirty:
            return True
        answer = self.ask_unsaved()
        if answer == QMessageBox.StandardButton.Save:
            return self.session.save()
        return answer == QMessageBox.StandardButton.Discard

    def closeEvent(self, event) -> None:
        if not self._may_discard():
            event.ignore()
            return
        self._play_timer.stop()
        self.session.close()
        event.accept()
