"""The main window's construction: its actions (one per row of
:data:`ui.views.shortcuts.COMMANDS`), menus, the Fig. 4 layout and the status bar."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtGui import QAction
from PySide6.QtWidgets import (
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
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

from ui.views import shortcuts, style
from ui.views.axis_sliders import FocusSpinBox, FrameSpinBox
from ui.views.correction_panel import CorrectionPanel
from ui.views.frame_table import FrameTable
from ui.views.marker_table import MarkerTable
from ui.views.posture_view import PostureView
from ui.views.timeline import TimelineView

#: The menus: action names of :data:`ui.views.shortcuts.COMMANDS` (None: a separator).
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



class WindowLayoutMixin:
    """Builds :class:`~ui.views.main_window.MainWindow`'s actions, menus, widgets and status
    bar."""

    # -- construction -------------------------------------------------------------------
    def _build_actions(self) -> None:
        """One action per row of :data:`ui.views.shortcuts.COMMANDS` (``self.act_<name>``); all
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



def _button(action: QAction, text: str) -> QToolButton:
    """A button for an action, labelled with a short text (the action's icon text)."""
    action.setIconText(text)
    b = QToolButton()
    b.setDefaultAction(action)
    b.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextOnly)
    b.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
    return b

