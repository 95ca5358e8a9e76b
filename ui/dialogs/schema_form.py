"""A form generated from a config :class:`~videotrack.project.config.Section`: one widget per key
(the project dialog's chain, cameras, annealing, markers and filter-step forms)."""

from __future__ import annotations

import json

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLineEdit,
    QPushButton,
    QSpinBox,
    QWidget,
)

from ui import adapters


class SchemaForm(QWidget):
    """One widget per :class:`videotrack.project.config.Key` of a section; ``changed`` on edits.

    Numbers get spin boxes with the key's bounds, choices a combo box, booleans a check box,
    paths a line with a browse button, lists a line of JSON. Tool tips are the keys' docs.
    """

    changed = Signal()

    def __init__(self, section, values: dict, base=None, parent=None) -> None:
        super().__init__(parent)
        self.section = section
        self.base = base
        self.widgets: dict[str, QWidget] = {}
        form = QFormLayout(self)
        form.setContentsMargins(0, 0, 0, 0)
        for key in section.keys:
            value = values.get(key.name, None if key.required else key.default)
            w = self._widget(key, value)
            w.setToolTip(key.doc)
            self.widgets[key.name] = w
            form.addRow(key.name, w)

    def _widget(self, key, value) -> QWidget:
        t = key.type
        if key.choices is not None:
            w = QComboBox()
            w.addItems([str(c) for c in key.choices])
            w.setCurrentText(str(value))
            w.currentTextChanged.connect(self.changed)
        elif t == "bool":
            w = QCheckBox()
            w.setChecked(bool(value))
            w.toggled.connect(self.changed)
        elif t == "int":
            w = QSpinBox()
            w.setRange(int(key.min if key.min is not None else -2**31),
                       int(min(key.max if key.max is not None else 2**31 - 1, 2**31 - 1)))
            w.setValue(int(value or 0))
            w.setKeyboardTracking(False)
            w.valueChanged.connect(self.changed)
        elif t == "float":
            w = QDoubleSpinBox()
            w.setDecimals(4)
            w.setRange(key.min if key.min is not None else -1e12,
                       key.max if key.max is not None else 1e12)
            w.setValue(float(value or 0.0))
            w.setKeyboardTracking(False)
            w.valueChanged.connect(self.changed)
        elif t == "path":
            w = _PathEdit(str(value or ""), self.base)
            w.edit.editingFinished.connect(self.changed)
        else:  # str, lists and unions: text (lists as JSON)
            w = QLineEdit(value if isinstance(value, str) else json.dumps(value))
            w.editingFinished.connect(self.changed)
        return w

    def values(self) -> dict:
        """The keys whose value differs from the default (what the file needs to hold)."""
        out = {}
        for key in self.section.keys:
            w = self.widgets[key.name]
            if isinstance(w, QComboBox):
                v = w.currentText()
                v = next((c for c in key.choices if str(c) == v), v)
            elif isinstance(w, QCheckBox):
                v = w.isChecked()
            elif isinstance(w, QSpinBox | QDoubleSpinBox):
                v = w.value()
            elif isinstance(w, _PathEdit):
                v = w.edit.text()
            else:
                text = w.text().strip()
                v = text if key.type == "str" else _json_or_text(text)
            if key.required or v != key.default:
                out[key.name] = v
        return out


def _json_or_text(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text  # the config's validation names the key and says what is wrong


class _PathEdit(QWidget):
    def __init__(self, text: str, base, parent=None) -> None:
        super().__init__(parent)
        self.base = base
        row = QHBoxLayout(self)
        row.setContentsMargins(0, 0, 0, 0)
        self.edit = QLineEdit(text)
        browse = QPushButton("…")
        browse.setFixedWidth(30)
        browse.clicked.connect(self._browse)
        row.addWidget(self.edit, 1)
        row.addWidget(browse)

    def _browse(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Choose file", str(self.base or ""))
        if path:
            self.edit.setText(adapters.relative_path(path, self.base) if self.base else path)
            self.edit.editingFinished.emit()
