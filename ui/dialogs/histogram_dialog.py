"""Joint-angle histograms (paper Sect. 2.2): one bar plot per axis, the current value marked.

"Learn from analysed frames" applies Eq. 4 once per frame to every free axis (one undo step);
the archive can be exported as histogram XML and loaded again, e.g. into another project.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import (
    QCheckBox,
    QDialog,
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QPushButton,
    QSplitter,
    QVBoxLayout,
    QWidget,
)

from ui import adapters
from ui.views import style


class HistogramDialog(QDialog):
    """Bar plot of the selected axis' histogram; follows the session's chain and frame."""

    def __init__(self, session, parent=None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Joint-angle histograms")
        self.resize(860, 520)
        self.session = session
        self.axes = QListWidget()
        self.axes.currentRowChanged.connect(lambda *_: self.refresh())
        self.plot = pg.PlotWidget()
        self.plot.setLabel("bottom", "angle", units="°")
        self.plot.setLabel("left", "probability H(x)")
        self.plot.showGrid(x=True, y=True, alpha=0.2)
        self.bars = pg.BarGraphItem(x=[], height=[], width=1.0, brush=pg.mkBrush("#4c8be0"),
                                    pen=pg.mkPen("#2a5ea8", width=0.5))
        self.plot.addItem(self.bars)
        self.current = pg.InfiniteLine(angle=90, pen=pg.mkPen(style.CURRENT_FRAME, width=2.5),
                                       label="frame {value:.1f}°",
                                       labelOpts={"position": 0.9, "color": style.CURRENT_FRAME,
                                                  "fill": (0, 0, 0, 150)})
        self.plot.addItem(self.current)
        self.info = QLabel()
        self.good_only = QCheckBox("Only frames within the current error threshold (and "
                                   "corrected ones)")
        self.good_only.setChecked(True)
        learn = QPushButton("Learn from analysed frames (Eq. 4)")
        learn.clicked.connect(self.learn)
        export = QPushButton("Export archive…")
        export.clicked.connect(self.export)
        load = QPushButton("Load archive…")
        load.clicked.connect(self.load)
        close = QPushButton("Close")
        close.clicked.connect(self.close)
        right = QWidget()
        rv = QVBoxLayout(right)
        rv.addWidget(self.plot, 1)
        rv.addWidget(self.info)
        split = QSplitter()
        split.addWidget(self.axes)
        split.addWidget(right)
        split.setSizes([180, 680])
        buttons = QHBoxLayout()
        for w in (learn, export, load):
            buttons.addWidget(w)
        buttons.addStretch(1)
        buttons.addWidget(close)
        layout = QVBoxLayout(self)
        layout.addWidget(split, 1)
        layout.addWidget(self.good_only)
        layout.addLayout(buttons)
        self.buttons = (learn, load)
        # the session outlives the dialog: every link is undone when the dialog closes or is
        # destroyed, or a frame step would reach its deleted widgets
        refresh = lambda *_: self.refresh()  # noqa: E731
        self._links = [(session.busyChanged, self._busy),
                       (session.bodyChanged, self.fill), (session.projectChanged, self.fill),
                       *((sig, refresh) for sig in (session.frameChanged,
                                                     session.resultsChanged,
                                                     session.postureChanged))]
        for sig, slot in self._links:
            sig.connect(slot)
        self.destroyed.connect(lambda *_, links=self._links: _unlink(links))
        self._busy(session.busy)
        self.fill()

    def closeEvent(self, event) -> None:
        _unlink(self._links)
        super().closeEvent(event)

    def done(self, result: int) -> None:  # Esc: reject() hides without a close event
        _unlink(self._links)
        super().done(result)

    def _busy(self, busy: bool) -> None:
        for b in self.buttons:  # the chain must not change under a running fit
            b.setEnabled(not busy)

    def fill(self) -> None:
        """List the axes of the chain, keeping the selection."""
        body = self.session.body
        row = max(self.axes.currentRow(), 0)
        self.axes.blockSignals(True)
        self.axes.clear()
        if body is not None:
            for ref in body.axis_refs():
                self.axes.addItem(ref.label + ("  (locked)" if ref.axis.locked else ""))
        self.axes.blockSignals(False)
        if self.axes.count():
            free = adapters.free_axes(body)
            self.axes.setCurrentRow(row if row or not free else free[0])
        self.refresh()

    @property
    def axis(self) -> int:
        return self.axes.currentRow()

    def refresh(self) -> None:
        body = self.session.body
        if body is None or self.axis < 0:
            return
        ref = body.axis_refs()[self.axis]
        hist = ref.axis.histogram
        angles, _, source = self.session.posture()
        bars = adapters.histogram_bars(hist, angles[self.axis])
        self.bars.setOpts(x=bars.centres, height=bars.heights, width=bars.width)
        self.current.setVisible(bars.value is not None)
        if bars.value is not None:
            self.current.setValue(bars.value)
        lo, hi = bars.view_range
        self.plot.setXRange(lo, hi, padding=0)
        self.plot.setYRange(0, max(float(bars.heights.max()), 1e-9) * 1.15, padding=0)
        self.plot.setTitle(f"{ref.label}  ({ref.axis.rot} rotation of joint {ref.joint})",
                           size="11pt")
        self.info.setText(
            f"N = {hist.n_trials} trials · mean {bars.mean:.1f}° · s(H) = "
            f"{hist.std_deg():.1f}° · range {ref.axis.min_deg:g}…{ref.axis.max_deg:g}° · "
            f"current frame {self.session.frame}: {angles[self.axis]:.1f}° ({source})")

    def bar_data(self) -> tuple[np.ndarray, np.ndarray]:
        """The drawn bars' (x, height), for tests."""
        return np.asarray(self.bars.opts["x"]), np.asarray(self.bars.opts["height"])

    def learn(self) -> None:
        self.session.learn_histograms(within_threshold=self.good_only.isChecked())

    def export(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Export histogram archive",
                                              default_path(self.session, ".histograms.xml"),
                                              "Histogram archive (*.xml)")
        if path:
            self.session.export_histograms(path)

    def load(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Load histogram archive",
                                              default_path(self.session, ""),
                                              "Histogram archive (*.xml)")
        if path:
            self.session.import_histograms(path)


def _unlink(links: list) -> None:
    """Disconnect the dialog's session handlers (once; the list is emptied)."""
    while links:
        sig, slot = links.pop()
        with contextlib.suppress(RuntimeError, TypeError):  # already gone with the session
            sig.disconnect(slot)


def default_path(session, suffix: str) -> str:
    """A file name beside the project for a save dialog."""
    if session.config is None:
        return ""
    return str(Path(session.config.folder) / f"{session.config.path.stem}{suffix}")
