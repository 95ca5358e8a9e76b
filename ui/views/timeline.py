"""Timeline of the fitted angles and the error over all frames, with the current frame.

The yellow line marks the current frame; drag it (or click a plot) to move there. Frames
above the re-analysis threshold show as red dots on the error curve. Where the fit gave
standard deviations, each angle has a faint band of ± 2 sd (about 95 % of right frames lie
within it).
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QSizePolicy

from ui.views import style


class TimelineView(pg.GraphicsLayoutWidget):
    """Angles (top) and error (bottom) against frame; emits ``frameRequested(int)``."""

    frameRequested = Signal(int)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setMinimumHeight(150)
        # the legend gets a row of its own above the plots, so it never hides a curve
        self.legend = pg.LegendItem(colCount=12, labelTextSize="8pt", verSpacing=-6)
        self.legend.layout.setContentsMargins(0, 0, 0, 0)
        self.addItem(self.legend, row=0, col=0)
        self.legend.setSizePolicy(QSizePolicy.Policy.Fixed, QSizePolicy.Policy.Fixed)
        self.ci.layout.setAlignment(self.legend, Qt.AlignmentFlag.AlignLeft)
        self.angles_plot = self.addPlot(row=1, col=0)
        self.angles_plot.setLabel("left", "angle", units="°")
        self.angles_plot.showGrid(x=True, y=True, alpha=0.2)
        self.error_plot = self.addPlot(row=2, col=0)
        self.error_plot.setLabel("left", "error", units="px")
        self.error_plot.setLabel("bottom", "frame")
        self.error_plot.showGrid(x=True, y=True, alpha=0.2)
        self.error_plot.setXLink(self.angles_plot)
        self.ci.layout.setRowStretchFactor(1, 3)
        self.ci.layout.setRowStretchFactor(2, 2)
        self.error_curve = self.error_plot.plot(pen=pg.mkPen(style.ERROR_CURVE, width=1.5))
        self.bad = pg.ScatterPlotItem(size=7, pen=None, brush=pg.mkBrush(style.THRESHOLD))
        self.error_plot.addItem(self.bad)
        for plot in (self.angles_plot, self.error_plot):
            style.cache_axes(plot)
        style.cache_drawing(self.error_curve, self.bad)
        self.threshold_line = pg.InfiniteLine(angle=0, movable=False, pen=pg.mkPen(
            style.THRESHOLD, width=1, style=Qt.PenStyle.DashLine))
        self.error_plot.addItem(self.threshold_line)
        self.curves: list[pg.PlotDataItem] = []
        self.bands: list[pg.FillBetweenItem] = []  # ± 2 sd of each curve
        self.lines = []
        for plot in (self.angles_plot, self.error_plot):
            line = pg.InfiniteLine(0, angle=90, movable=True,
                                   pen=pg.mkPen(style.CURRENT_FRAME, width=2),
                                   hoverPen=pg.mkPen(style.CURRENT_FRAME, width=4))
            line.sigDragged.connect(self._dragged)
            plot.addItem(line)
            self.lines.append(line)
            plot.scene().sigMouseClicked.connect(self._clicked)
        self._labels: list[str] = []

    def set_data(self, timeline, labels, threshold: float) -> None:
        """Show a :class:`ui.adapters.Timeline`; ``labels`` names the angle columns drawn
        (``(index, label)`` pairs, e.g. the free axes)."""
        names = [lb for _, lb in labels]
        if names != self._labels:
            for c in (*self.curves, *self.bands):
                self.angles_plot.removeItem(c)
            self.legend.clear()
            self.curves = [self.angles_plot.plot(pen=pg.mkPen(style.colour(k), width=1.5),
                                                 connect="finite")
                           for k in range(len(names))]
            self.bands = [self._band(k) for k in range(len(names))]
            style.cache_drawing(*self.curves)
            for curve, name in zip(self.curves, names, strict=True):
                self.legend.addItem(curve, name)
            self._labels = names
        x = timeline.frames
        for curve, band, (index, _) in zip(self.curves, self.bands, labels, strict=True):
            y = timeline.angles_deg[:, index]
            curve.setData(x, y, connect="finite")
            spread = 2.0 * timeline.sd_deg[:, index]
            shown = bool(np.isfinite(spread).any())
            band.setVisible(shown)
            if shown:  # the same gaps as the curve's: the fill pairs their pieces
                spread = np.where(np.isfinite(spread), spread, 0.0)
                band.curves[0].setData(x, y - spread, connect="finite")
                band.curves[1].setData(x, y + spread, connect="finite")
        self.error_curve.setData(x, timeline.error, connect="finite")
        with np.errstate(invalid="ignore"):
            bad = np.isfinite(timeline.error) & (timeline.error > threshold)
        self.bad.setData(x[bad], timeline.error[bad])
        self.threshold_line.setValue(threshold if np.isfinite(threshold) else 0)
        self.threshold_line.setVisible(bool(np.isfinite(threshold)))
        if len(x):
            self.angles_plot.setXRange(-0.5, len(x) - 0.5, padding=0.01)

    def _band(self, k: int) -> pg.FillBetweenItem:
        """The ± 2 sd band of curve ``k``, in its colour, faint and behind the curves."""
        low, high = pg.PlotDataItem(), pg.PlotDataItem()
        colour = pg.mkColor(style.colour(k))
        colour.setAlpha(50)
        band = pg.FillBetweenItem(low, high, brush=pg.mkBrush(colour))
        band.setZValue(-1)
        band.setVisible(False)
        self.angles_plot.addItem(band)
        return band

    def set_frame(self, frame: int) -> None:
        for line in self.lines:
            line.blockSignals(True)
            line.setValue(frame)
            line.blockSignals(False)

    @property
    def frame_line_value(self) -> float:
        return float(self.lines[0].value())

    def _dragged(self, line) -> None:
        frame = round(line.value())
        self.set_frame(frame)
        self.frameRequested.emit(frame)

    def _clicked(self, ev) -> None:
        for plot in (self.angles_plot, self.error_plot):
            if plot.sceneBoundingRect().contains(ev.scenePos()):
                x = plot.vb.mapSceneToView(ev.scenePos()).x()
                self.frameRequested.emit(round(x))
                return
