"""The main window, laid out as the paper's Fig. 4.

Left (1): the control panel, fitting buttons and the per-frame error table. Middle (2): one
video view per view with the detected centroids and the model's projection. Right (3): the
3D posture and the manual correction sliders. Bottom: playback, the frame slider and the
timeline of angles and error. The status bar says what the program is doing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QAction
from PySide6.QtWidgets import (
    QFileDialog,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QInputDialog,
    QLabel,
    QMainWindow,
    QMessageBox,
    QProgressBar,
    QPushButton,
    QSizePolicy,
    QSlider,
    QSplitter,
    QStyle,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from kinematics.errors import LocatedError
from ui import adapters, shortcuts, style
from ui.axis_sliders import FocusSpinBox, FrameSpinBox
from ui.correction_panel import SETTLE_MS, CorrectionPanel
from ui.frame_table import FrameTable
from ui.marker_table import MarkerTable
from ui.posture_view import PostureView
from ui.session import Session
from ui.timeline import TimelineView
from ui.video_view import VideoView

#: Playback never asks for more frames per second than this.
MAX_PLAY_FPS = 50.0
#: One marker nudge key moves the selected model marker this far (view pixels).
MARKER_NUDGE_PX = 0.5

#: The menus: action names of :data:`ui.shortcuts.COMMANDS` (None: a separator).
MENUS = {
    "&File": ("open", "save", None, "chain_file", None, "quit"),
    "&Edit": ("undo", "redo", None, "chain_editor", "settings"),
    "&Analysis": ("detect", None, "fit_all", "fit_current", "fit_range", "fit_selected",
                  "fit_bad", None, "cancel", None, "histograms"),
    "&View": ("play", "prev", "next", "prev10", "next10", "first", "last", None, "prev_bad",
              "next_bad"),
    "&Correct": ("accept_next", "accept_selected", "swap", None, "prev_axis", "next_axis",
                 "nudge_down", "nudge_up", "nudge_down_big", "nudge_up_big", None,
                 "marker_left", "marker_right", "marker_up", "marker_down", None,
                 "refit_forward", "refit_backward", "interpolate"),
    "&Help": ("help",),
}


class MainWindow(QMainWindow):
    """VideoTrack's main window around one :class:`~ui.session.Session`."""

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

    # -- construction -------------------------------------------------------------------
    def _build_actions(self) -> None:
        """One action per row of :data:`ui.shortcuts.COMMANDS` (``self.act_<name>``); all
        are window-wide, so a key works wherever the focus is, except that a focused text
        field keeps the keys it edits with (Qt's shortcut override)."""
        for command in shortcuts.COMMANDS:
            if command.run is None:
                continue
            action = QAction(command.text, self)
            action.triggered.connect(lambda *_, c=command: c.run(self))
            action.setShortcuts(command.sequences())
            action.setShortcutContext(Qt.ShortcutContext.WindowShortcut)
            action.setStatusTip(command.tip)
            action.setToolTip(command.tip or command.label)
            self.addAction(action)
            setattr(self, f"act_{command.name}", action)

    def _build_menus(self) -> None:
        bar = self.menuBar()
        for title, names in MENUS.items():
            menu = bar.addMenu(title)
            for name in names:
                menu.addSeparator() if name is None else menu.addAction(
                    getattr(self, f"act_{name}"))

    def _build_layout(self, use_opengl) -> None:
        s = self.session
        # (1) control panel and table
        left = QWidget()
        lv = QVBoxLayout(left)
        lv.setContentsMargins(4, 4, 4, 4)
        self.project_label = QLabel("No project open")
        self.project_label.setWordWrap(True)
        self.project_label.setStyleSheet("font-weight: bold")
        lv.addWidget(self.project_label)
        fit_box = QGroupBox("Fit")
        grid = QGridLayout(fit_box)
        buttons = [(self.act_fit_all, "Fit all"), (self.act_fit_current, "Fit current"),
                   (self.act_fit_range, "Fit range…"), (self.act_fit_selected, "Fit selected"),
                   (self.act_fit_bad, "Re-fit bad"), (self.act_detect, "Detect markers")]
        for k, (act, text) in enumerate(buttons):
            grid.addWidget(_button(act, text), k // 2, k % 2)
        grid.addWidget(QLabel("Highlight error above"), 3, 0)
        self.threshold = FocusSpinBox()
        self.threshold.setRange(0.0, 1e6)
        self.threshold.setDecimals(1)
        self.threshold.setSuffix(" px")
        self.threshold.setToolTip("The re-analysis threshold of the fit (Table 1 note)")
        self.threshold.valueChanged.connect(self._threshold_changed)
        grid.addWidget(self.threshold, 3, 1)
        lv.addWidget(fit_box)
        self.summary = QLabel()
        lv.addWidget(self.summary)
        self.table = FrameTable(s)
        lv.addWidget(self.table, 1)
        # (2) video views
        self.views_splitter = QSplitter(Qt.Orientation.Vertical)
        # (3) posture and correction
        right = QSplitter(Qt.Orientation.Vertical)
        self.posture_view = PostureView(use_opengl=use_opengl)
        self.correction = CorrectionPanel(s)
        self.marker_table = MarkerTable()
        residuals = QGroupBox("Marker residuals (px)")
        QVBoxLayout(residuals).addWidget(self.marker_table)
        right.addWidget(self.posture_view)
        right.addWidget(self.correction)
        right.addWidget(residuals)
        right.setSizes([420, 300, 160])
        top = QSplitter(Qt.Orientation.Horizontal)
        for w in (left, self.views_splitter, right):
            top.addWidget(w)
        top.setSizes([390, 740, 470])
        top.setStretchFactor(1, 1)
        # bottom: playback and timeline
        bottom = QWidget()
        bv = QVBoxLayout(bottom)
        bv.setContentsMargins(4, 0, 4, 4)
        row = QHBoxLayout()
        icons = self.style()
        self.play_button = QToolButton()
        self.play_button.setDefaultAction(self.act_play)
        self.act_play.setIcon(icons.standardIcon(QStyle.StandardPixmap.SP_MediaPlay))
        self.act_prev.setIcon(icons.standardIcon(QStyle.StandardPixmap.SP_MediaSeekBackward))
        self.act_next.setIcon(icons.standardIcon(QStyle.StandardPixmap.SP_MediaSeekForward))
        for act in (self.act_prev, self.act_play, self.act_next):
            b = QToolButton()
            b.setDefaultAction(act)
            row.addWidget(b)
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.valueChanged.connect(s.set_frame)
        row.addWidget(self.slider, 1)
        self.frame_box = FrameSpinBox()
        self.frame_box.setPrefix("frame ")
        self.frame_box.setKeyboardTracking(False)
        self.frame_box.valueChanged.connect(s.set_frame)
        row.addWidget(self.frame_box)
        self.time_label = QLabel()
        self.time_label.setMinimumWidth(90)
        row.addWidget(self.time_label)
        bv.addLayout(row)
        self.timeline = TimelineView()
        self.timeline.frameRequested.connect(s.set_frame)
        bv.addWidget(self.timeline, 1)
        outer = QSplitter(Qt.Orientation.Vertical)
        outer.addWidget(top)
        outer.addWidget(bottom)
        outer.setSizes([650, 280])
        outer.setStretchFactor(0, 1)
        self.setCentralWidget(outer)

    def _build_status_bar(self) -> None:
        bar = self.statusBar()
        self.progress = QProgressBar()
        self.progress.setMaximumWidth(220)
        self.progress.setFormat("%v / %m")
        self.progress.setVisible(False)
        self.rate = QLabel()
        self.stale_label = QLabel()  # results of an earlier chain: say so until re-fitted
        self.stale_label.setStyleSheet(f"color: {style.STALE_TEXT}; font-weight: bold")
        self.stale_label.setVisible(False)
        bar.addPermanentWidget(self.stale_label)
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.clicked.connect(self.session.cancel)
        self.cancel_button.setVisible(False)
        for w in (self.rate, self.progress, self.cancel_button):
            bar.addPermanentWidget(w)
        # room for the Cancel button from the start: showing it must not change the bar's
        # height, which would lay out and repaint every view when a task starts and ends
        bar.setMinimumHeight(max(self.cancel_button.sizeHint().height(),
                                 self.progress.sizeHint().height()) + 4)
        bar.showMessage("Open a project (File ▸ Open project…)")

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
        from videotrack.detection_edits import snap_to_centroid

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
        from videotrack.video import parse_frame_range, resolve_frames

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

    def show_shortcuts(self):
        """The shortcut sheet, made from :data:`ui.shortcuts.COMMANDS`."""
        from ui.shortcut_sheet import ShortcutSheet

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
        from ui.chain_editor import ChainEditor

        dialog = ChainEditor(self.session, self)
        dialog.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        dialog.open()
        return dialog

    def open_histograms(self):
        from ui.histogram_dialog import HistogramDialog

        dialog = HistogramDialog(self.session, self)
        dialog.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        dialog.show()
        return dialog

    def open_project_dialog(self):
        from ui.project_dialog import ProjectDialog

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


def _button(action: QAction, text: str) -> QToolButton:
    """A button for an action, labelled with a short text (the action's icon text)."""
    action.setIconText(text)
    b = QToolButton()
    b.setDefaultAction(action)
    b.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextOnly)
    b.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
    return b


def default_path(session: Session, suffix: str) -> str:
    """A file name beside the project for a save dialog."""
    if session.config is None:
        return ""
    return str(Path(session.config.folder) / f"{session.config.path.stem}{suffix}")
