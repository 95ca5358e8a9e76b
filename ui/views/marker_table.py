"""Per-marker residuals of the posture shown: one row per model marker, one column per view,
the distance in pixels to the nearest detection (:func:`ui.adapters.residuals_of`). The
largest cell of the frame is shaded: the marker to look at first."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QHeaderView, QTableWidget, QTableWidgetItem

from ui.views import style


class MarkerTable(QTableWidget):
    """Rows: markers; columns: views; cells: residual pixels (– without a detection)."""

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.setFocusPolicy(Qt.FocusPolicy.NoFocus)  # keys stay with the window
        self.verticalHeader().setDefaultSectionSize(18)
        self.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.setToolTip("Distance of each model marker to its nearest detection per view "
                        "(pixels); the largest is shaded")
        self.residuals = np.empty((0, 0))

    def set_residuals(self, residuals: np.ndarray, markers, views, hidden=None) -> None:
        """Show an (n_views, n_markers) array of :func:`ui.adapters.residuals_of`; a
        marker ``hidden`` in a view ((n_views, n_markers) of bool) reads "hidden" there."""
        self.residuals = np.asarray(residuals, float)
        hidden = np.zeros(self.residuals.shape, bool) if hidden is None else np.asarray(
            hidden, bool)
        markers, views = list(markers), list(views)
        if self.rowCount() != len(markers) or self.columnCount() != len(views):
            self.setRowCount(len(markers))
            self.setColumnCount(len(views))
            for r in range(len(markers)):
                for c in range(len(views)):
                    item = QTableWidgetItem()
                    item.setTextAlignment(Qt.AlignmentFlag.AlignRight
                                          | Qt.AlignmentFlag.AlignVCenter)
                    self.setItem(r, c, item)
        self.setVerticalHeaderLabels(markers)
        self.setHorizontalHeaderLabels(views)
        finite = np.isfinite(self.residuals)
        worst = (np.unravel_index(np.argmax(np.where(finite, self.residuals, -1)),
                                  self.residuals.shape) if finite.any() else None)
        for r in range(len(markers)):
            for c in range(len(views)):
                value = self.residuals[c, r] if self.residuals.size else np.nan
                item = self.item(r, c)
                gone = c < hidden.shape[0] and r < hidden.shape[1] and hidden[c, r]
                item.setText("hidden" if gone else f"{value:.2f}" if np.isfinite(value)
                             else "–")
                shaded = worst is not None and (c, r) == tuple(worst)
                item.setBackground(style.BAD_ROW if shaded else Qt.GlobalColor.transparent)
                item.setForeground(style.TEXT_ON_SHADE if shaded else self.palette().text())

    def text(self, marker: int, view: int) -> str:
        return self.item(marker, view).text()
