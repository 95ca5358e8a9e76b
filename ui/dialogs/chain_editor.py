"""The chain editor (paper Sect. 3.1: "manipulated in a dialog with immediate display of its
projection on the video-image").

The chain is shown as a tree of chains, joints, axes, segments and markers. Selecting an
element shows its numbers; every change is applied to a copy of the chain, checked by
:func:`kinematics.model.validate_body` and, when valid, drawn at once on the video views.
Sliders move the free axes of the posture. OK makes the copy the session's chain (one undo
step), Cancel forgets it, Save as XML writes it to a file. Enter commits the field being
edited and never closes the dialog. Names cannot be changed here,
because results files name their columns after them.
"""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QScrollArea,
    QSplitter,
    QStackedWidget,
    QTreeWidget,
    QTreeWidgetItem,
    QVBoxLayout,
    QWidget,
)

from kinematics.errors import LocatedError
from kinematics.model import ROOT_MODES, validate_body
from ui import adapters
from ui.views.axis_sliders import AxisSliders

KIND_ROLE = Qt.ItemDataRole.UserRole


def _spin(lo: float = -1e5, hi: float = 1e5, decimals: int = 3, suffix: str = ""):
    box = QDoubleSpinBox()
    box.setRange(lo, hi)
    box.setDecimals(decimals)
    box.setSuffix(suffix)
    box.setKeyboardTracking(False)
    return box


class Vec3Edit(QWidget):
    """Three numbers (x, y, z or y, x, z angles); emits ``changed`` on every edit."""

    changed = Signal()

    def __init__(self, suffix: str = "", parent=None) -> None:
        super().__init__(parent)
        row = QHBoxLayout(self)
        row.setContentsMargins(0, 0, 0, 0)
        self.boxes = [_spin(suffix=suffix) for _ in range(3)]
        for b in self.boxes:
            b.valueChanged.connect(self.changed)
            row.addWidget(b)

    def value(self) -> tuple[float, float, float]:
        return tuple(b.value() for b in self.boxes)

    def set_value(self, v) -> None:
        for b, x in zip(self.boxes, v, strict=True):
            b.blockSignals(True)
            b.setValue(float(x))
            b.blockSignals(False)


