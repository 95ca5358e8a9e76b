"""Manual correction of the current frame (paper Sect. 4, "as a last resort").

Moving a slider shows the posture at once; releasing it pins that axis at the value and
re-fits the rest of the chain to the detections (:meth:`ui.session.Session.correct`).
Dragging a model marker in a video view does the same for the axis that moves it best
(:meth:`ui.session.Session.drag_marker`). Pinned axes are shown in bold; undo reverts.
"""

from __future__ import annotations

from PySide6.QtWidgets import (
    QCheckBox,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QScrollArea,
    QVBoxLayout,
)

from ui import adapters
from ui.axis_sliders import AxisSliders


class CorrectionPanel(QGroupBox):
    """Sliders for the free axes of the current frame's posture."""

    def __init__(self, session, parent=None) -> None:
        super().__init__("Manual correction", parent)
        self.session = session
        layout = QVBoxLayout(self)
        self.source = QLabel()
        self.source.setWordWrap(True)
        layout.addWidget(self.source)
        self.sliders = AxisSliders()
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(self.sliders)
        scroll.setFrameShape(QScrollArea.Shape.NoFrame)
        layout.addWidget(scroll, 1)
        self.refit = QCheckBox("Re-fit the rest of the chain")
        self.refit.setChecked(True)
        self.refit.setToolTip("Hold the axes you set (shown bold) and fit the other axes to "
                              "the detections; off: take the posture exactly as set")
        row = QHBoxLayout()
        row.addWidget(self.refit, 1)
        self.release = QPushButton("Release pins")
        self.release.setToolTip("Forget which axes of this frame were set by hand")
        self.release.clicked.connect(lambda: session.release_pins())
        row.addWidget(self.release)
        layout.addLayout(row)
        hint = QLabel("Tip: drag an orange model marker in a video view to move it there.")
        hint.setWordWrap(True)
        hint.setStyleSheet("color: grey; font-size: 8pt")
        layout.addWidget(hint)
        self.sliders.moved.connect(self._moved)
        self.sliders.committed.connect(self._committed)
        for sig in (session.projectChanged, session.bodyChanged):
            sig.connect(self.rebuild)
        for sig in (session.frameChanged, session.resultsChanged, session.postureChanged,
                    session.undoChanged):
            sig.connect(self.refresh)
        session.busyChanged.connect(lambda busy: self.setEnabled(not busy))
        self._axes: list[int] = []

    def rebuild(self) -> None:
        body = self.session.body
        axes = [] if body is None else adapters.free_axes(body)
        if body is not None and axes != self._axes:
            self.sliders.set_axes(body, axes)
            self._axes = axes
        self.refresh()

    def refresh(self, *_) -> None:
        s = self.session
        if s.body is None:
            self.source.setText("No chain loaded.")
            return
        angles, _, source = s.posture()
        pins = s.pins.get(s.frame, {})
        self.sliders.set_values(angles, pinned=pins)
        result = s.results.get(s.frame)
        what = {"preview": "preview (release to apply)", "start": "start posture (not fitted)",
                "fit": result.status if result is not None else ""}[source]
        self.source.setText(f"Frame {s.frame}: {what}"
                            + (f", {len(pins)} axes pinned" if pins else ""))
        self.release.setEnabled(bool(pins))

    def _moved(self, index: int, value: float) -> None:
        angles, _, _ = self.session.posture()
        angles[index] = value
        self.session.set_preview_angles(angles)

    def _committed(self, index: int, value: float) -> None:
        self.session.correct({index: value}, refit=self.refit.isChecked())
