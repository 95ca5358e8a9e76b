"""Manual correction of the current frame (paper Sect. 4, "as a last resort").

Moving a slider shows the posture at once; releasing it pins that axis at the value and
re-fits the rest of the chain to the detections (:meth:`ui.state.Session.correct`).
Dragging a model marker in a video view does the same for the axis that moves it best
(:meth:`ui.state.Session.drag_marker`). Pinned axes are shown in bold; undo reverts.

Steps (nudge keys, a focused slider's keys or wheel, a number box's arrows) show at once but
re-fit only once they rest for :data:`SETTLE_MS`: one re-fit for a run of key presses, and no
key press is lost to a re-fit in progress.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QTimer
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
from ui.views.axis_sliders import AxisSliders

#: Quiet time after the last step before the frame is re-fitted (milliseconds).
SETTLE_MS = 300


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
        self.sliders.stepped.connect(self._stepped)
        #: Steps not yet committed: (frame, {axis: degrees}).
        self.pending: tuple[int, dict[int, float]] | None = None
        self.settle = QTimer(self, singleShot=True, interval=SETTLE_MS)
        self.settle.timeout.connect(self.flush)
        session.frameChanged.connect(lambda *_: self.flush())
        session.resultsChanged.connect(self._show_pending)
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
        self.sliders.select(index)
        angles, _, _ = self.session.posture()
        angles[index] = value
        self.session.set_preview_angles(angles)

    def _committed(self, index: int, value: float) -> None:
        """A slider released or a number entered: re-fit now (with any steps pending)."""
        self._queue(index, value)
        self.flush()

    def _stepped(self, index: int, value: float) -> None:
        self._queue(index, value)
        self.settle.start()  # restarted by every step

    def _queue(self, index: int, value: float) -> None:
        frame = self.session.frame
        if self.pending is not None and self.pending[0] != frame:
            self.flush()
        values = {} if self.pending is None else self.pending[1]
        values[index] = float(value)
        self.pending = (frame, values)

    # -- keys ---------------------------------------------------------------------------
    def select_axis(self, step: int) -> None:
        """Select the next (``step`` 1) or previous (-1) axis for the nudge keys."""
        axes = list(self.sliders.rows)
        if not axes:
            return
        k = axes.index(self.sliders.selected) if self.sliders.selected in axes else -step
        self.sliders.select(axes[(k + step) % len(axes)])
        label = self.sliders.rows[self.sliders.selected][0].text()
        self.session.status.emit(f"nudge keys move {label}")

    def nudge(self, delta_deg: float) -> None:
        """Turn the selected axis by ``delta_deg`` (shown at once, re-fitted once the keys
        rest)."""
        s, index = self.session, self.sliders.selected
        if index is None or s.body is None:
            return
        pending = self.pending[1] if self.pending and self.pending[0] == s.frame else {}
        base = pending.get(index, s.posture()[0][index])
        lo, hi = s.body.ranges_deg()[index]
        value = float(np.clip(round(base + delta_deg, 6), lo, hi))
        self._queue(index, value)
        self._show_pending()
        self.settle.start()

    def _show_pending(self, *_) -> None:
        """Draw the pending steps over the frame's posture (also after a re-fit arrived)."""
        s = self.session
        if self.pending is None or self.pending[0] != s.frame or s.body is None:
            return
        angles, _, _ = s.posture()
        for k, v in self.pending[1].items():
            angles[k] = v
        s.set_preview_angles(angles)
        self.refresh()

    def flush(self) -> None:
        """Commit the pending steps now (a re-fit waits for a running task to end)."""
        if self.pending is None or self.session.closed:
            self.pending = None
            return
        if self.session.busy:
            self.settle.start()
            return
        self.settle.stop()
        (frame, values), self.pending = self.pending, None
        labels = ", ".join(self.session.body.axis_labels[k] for k in values)
        self.session.correct(values, refit=self.refit.isChecked(), frame=frame,
                             label=f"set {labels}")
