"""The per-frame error table (Fig. 4, part 1): frame, error, error per view, runs, the
largest angle sd, status.

Rows above the re-analysis threshold are shaded red, frames corrected by hand blue. The
table sorts by any column (numbers as numbers); clicking a row (or moving to it with the
Up/Down keys) makes it the current frame, and stepping frames moves the selection along.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import (
    QAbstractTableModel,
    QItemSelectionModel,
    QModelIndex,
    QSortFilterProxyModel,
    Qt,
)
from PySide6.QtWidgets import QAbstractItemView, QHeaderView, QTableView

from ui import adapters
from ui.views import style

SORT_ROLE = Qt.ItemDataRole.UserRole
_ROOT = QModelIndex()  # the invalid index: a table has no children


class FrameTableModel(QAbstractTableModel):
    """The rows of :func:`ui.adapters.frame_table`, updated frame by frame."""

    def __init__(self, session, parent=None) -> None:
        super().__init__(parent)
        self.session = session
        self.table = adapters.frame_table({}, 0, 0)
        self.views: list[str] = []
        self.headers: list[str] = self._headers()
        self.bad = np.zeros(0, bool)  # the highlight rule per row, kept with the table
        session.projectChanged.connect(self.reset)
        session.detectionsChanged.connect(self.reset)
        session.resultsChanged.connect(self.update_frames)

    def _headers(self) -> list[str]:
        return ["frame", "error", *self.views, "runs", "sd", "status"]

    def reset(self) -> None:
        """Rebuild every row (a project, detections or threshold changed)."""
        self.beginResetModel()
        self.views = self.session.error_views
        self.headers = self._headers()
        self.table = adapters.frame_table(self.session.results, self.session.n_frames,
                                          len(self.views))
        self.bad = self._bad(slice(None))
        self.endResetModel()

    def _bad(self, rows) -> np.ndarray:
        """Shaded as bad: above the threshold and not corrected (computed once per change,
        not per cell: the view asks for thousands of cells while results stream in)."""
        status = np.asarray(self.table.status, dtype=object)[rows]
        return adapters.is_bad(self.table.error[rows], self.session.threshold) & (
            status != "corrected")

    def update_frames(self, frames) -> None:
        """Refresh the rows of these frames only (results arrive while fitting)."""
        n = len(self.table.frame)
        frames = [f for f in frames if 0 <= f < n]
        t = self.table
        for f in frames:
            (t.error[f], t.error_per_view[f], t.runs[f], t.sd[f],
             t.status[f]) = adapters.table_row(self.session.results.get(f), len(self.views))
        if frames:
            self.bad[frames] = self._bad(frames)
            self.dataChanged.emit(self.index(min(frames), 0),
                                  self.index(max(frames), self.columnCount() - 1))

    def rowCount(self, parent=_ROOT) -> int:
        return 0 if parent.isValid() else len(self.table.frame)

    def columnCount(self, parent=_ROOT) -> int:
        return 0 if parent.isValid() else len(self.headers)

    def headerData(self, section, orientation, role=Qt.ItemDataRole.DisplayRole):
        if orientation != Qt.Orientation.Horizontal:
            return None
        if role == Qt.ItemDataRole.DisplayRole:
            return self.headers[section]
        if role == Qt.ItemDataRole.ToolTipRole:
            nv = len(self.views)
            if section == 1:
                return ("error E of the fitted posture (Eq. 5), pixels (a keypoint project "
                        "fitted to 3D points: the chain's length units)")
            if 2 <= section < 2 + nv:
                return f"part of E from view '{self.views[section - 2]}', pixels"
            if section == 2 + nv:
                return "annealing runs (1 + re-analyses)"
            if section == 3 + nv:
                return ("the largest standard deviation of the frame's angles, degrees: "
                        "sort by it (largest first) to check the least sure frames first")
        return None

    def value(self, row: int, column: int):
        """The sort value of a cell: a number, or the status text."""
        t, nv = self.table, len(self.views)
        if column == 0:
            return int(t.frame[row])
        if column == 1:
            return float(t.error[row])
        if column < 2 + nv:
            return float(t.error_per_view[row, column - 2])
        if column == 2 + nv:
            return int(t.runs[row])
        if column == 3 + nv:
            return float(t.sd[row])
        return t.status[row]

    def data(self, index, role=Qt.ItemDataRole.DisplayRole):
        if not index.isValid():
            return None
        row, col = index.row(), index.column()
        if role == Qt.ItemDataRole.DisplayRole:
            value = self.value(row, col)
            if isinstance(value, float):
                return "–" if not np.isfinite(value) else f"{value:.2f}"
            if col == 2 + len(self.views) and value == 0:
                return "–"
            return str(value)
        if role == SORT_ROLE:
            value = self.value(row, col)
            if isinstance(value, float) and not np.isfinite(value):
                return float("inf")  # unfitted frames sort after the worst
            return value
        if role == Qt.ItemDataRole.BackgroundRole:
            if self.table.status[row] == "corrected":
                return style.CORRECTED_ROW
            return style.BAD_ROW if self.bad[row] else None
        if role == Qt.ItemDataRole.ForegroundRole:
            status = self.table.status[row]
            if status == adapters.NOT_FITTED:
                return style.UNFITTED_TEXT
            if status == "corrected" or self.bad[row]:
                return style.TEXT_ON_SHADE  # shaded rows stay readable in a dark theme
            return None
        if role == Qt.ItemDataRole.TextAlignmentRole and col < len(self.headers) - 1:
            return int(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        return None

    def highlighted_rows(self) -> list[int]:
        """Frames shaded as bad (for tests and the status bar)."""
        return [int(r) for r in np.flatnonzero(self.bad)]


class FrameTable(QTableView):
    """Sortable view of :class:`FrameTableModel` that follows the session's frame."""

    def __init__(self, session, parent=None) -> None:
        super().__init__(parent)
        self.session = session
        self.source = FrameTableModel(session, self)
        self.proxy = QSortFilterProxyModel(self)
        self.proxy.setSourceModel(self.source)
        self.proxy.setSortRole(SORT_ROLE)
        self.setModel(self.proxy)
        self.setSortingEnabled(True)
        self.sortByColumn(0, Qt.SortOrder.AscendingOrder)
        self.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.setSelectionMode(QAbstractItemView.SelectionMode.ExtendedSelection)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.verticalHeader().setVisible(False)
        self.verticalHeader().setDefaultSectionSize(20)
        # sized once per reset: sizing to contents on every change would read every row
        # each time a batch of results arrives
        self.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Interactive)
        self.horizontalHeader().setStretchLastSection(True)
        self.source.modelReset.connect(self._size_columns)
        self.setAlternatingRowColors(False)
        self._clicking = False
        self.clicked.connect(self._clicked)
        session.frameChanged.connect(self.follow)

    def _size_columns(self) -> None:
        self.horizontalHeader().setResizeContentsPrecision(64)
        self.resizeColumnsToContents()
        # numbers not yet fitted must fit later: at least "00000.00"
        wide = self.fontMetrics().horizontalAdvance("00000.00") + 12
        for c in range(1, self.source.columnCount() - 1):
            self.setColumnWidth(c, max(self.columnWidth(c), wide))

    def row_of(self, frame: int) -> int:
        """The row where ``frame`` is shown (after sorting)."""
        return self.proxy.mapFromSource(self.source.index(frame, 0)).row()

    def frame_at(self, row: int) -> int:
        return int(self.proxy.mapToSource(self.proxy.index(row, 0)).row())

    def _clicked(self, index) -> None:
        self._clicking = True  # a Ctrl/Shift click has made the selection: keep it
        try:
            self.session.set_frame(self.frame_at(index.row()))
        finally:
            self._clicking = False

    def keyPressEvent(self, event) -> None:
        """Up/Down/Page keys move the current row; the current frame follows it."""
        before = self.currentIndex()
        super().keyPressEvent(event)
        current = self.currentIndex()
        if current.isValid() and current != before:
            self._clicking = True
            try:
                self.session.set_frame(self.frame_at(current.row()))
            finally:
                self._clicking = False

    def follow(self, frame: int) -> None:
        """Scroll to the current frame and make the selection agree with it.

        A multi-row selection that holds the frame is kept (for *Fit selected*); otherwise
        the frame's row alone is selected, so the highlighted rows are what F7 fits.
        """
        if not 0 <= frame < self.source.rowCount():
            return
        index = self.proxy.index(self.row_of(frame), 0)
        self.scrollTo(index, QAbstractItemView.ScrollHint.EnsureVisible)
        if self._clicking or frame in self.selected_frames():
            return
        # not selectRow(): it would toggle while Ctrl is held (Ctrl+→); signals stay on so
        # that the view repaints the highlight
        sel = self.selectionModel()
        flags = QItemSelectionModel.SelectionFlag
        sel.setCurrentIndex(index, flags.NoUpdate)
        sel.select(index, flags.ClearAndSelect | flags.Rows)

    def selected_frames(self) -> list[int]:
        return sorted(self.frame_at(i.row()) for i in self.selectionModel().selectedRows())