class ChainEditor(QDialog):
    """Edits a copy of the session's chain with live re-projection."""

    def __init__(self, session, parent=None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Chain editor")
        self.resize(1000, 640)
        self.session = session
        self.original = session.body
        self.body = session.body  # the last valid edited copy
        self.current: tuple[str, str, int | None] | None = None
        angles, _, _ = session.posture()
        self.angles = angles.copy()

        self.tree = QTreeWidget()
        self.tree.setHeaderLabels(["element", "values"])
        self.tree.setColumnWidth(0, 210)
        self.tree.currentItemChanged.connect(self._selected)
        self.pages = QStackedWidget()
        self.pages.addWidget(QLabel("Select a joint, axis, segment or marker."))
        self._build_pages()
        self.message = QLabel()
        self.message.setWordWrap(True)
        self.sliders = AxisSliders()
        self.sliders.moved.connect(self._slid)
        self.sliders.committed.connect(self._slid)

        right = QWidget()
        rv = QVBoxLayout(right)
        rv.addWidget(self.pages)
        rv.addWidget(self.message)
        box = QGroupBox("Posture (moves the model on the video)")
        bl = QVBoxLayout(box)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(self.sliders)
        scroll.setFrameShape(QScrollArea.Shape.NoFrame)
        bl.addWidget(scroll)
        rv.addWidget(box, 1)
        split = QSplitter()
        split.addWidget(self.tree)
        split.addWidget(right)
        split.setSizes([440, 560])
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok
                                        | QDialogButtonBox.StandardButton.Cancel)
        self.save_button = self.buttons.addButton("Save as XML…",
                                                  QDialogButtonBox.ButtonRole.ActionRole)
        self.save_button.clicked.connect(self.save_as)
        self.buttons.accepted.connect(self.accept)
        self.buttons.rejected.connect(self.reject)
        for button in self.buttons.buttons():  # no default button: Enter is for the fields
            button.setAutoDefault(False)
            button.setDefault(False)
        layout = QVBoxLayout(self)
        layout.addWidget(split, 1)
        layout.addWidget(self.buttons)
        self._fill_tree()
        self._rebuild_sliders()
        self._show_valid()

    # -- pages --------------------------------------------------------------------------
    def _build_pages(self) -> None:
        def page(*rows):
            w = QWidget()
            form = QFormLayout(w)
            for label, field in rows:
                form.addRow(label, field)
            self.pages.addWidget(w)
            return w

        self.root_mode = QComboBox()
        self.root_mode.addItems(ROOT_MODES)
        self.root_mode.setToolTip("fixed: the root sits at the position; marker: it follows "
                                  "the root marker; free: its position and orientation are "
                                  "fitted per frame (a freely moving body)")
        self.root_marker = QComboBox()
        self.root_pos = Vec3Edit()
        self.root_twin = QLineEdit()
        self.root_rwin = QLineEdit()
        for w in (self.root_twin, self.root_rwin):
            w.setToolTip("the search window around the seed of a free root; empty for the "
                         "default from the body's size")
        self.root_note = QLabel()
        self.root_note.setWordWrap(True)
        self.root_note.setStyleSheet("color: grey")
        self.page_chain = page(("root mode", self.root_mode), ("root marker", self.root_marker),
                               ("root position (x, y, z)", self.root_pos),
                               ("translation window ±", self.root_twin),
                               ("rotation window ±", self.root_rwin), ("", self.root_note))
        self.root_pos.changed.connect(self._edited)
        self.root_mode.currentIndexChanged.connect(self._edited)
        self.root_marker.currentIndexChanged.connect(self._edited)
        self.root_twin.textChanged.connect(self._edited)
        self.root_rwin.textChanged.connect(self._edited)
        self.joint_orient = Vec3Edit("°")
        self.joint_trans = Vec3Edit()
        self.page_joint = page(("default orientation R^d (y, x, z)", self.joint_orient),
                               ("translation T (x, y, z)", self.joint_trans))
        self.axis_min = _spin(-360, 360, 2, "°")
        self.axis_max = _spin(-360, 360, 2, "°")
        self.axis_locked = QCheckBox("locked at")
        self.axis_lock_value = _spin(-360, 360, 2, "°")
        lock_row = QWidget()
        lr = QHBoxLayout(lock_row)
        lr.setContentsMargins(0, 0, 0, 0)
        lr.addWidget(self.axis_locked)
        lr.addWidget(self.axis_lock_value, 1)
        note = QLabel("A new range or lock resets the axis' histogram to the paper's initial "
                      "one (uniform over the range).")
        note.setWordWrap(True)
        note.setStyleSheet("color: grey")
        self.page_axis = page(("min", self.axis_min), ("max", self.axis_max), ("", lock_row),
                              ("", note))
        self.seg_length = _spin(0, 1e5, 3)
        self.seg_rot = Vec3Edit("°")
        self.page_segment = page(("length", self.seg_length),
                                 ("default rotation R^s (y, x, z)", self.seg_rot))
        self.marker_offset = Vec3Edit()
        self.page_marker = page(("offset (x, y, z) from the segment's end", self.marker_offset))
        for w in (self.joint_orient, self.joint_trans, self.seg_rot, self.marker_offset):
            w.changed.connect(self._edited)
        for w in (self.axis_min, self.axis_max, self.axis_lock_value, self.seg_length):
            w.valueChanged.connect(self._edited)
        self.axis_locked.toggled.connect(self._edited)

    def _fill_tree(self) -> None:
        self.tree.blockSignals(True)
        self.tree.clear()
        parents: dict[int, QTreeWidgetItem] = {}
        for depth, kind, name, index in adapters.body_tree(self.body):
            item = QTreeWidgetItem([f"{kind} {name}", self._summary(kind, name, index)])
            item.setData(0, KIND_ROLE, (kind, name, index))
            if depth == 0:
                self.tree.addTopLevelItem(item)
            else:
                parents[depth - 1].addChild(item)
            parents[depth] = item
        self.tree.expandAll()
        self.tree.blockSignals(False)

    def _summary(self, kind: str, name: str, index) -> str:
        b = self.body
        if kind == "axis":
            a = b.axis_refs()[index].axis
            rng = f"{a.rot}: {a.min_deg:g}…{a.max_deg:g}°"
            return f"{rng}, locked {a.locked_deg:g}°" if a.locked else rng
        element = adapters.find_element(b, kind, name)
        if kind == "segment":
            return f"length {element.length:g} {b.units}"
        if kind == "marker":
            return "offset ({:g}, {:g}, {:g})".format(*element.offset)
        if kind == "chain":
            r = element.root
            return f"root {r.mode} {r.marker}" if r.mode == "marker" else f"root {r.mode}"
        return ""

    def _item(self, kind: str, name: str) -> QTreeWidgetItem | None:
        for item in self._items():
            if item.data(0, KIND_ROLE)[:2] == (kind, name):
                return item
        return None

    def _items(self):
        stack = [self.tree.topLevelItem(i) for i in range(self.tree.topLevelItemCount())]
        while stack:
            item = stack.pop(0)
            yield item
            stack.extend(item.child(i) for i in range(item.childCount()))

    def select(self, kind: str, name: str) -> None:
        """Show an element's page (e.g. ``select("segment", "femur")``)."""
        self.tree.setCurrentItem(self._item(kind, name))

    def _selected(self, item, _previous=None) -> None:
        if item is None:
            return
        kind, name, index = item.data(0, KIND_ROLE)
        self.current = (kind, name, index)
        widgets = [self.root_mode, self.root_marker, self.root_twin, self.root_rwin,
                   self.root_pos, self.joint_orient, self.joint_trans, self.axis_min,
                   self.axis_max, self.axis_locked, self.axis_lock_value, self.seg_length,
                   self.seg_rot, self.marker_offset]
        for w in widgets:
            w.blockSignals(True)
        b = self.body
        if kind == "chain":
            root = adapters.find_element(b, kind, name).root
            self.root_mode.setCurrentText(root.mode)
            self.root_marker.clear()
            self.root_marker.addItem("(none)", None)
            for m in adapters.chain_marker_names(b, name):
                self.root_marker.addItem(m, m)
            self.root_marker.setCurrentIndex(max(0, self.root_marker.findData(root.marker)))
            self.root_pos.set_value(root.position)
            for box, value in ((self.root_twin, root.translation_window),
                               (self.root_rwin, root.rotation_window_deg)):
                box.setText("" if value is None else f"{value:g}")
            self._root_page_state()
            self.pages.setCurrentWidget(self.page_chain)
        elif kind == "joint":
            j = adapters.find_element(b, kind, name)
            self.joint_orient.set_value(j.orientation_deg)
            self.joint_trans.set_value(j.translation)
            self.pages.setCurrentWidget(self.page_joint)
        elif kind == "axis":
            a = b.axis_refs()[index].axis
            self.axis_min.setValue(a.min_deg)
            self.axis_max.setValue(a.max_deg)
            self.axis_locked.setChecked(a.locked)
            self.axis_lock_value.setValue(a.locked_deg if a.locked else a.min_deg)
            self.axis_lock_value.setEnabled(a.locked)
            self.pages.setCurrentWidget(self.page_axis)
        elif kind == "segment":
            s = adapters.find_element(b, kind, name)
            self.seg_length.setValue(s.length)
            self.seg_rot.set_value(s.rotation_deg)
            self.pages.setCurrentWidget(self.page_segment)
        elif kind == "marker":
            self.marker_offset.set_value(adapters.find_element(b, kind, name).offset)
            self.pages.setCurrentWidget(self.page_marker)
        for w in widgets:
            w.blockSignals(False)

    # -- editing ------------------------------------------------------------------------
    def _candidate(self):
        """The last valid chain with the current page's values applied."""
        kind, name, index = self.current
        b = self.body
        if kind == "chain":
            self._root_page_state()
            return adapters.edit_root_settings(
                b, name, mode=self.root_mode.currentText(), position=self.root_pos.value(),
                marker=self.root_marker.currentData(), translation_text=self.root_twin.text(),
                rotation_text=self.root_rwin.text())
        if kind == "joint":
            return adapters.edit_joint(b, name, orientation_deg=self.joint_orient.value(),
                                       translation=self.joint_trans.value())
        if kind == "axis":
            locked = self.axis_locked.isChecked()
            self.axis_lock_value.setEnabled(locked)
            return adapters.edit_axis(b, index, min_deg=self.axis_min.value(),
                                      max_deg=self.axis_max.value(),
                                      locked_deg=self.axis_lock_value.value() if locked
                                      else None)
        if kind == "segment":
            return adapters.edit_segment(b, name, length=self.seg_length.value(),
                                         rotation_deg=self.seg_rot.value())
        return adapters.edit_marker(b, name, offset=self.marker_offset.value())

    def _root_page_state(self) -> None:
        """Enable what the chosen root mode uses; the windows' placeholders show the
        defaults of the last valid chain."""
        if self.current is None or self.current[0] != "chain":
            return
        name = self.current[1]
        mode = self.root_mode.currentText()
        self.root_marker.setEnabled(mode != "fixed")
        self.root_twin.setEnabled(mode == "free")
        self.root_rwin.setEnabled(mode == "free")
        default = adapters.default_root_windows(self.body, name)
        units = self.body.units
        self.root_twin.setPlaceholderText("" if default is None
                                          else f"default {default[0]:.4g} {units}")
        self.root_rwin.setPlaceholderText("" if default is None
                                          else f"default {default[1]:.4g}°")
        placing = adapters.root_markers(self.body, name)
        notes = {
            "fixed": "The root joint stays at the position.",
            "marker": "The root joint follows the detected root marker, searched near the "
                      "position in the first frame.",
            "free": "Position and orientation of the root joint are fitted per frame, seeded "
                    "by the markers of its segments ("
                    + (", ".join(placing) or "none") + "); with fewer than three the root "
                    "marker seeds the position only. The windows bound the search around the "
                    "seed (empty: default).",
        }
        self.root_note.setText(notes.get(mode, ""))

    def _edited(self, *_) -> None:
        if self.current is None:
            return
        try:
            candidate = self._candidate()
            validate_body(candidate)
        except LocatedError as err:
            self._show_invalid(str(err))
            return
        locks_changed = list(candidate.locked_mask()) != list(self.body.locked_mask()) or (
            candidate.ranges_deg().tolist() != self.body.ranges_deg().tolist())
        self.body = candidate
        item = self.tree.currentItem()
        kind, name, index = self.current
        item.setText(1, self._summary(kind, name, index))
        if locks_changed:
            self._rebuild_sliders()
        self._show_valid()
        self.session.set_preview_body(self.body)
        self.session.set_preview_angles(self._posture())

    def _show_invalid(self, message: str) -> None:
        self.message.setText(f"⚠ {message}")
        self.message.setStyleSheet("color: #c00000")
        self.buttons.button(QDialogButtonBox.StandardButton.Ok).setEnabled(False)
        self.save_button.setEnabled(False)

    def _show_valid(self) -> None:
        self.message.setText("✓ valid chain")
        self.message.setStyleSheet("color: #208020")
        self.buttons.button(QDialogButtonBox.StandardButton.Ok).setEnabled(True)
        self.save_button.setEnabled(True)

    def _posture(self):
        return adapters.clamp_to_range(self.body, self.angles)

    def _rebuild_sliders(self) -> None:
        self.sliders.set_axes(self.body, adapters.free_axes(self.body))
        self.sliders.set_values(self._posture())

    def _slid(self, index: int, value: float) -> None:
        self.angles[index] = value
        self.session.set_preview_body(self.body)
        self.session.set_preview_angles(self._posture())

    # -- closing ------------------------------------------------------------------------
    def save_as(self) -> None:
        s = self.session
        start = str(s.model.chain_path) if s.model is not None else ""
        path, _ = QFileDialog.getSaveFileName(self, "Save chain as", start,
                                              "Chain XML (*.xml)")
        if path:
            s.save_chain_as(path, self.body)

    def keyPressEvent(self, event) -> None:
        """Enter commits the field being edited (the field has seen it) and never closes the
        dialog: only its buttons do. Esc still cancels."""
        if event.key() in (Qt.Key.Key_Return, Qt.Key.Key_Enter):
            event.accept()
            return
        super().keyPressEvent(event)

    def accept(self) -> None:
        s = self.session
        s.set_preview_angles(None)
        if self.body is not self.original:
            s.commit_body(self.body, "edit chain")
        else:
            s.set_preview_body(None)
        super().accept()

    def reject(self) -> None:
        self.session.set_preview_angles(None)
        self.session.set_preview_body(None)
        super().reject()
