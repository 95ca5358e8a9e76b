"""The shortcut sheet (``?``): every key of :data:`ui.views.shortcuts.COMMANDS`, by group."""

from __future__ import annotations

from PySide6.QtWidgets import (
    QDialog,
    QDialogButtonBox,
    QHeaderView,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
)

from ui.views import shortcuts


class ShortcutSheet(QDialog):
    """A table ``key | action | group``, made from the command table (never out of date)."""

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Keyboard shortcuts")
        self.resize(620, 640)
        layout = QVBoxLayout(self)
        rows = shortcuts.keyed()
        self.table = QTableWidget(len(rows), 3)
        self.table.setHorizontalHeaderLabels(["key", "action", "group"])
        for r, command in enumerate(rows):
            for c, text in enumerate((command.key_text(), command.label, command.group)):
                item = QTableWidgetItem(text)
                item.setToolTip(command.tip)
                self.table.setItem(r, c, item)
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.table.horizontalHeader().setSectionResizeMode(
            QHeaderView.ResizeMode.ResizeToContents)
        self.table.horizontalHeader().setStretchLastSection(True)
        layout.addWidget(self.table)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Close)
        buttons.rejected.connect(self.reject)
        layout.addWidget(buttons)

    def rows(self) -> list[tuple[str, str]]:
        """``(keys, action)`` as shown (for tests)."""
        return [(self.table.item(r, 0).text(), self.table.item(r, 1).text())
                for r in range(self.table.rowCount())]
