"""A slider and a number box per axis, over the axis' range (degrees, 0.1° steps).

Used by the manual correction panel and by the chain editor. ``moved(index, value)`` fires
while a slider is dragged (for live re-projection), ``committed(index, value)`` when it is
released or a number is entered, ``stepped(index, value)`` for a step by key, wheel or the
box's arrows (the panel re-fits once the steps rest, not per step); ``index`` is the axis'
posture-vector index. The mouse wheel changes a slider or number only while it has the
keyboard focus (click it first); Enter in a number box hands the keys back to the window, so
the arrow keys step frames again.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QFont
from PySide6.QtWidgets import QDoubleSpinBox, QGridLayout, QLabel, QSlider, QSpinBox, QWidget

#: Slider steps per degree.
STEPS = 10


class _WheelGuard:
    """Mixin: the wheel edits the value only while the widget has the keyboard focus.

    Otherwise the wheel event goes to the parent (the panel scrolls), so scrolling over the
    correction panel never moves a slider and re-fits a frame.
    """

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)  # click or Tab, not the wheel

    def wheelEvent(self, event) -> None:
        if self.hasFocus():
            super().wheelEvent(event)
        else:
            event.ignore()


class _ReturnsKeys:
    """Mixin for number boxes: Enter commits and gives up the focus, so window keys (the
    arrows step frames) work again; while focused the box is a text field being edited and
    keeps its keys. :attr:`stepping` is True during a step (arrows, wheel), not typing."""

    stepping = False

    def keyPressEvent(self, event) -> None:
        super().keyPressEvent(event)
        if event.key() in (Qt.Key.Key_Return, Qt.Key.Key_Enter):
            self.clearFocus()

    def stepBy(self, steps: int) -> None:
        self.stepping = True
        try:
            super().stepBy(steps)
        finally:
            self.stepping = False


class FocusSlider(_WheelGuard, QSlider):
    """A slider that takes the wheel only when focused."""


class FocusSpinBox(_ReturnsKeys, _WheelGuard, QDoubleSpinBox):
    """A number box that takes the wheel only when focused."""


class FrameSpinBox(_ReturnsKeys, _WheelGuard, QSpinBox):
    """The frame number box of the playback row."""


class AxisSliders(QWidget):
    """Rows ``label | slider | value`` for the given axes of a body."""

    moved = Signal(int, float)
    committed = Signal(int, float)
    stepped = Signal(int, float)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.grid = QGridLayout(self)
        self.grid.setContentsMargins(0, 0, 0, 0)
        self.grid.setVerticalSpacing(2)
        self.rows: dict[int, tuple[QLabel, QSlider, QDoubleSpinBox]] = {}
        self.selected: int | None = None

    def set_axes(self, body, indices) -> None:
        """Build one row per posture index of ``body`` (free axes, typically)."""
        for label, slider, box in self.rows.values():
            for w in (label, slider, box):
                self.grid.removeWidget(w)
                w.deleteLater()
        self.rows = {}
        refs = body.axis_refs()
        for row, index in enumerate(indices):
            a = refs[index].axis
            label = QLabel(refs[index].label)
            slider = FocusSlider(Qt.Orientation.Horizontal)
            slider.setRange(round(a.min_deg * STEPS), round(a.max_deg * STEPS))
            slider.setMinimumWidth(120)
            box = FocusSpinBox()
            box.setRange(a.min_deg, a.max_deg)
            box.setDecimals(1)
            box.setSuffix("°")
            box.setKeyboardTracking(False)
            slider.valueChanged.connect(lambda v, i=index: self._slid(i, v))
            slider.sliderReleased.connect(lambda i=index: self._released(i))
            box.valueChanged.connect(lambda v, i=index: self._typed(i, v))
            self.grid.addWidget(label, row, 0)
            self.grid.addWidget(slider, row, 1)
            self.grid.addWidget(box, row, 2)
            self.rows[index] = (label, slider, box)
        self.select(self.selected if self.selected in self.rows else next(iter(self.rows),
                                                                          None))

    def select(self, index: int | None) -> None:
        """Mark the axis the nudge keys move (a frame around its label)."""
        self.selected = index
        for k, (label, _, _) in self.rows.items():
            label.setStyleSheet("border: 1px solid palette(highlight); padding: 0 2px"
                                if k == index else "padding: 0 3px")

    def set_values(self, angles_deg, pinned=()) -> None:
        """Show a posture without emitting; ``pinned`` axes get a bold label."""
        for index, (label, slider, box) in self.rows.items():
            v = float(angles_deg[index])
            if not np.isfinite(v):
                continue
            for w, value in ((slider, round(v * STEPS)), (box, v)):
                w.blockSignals(True)
                w.setValue(value)
                w.blockSignals(False)
            font = QFont(label.font())
            font.setBold(index in pinned)
            label.setFont(font)

    def value(self, index: int) -> float:
        return self.rows[index][2].value()

    def _slid(self, index: int, v: int) -> None:
        box = self.rows[index][2]
        box.blockSignals(True)
        box.setValue(v / STEPS)
        box.blockSignals(False)
        self.moved.emit(index, v / STEPS)
        if not self.rows[index][1].isSliderDown():  # keyboard, wheel or page steps
            self.stepped.emit(index, v / STEPS)

    def _released(self, index: int) -> None:
        self.committed.emit(index, self.rows[index][1].value() / STEPS)

    def _typed(self, index: int, v: float) -> None:
        slider = self.rows[index][1]
        slider.blockSignals(True)
        slider.setValue(round(v * STEPS))
        slider.blockSignals(False)
        self.moved.emit(index, v)
        (self.stepped if self.rows[index][2].stepping else self.committed).emit(index, v)
