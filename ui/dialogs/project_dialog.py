"""Project settings: views (ROIs drawn on the frame), the filter chain with a live preview of
the mask and the detections of the current frame, the chain and camera files and the
annealing parameters.

The forms are generated from the declarative config schema (:mod:`videotrack.project.config`), so
every key, bound and choice is the one the project file accepts. The dialog edits a copy of
the project file's table; OK validates it and hands it to the session (saved with File ▸
Save). The preview runs :class:`videotrack.detect.run.FrameDetector` in a worker thread.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QListWidget,
    QPushButton,
    QScrollArea,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from kinematics.errors import LocatedError
from ui import adapters
from ui.dialogs.schema_form import SchemaForm
from ui.state.workers import TaskWorker
from ui.views import style
from ui.views.video_view import display_image

VIEW_COLUMNS = ("name", "x", "y", "width", "height", "flip_x", "flip_y", "camera", "video")
#: The [[views]] keys the view table edits; any other key of a view is kept as it is.
_VIEW_KEYS = ("name", "roi", "flip_x", "flip_y", "camera", "video")


# -- the dialog -----------------------------------------------------------------------------
class ProjectDialog(QDialog):
    """Edits a copy of the project file; OK applies it to the session."""

    def __init__(self, session, parent=None) -> None:
        from videotrack.project.config import ANNEAL, CAMERAS, CHAIN, FILTER_STEPS, MARKERS

        super().__init__(parent)
        self.setWindowTitle("Project settings")
        self.resize(1250, 760)
        self.session = session
        self.base = session.config.folder
        self.raw = copy.deepcopy(session.raw_config)
        self.step_sections = FILTER_STEPS.sections
        self.steps: list[dict] = [dict(s) for s in self.raw.get("filters", {}).get("steps", [])]
        self._worker: TaskWorker | None = None
        self._pending = False
        self._videos = None  # opened and used by the preview worker only
        self.preview_result: list | None = None

        tabs = QTabWidget()
        tabs.addTab(self._views_tab(), "Views")
        tabs.addTab(self._filters_tab(MARKERS), "Filters and preview")
        model = QWidget()
        mv = QVBoxLayout(model)
        self.chain_form = SchemaForm(CHAIN, self.raw.get("chain", {}), self.base)
        self.cameras_form = SchemaForm(CAMERAS, self.raw.get("cameras", {}), self.base)
        self.anneal_form = SchemaForm(ANNEAL, self.raw.get("anneal", {}), self.base)
        for title, form in (("Chain", self.chain_form), ("Cameras", self.cameras_form),
                            ("Annealing (defaults: the paper's Table 1)", self.anneal_form)):
            box = QGroupBox(title)
            QVBoxLayout(box).addWidget(form)
            mv.addWidget(box)
        mv.addStretch(1)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(model)
        tabs.addTab(scroll, "Chain and fitting")
        self.tabs = tabs
        self.message = QLabel()
        self.message.setWordWrap(True)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok
                                   | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        layout = QVBoxLayout(self)
        layout.addWidget(tabs, 1)
        layout.addWidget(self.message)
        layout.addWidget(buttons)
        self._preview_timer = QTimer(self, singleShot=True, interval=150)
        self._preview_timer.timeout.connect(self.update_preview)
        self.schedule_preview()

    # -- views --------------------------------------------------------------------------
    def _views_tab(self) -> QWidget:
        s = self.session
        self.frame_plot = pg.PlotWidget()
        self.frame_plot.invertY(True)
        self.frame_plot.setAspectLocked(True)
        self.frame_image = pg.ImageItem()
        self.frame_plot.addItem(self.frame_image)
        self.video_choice = QComboBox()
        n_videos = len(s.videos.sources) if s.videos is not None else 0
        self.video_choice.addItems([f"video {k}" for k in range(n_videos)])
        self.video_choice.currentIndexChanged.connect(self._show_frame)
        self.view_table = QTableWidget(0, len(VIEW_COLUMNS))
        self.view_table.setHorizontalHeaderLabels(VIEW_COLUMNS)
        self.view_table.horizontalHeader().setSectionResizeMode(
            QHeaderView.ResizeMode.ResizeToContents)
        self.view_table.itemChanged.connect(self._view_cell_changed)
        self.rois: list[pg.RectROI] = []
        # keys of each row's [[views]] table the table does not show (model_markers, a
        # view's colour range): kept as they are when the dialog writes the views back
        raw_views = {t.get("name"): t for t in self.raw.get("views", []) if isinstance(t, dict)}
        self._view_extra: list[dict] = []
        add = QPushButton("Add view")
        add.clicked.connect(self.add_view)
        remove = QPushButton("Remove view")
        remove.clicked.connect(self.remove_view)
        for view in s.views:
            self._append_view(view.to_dict(), {k: v for k, v in raw_views.get(
                view.name, {}).items() if k not in _VIEW_KEYS})
        left = QWidget()
        lv = QVBoxLayout(left)
        lv.addWidget(QLabel("Drag or resize a rectangle to set a view's region of interest:"))
        lv.addWidget(self.video_choice)
        lv.addWidget(self.frame_plot, 1)
        right = QWidget()
        rv = QVBoxLayout(right)
        rv.addWidget(self.view_table, 1)
        row = QHBoxLayout()
        row.addWidget(add)
        row.addWidget(remove)
        row.addStretch(1)
        rv.addLayout(row)
        split = QSplitter()
        split.addWidget(left)
        split.addWidget(right)
        split.setSizes([700, 520])
        self._show_frame()
        return split

    def _show_frame(self, *_) -> None:
        frames = self.session.full_frames()
        k = max(self.video_choice.currentIndex(), 0)
        if k < len(frames):
            img = frames[k]
            self.frame_image.setImage(display_image(img), autoLevels=False, levels=(0, 255))
            self.frame_image.setRect(-0.5, -0.5, img.shape[1], img.shape[0])
        for roi, row in zip(self.rois, range(self.view_table.rowCount()), strict=True):
            roi.setVisible(self._cell(row, "video") == str(k))

    def _append_view(self, d: dict, extra: dict | None = None) -> None:
        self._view_extra.append(dict(extra or {}))
        row = self.view_table.rowCount()
        self.view_table.blockSignals(True)
        self.view_table.insertRow(row)
        roi = d.get("roi") or [0, 0, 1, 1]
        values = [d["name"], *roi, d.get("flip_x", False), d.get("flip_y", False),
                  d.get("camera") or d["name"], d.get("video", 0)]
        for col, v in enumerate(values):
            item = QTableWidgetItem()
            if isinstance(v, bool):
                item.setFlags(Qt.ItemFlag.ItemIsUserCheckable | Qt.ItemFlag.ItemIsEnabled)
                item.setCheckState(Qt.CheckState.Checked if v else Qt.CheckState.Unchecked)
            else:
                item.setText(str(v))
            self.view_table.setItem(row, col, item)
        self.view_table.blockSignals(False)
        pen = pg.mkPen(style.colour(row), width=2)
        r = pg.RectROI((roi[0] - 0.5, roi[1] - 0.5), (roi[2], roi[3]), pen=pen,
                       removable=False)
        r.addScaleHandle((0, 0), (1, 1))
        label = pg.TextItem(d["name"], color=style.colour(row), anchor=(0, 1))
        label.setParentItem(r)
        r.sigRegionChangeFinished.connect(lambda roi_=r: self._roi_moved(roi_))
        self.frame_plot.addItem(r)
        self.rois.append(r)

    def _cell(self, row: int, column: str) -> str:
        item = self.view_table.item(row, VIEW_COLUMNS.index(column))
        if column in ("flip_x", "flip_y"):
            return str(item.checkState() == Qt.CheckState.Checked)
        return item.text().strip()

    def _roi_moved(self, roi) -> None:
        row = self.rois.index(roi)
        x, y = (round(v + 0.5) for v in roi.pos())
        w, h = (max(1, round(v)) for v in roi.size())
        self.view_table.blockSignals(True)
        for col, v in zip(("x", "y", "width", "height"), (x, y, w, h), strict=True):
            self.view_table.item(row, VIEW_COLUMNS.index(col)).setText(str(v))
        self.view_table.blockSignals(False)
        self.schedule_preview()

    def _view_cell_changed(self, item) -> None:
        row = item.row()
        try:
            x, y, w, h = (int(self._cell(row, c)) for c in ("x", "y", "width", "height"))
        except ValueError:
            return
        roi = self.rois[row]
        roi.blockSignals(True)
        roi.setPos((x - 0.5, y - 0.5))
        roi.setSize((w, h))
        roi.blockSignals(False)
        self.schedule_preview()

    def add_view(self) -> None:
        frames = self.session.full_frames()
        h, w = frames[0].shape[:2] if frames else (100, 100)
        names = {self._cell(r, "name") for r in range(self.view_table.rowCount())}
        name = next(f"view{k}" for k in range(1, 100) if f"view{k}" not in names)
        self._append_view({"name": name, "roi": [0, 0, w // 2, h // 2]})

    def remove_view(self) -> None:
        row = self.view_table.currentRow()
        if row < 0:
            return
        self.view_table.removeRow(row)
        self._view_extra.pop(row)
        self.frame_plot.removeItem(self.rois.pop(row))
        self.schedule_preview()

    def view_tables(self) -> list[dict]:
        """The views as ``[[views]]`` tables (defaults left out)."""
        out = []
        for row in range(self.view_table.rowCount()):
            c = self._cell
            d = {"name": c(row, "name"),
                 "roi": [_int(c(row, k)) for k in ("x", "y", "width", "height")]}
            for flip in ("flip_x", "flip_y"):
                if c(row, flip) == "True":
                    d[flip] = True
            if c(row, "camera") and c(row, "camera") != d["name"]:
                d["camera"] = c(row, "camera")
            if _int(c(row, "video")):
                d["video"] = _int(c(row, "video"))
            out.append({**copy.deepcopy(self._view_extra[row]), **d})
        return out

    # -- filters ------------------------------------------------------------------------
    def _filters_tab(self, markers_section) -> QWidget:
        self.step_list = QListWidget()
        self.step_list.currentRowChanged.connect(self._step_selected)
        self.step_type = QComboBox()
        self.step_type.addItems(list(self.step_sections))
        add = QPushButton("Add step")
        add.clicked.connect(lambda: self.add_step(self.step_type.currentText()))
        remove = QPushButton("Remove")
        remove.clicked.connect(self.remove_step)
        up = QPushButton("Up")
        up.clicked.connect(lambda: self.move_step(-1))
        down = QPushButton("Down")
        down.clicked.connect(lambda: self.move_step(1))
        self.step_box = QGroupBox("Step")
        self.step_layout = QVBoxLayout(self.step_box)
        self.step_form: SchemaForm | None = None
        self.markers_form = SchemaForm(markers_section, self.raw.get("markers", {}), self.base)
        self.markers_form.changed.connect(self.schedule_preview)
        left = QWidget()
        lv = QVBoxLayout(left)
        lv.addWidget(QLabel("Filter steps, run in order on each view image:"))
        lv.addWidget(self.step_list, 1)
        row = QHBoxLayout()
        for w in (self.step_type, add, remove, up, down):
            row.addWidget(w)
        lv.addLayout(row)
        lv.addWidget(self.step_box)
        mbox = QGroupBox("Marker regions")
        QVBoxLayout(mbox).addWidget(self.markers_form)
        lv.addWidget(mbox)
        # preview
        self.preview = pg.GraphicsLayoutWidget()
        self.preview_plots: list = []
        self.preview_label = QLabel()
        self.preview_label.setWordWrap(True)
        right = QWidget()
        rv = QVBoxLayout(right)
        rv.addWidget(QLabel(f"Preview of frame {self.session.frame}: marker pixels of the "
                            "filter chain's mask in magenta, detected centroids as green rings"))
        rv.addWidget(self.preview, 1)
        rv.addWidget(self.preview_label)
        split = QSplitter()
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(left)
        split.addWidget(scroll)
        split.addWidget(right)
        split.setSizes([480, 740])
        self._fill_steps()
        return split

    def _fill_steps(self, select: int = 0) -> None:
        self.step_list.blockSignals(True)
        self.step_list.clear()
        for k, step in enumerate(self.steps):
            self.step_list.addItem(_step_text(k, step))
        if self.steps:
            self.step_list.setCurrentRow(min(select, len(self.steps) - 1))
        self.step_list.blockSignals(False)
        self._step_selected(self.step_list.currentRow())

    def _step_selected(self, row: int) -> None:
        if self.step_form is not None:
            self.step_layout.removeWidget(self.step_form)
            self.step_form.hide()
            self.step_form.deleteLater()
            self.step_form = None
        if not 0 <= row < len(self.steps):
            self.step_box.setTitle("Step")
            return
        step = self.steps[row]
        self.step_box.setTitle(f"Step {row + 1}: {step['type']}")
        self.step_form = SchemaForm(self.step_sections[step["type"]], step, self.base)
        self.step_form.changed.connect(lambda r=row: self._step_edited(r))
        self.step_layout.addWidget(self.step_form)

    def _step_edited(self, row: int) -> None:
        self.steps[row] = {"type": self.steps[row]["type"], **self.step_form.values()}
        self.step_list.item(row).setText(_step_text(row, self.steps[row]))
        self.schedule_preview()

    def set_step_value(self, row: int, key: str, value) -> None:
        """Set one key of a step as if typed in its form (scripts and tests)."""
        self.step_list.setCurrentRow(row)
        w = self.step_form.widgets[key]
        if hasattr(w, "setValue"):
            w.setValue(value)
        else:
            w.setText(str(value))
        self._step_edited(row)

    def add_step(self, kind: str) -> None:
        """Insert a step of ``kind`` after the selected one (required keys get a start)."""
        section = self.step_sections[kind]
        step = {"type": kind, **{k.name: _start_value(k) for k in section.keys if k.required}}
        row = self.step_list.currentRow() + 1
        self.steps.insert(row, step)
        self._fill_steps(row)
        self.schedule_preview()

    def remove_step(self) -> None:
        row = self.step_list.currentRow()
        if 0 <= row < len(self.steps):
            del self.steps[row]
            self._fill_steps(row)
            self.schedule_preview()

    def move_step(self, delta: int) -> None:
        row = self.step_list.currentRow()
        new = row + delta
        if 0 <= row < len(self.steps) and 0 <= new < len(self.steps):
            self.steps[row], self.steps[new] = self.steps[new], self.steps[row]
            self._fill_steps(new)
            self.schedule_preview()

    # -- the edited config --------------------------------------------------------------
    def edited_raw(self) -> dict:
        """The project file's table with this dialog's edits."""
        raw = copy.deepcopy(self.raw)
        raw["views"] = self.view_tables()
        raw["filters"] = {**raw.get("filters", {}), "steps": [dict(s) for s in self.steps]}
        for name, form in (("markers", self.markers_form), ("chain", self.chain_form),
                           ("cameras", self.cameras_form), ("anneal", self.anneal_form)):
            values = form.values()
            if values:
                raw[name] = values
            else:
                raw.pop(name, None)
        return raw

    def edited_config(self):
        """The edited settings, validated (raises :class:`VideoTrackError`)."""
        return self.session.parse_raw(self.edited_raw())

    # -- preview ------------------------------------------------------------------------
    def schedule_preview(self) -> None:
        self._preview_timer.start()

    def update_preview(self) -> None:
        """Detect in the current frame with the edited settings (in a worker thread)."""
        from videotrack.detect.run import settings_from_config

        if self._worker is not None:
            self._pending = True
            return
        try:
            config = self.edited_config()
            settings = settings_from_config(config)
        except LocatedError as err:
            self._show_message(str(err), ok=False)
            return
        except (TypeError, ValueError) as err:
            self._show_message(f"invalid value: {err}", ok=False)
            return
        video_frame = self.session.video_frame(self.session.frame)
        paths_fps = (config["video"]["path"], config["video"]["fps"] or None)

        def work(_worker):
            from videotrack.detect.run import FrameDetector
            from videotrack.detect.video import open_videos

            if self._videos is None:
                self._videos = open_videos(paths_fps[0], colour=True, fps=paths_fps[1])
            detector = FrameDetector(self._videos, settings)
            return ([v.name for v in detector.views],
                    adapters.detection_preview(detector, self._videos.read(video_frame)))

        worker = TaskWorker(work)
        worker.done.connect(self._preview_done)
        worker.failed.connect(lambda msg: self._show_message(msg, ok=False))
        worker.finished.connect(self._preview_finished)
        self._worker = worker
        worker.start()

    def _preview_finished(self) -> None:
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.deleteLater()
        if self._pending:
            self._pending = False
            self.update_preview()

    def _preview_done(self, result) -> None:
        names, views = result
        self.preview_result = views
        while len(self.preview_plots) < len(views):
            plot = self.preview.addPlot(row=len(self.preview_plots), col=0)
            plot.invertY(True)
            plot.setAspectLocked(True)
            image = pg.ImageItem()
            scatter = pg.ScatterPlotItem(**style.detection_style())
            plot.addItem(image)
            plot.addItem(scatter)
            self.preview_plots.append((plot, image, scatter))
        for k, (plot, image, scatter) in enumerate(self.preview_plots):
            visible = k < len(views)
            plot.setVisible(visible)
            if not visible:
                continue
            view = views[k]
            image.setImage(view.overlay(), autoLevels=False, levels=(0, 255))
            image.setRect(-0.5, -0.5, view.mask.shape[1], view.mask.shape[0])
            scatter.setData(pos=np.asarray(view.points).reshape(-1, 2))
            plot.setTitle(f"{names[k]}: {len(view.points)} markers", size="10pt")
        counts = ", ".join(f"{n}: {len(v.points)}" for n, v in zip(names, views, strict=True))
        self.preview_label.setText(f"markers found: {counts}")
        self._show_message("settings are valid", ok=True)

    def _show_message(self, text: str, ok: bool) -> None:
        self.message.setText(("✓ " if ok else "⚠ ") + text)
        self.message.setStyleSheet("color: #208020" if ok else "color: #c00000")

    def wait_preview(self, timeout_ms: int = 20000) -> None:
        """Let a scheduled preview run to its end (scripts and tests)."""
        from PySide6.QtCore import QCoreApplication, QElapsedTimer

        clock = QElapsedTimer()
        clock.start()
        while (self._preview_timer.isActive() or self._worker is not None or self._pending) \
                and clock.elapsed() < timeout_ms:
            QCoreApplication.processEvents()
            worker = self._worker
            if worker is not None:
                worker.wait(20)

    # -- closing ------------------------------------------------------------------------
    def _stop_preview(self) -> None:
        self._preview_timer.stop()
        self._pending = False
        if self._worker is not None:
            self._worker.wait()
        if self._videos is not None:
            self._videos.close()
            self._videos = None

    def accept(self) -> None:
        try:
            self.edited_config()
        except LocatedError as err:
            self._show_message(str(err), ok=False)
            return
        self._stop_preview()
        if self.session.apply_config(self.edited_raw()):
            super().accept()

    def reject(self) -> None:
        self._stop_preview()
        super().reject()


def _step_text(row: int, step: dict) -> str:
    """How a filter step is listed: ``2. erode (size=5)``."""
    args = ", ".join(f"{k}={json.dumps(v)}" for k, v in step.items() if k != "type")
    return f"{row + 1}. {step['type']}" + (f" ({args})" if args else "")


def _start_value(key):
    """A first value for a required key of a new filter step (the user then tunes it)."""
    if key.type == "int":
        return int(np.clip(128, key.min if key.min is not None else 0,
                           key.max if key.max is not None else 255))
    if key.type == "float":
        return float(key.min or 0.0)
    if key.type.startswith("list"):
        return [0] * (key.length or 0)
    return ""


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        return 0
