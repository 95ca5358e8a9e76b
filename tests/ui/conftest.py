"""Fixtures of the GUI tests: a small synthetic project, a session and a main window.

Qt runs offscreen (no display needed) unless QT_QPA_PLATFORM says otherwise
(tests/ui/test_real_display.py runs these tests again on Xvfb); the project is the paper's
locust set-up made by ``videotrack synth`` (12 frames) and detected once per test session,
then copied for each test so tests may save into it.
"""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import shutil
import tomllib

import pytest
import tomli_w

import ui  # noqa: F401  (before the QApplication: ui sets the shared OpenGL context)
from tests.fixtures.settings import SHORT_ANNEAL
from videotrack.cli import main


@pytest.fixture(scope="session")
def synth_project(tmp_path_factory):
    """Folder of a detected synthetic project with a short annealing schedule."""
    out = tmp_path_factory.mktemp("gui-project")
    assert main(["synth", str(out), "--frames", "12", "--sequences", "1"]) == 0
    assert main(["detect", str(out / "project.toml")]) == 0
    config = out / "project.toml"
    raw = tomllib.loads(config.read_text())
    raw["anneal"] = {**raw.get("anneal", {}), **SHORT_ANNEAL}
    config.write_text(tomli_w.dumps(raw))
    return out


@pytest.fixture
def project(synth_project, tmp_path):
    """A private copy of the synthetic project; returns its project file."""
    folder = tmp_path / "project"
    shutil.copytree(synth_project, folder)
    return folder / "project.toml"


@pytest.fixture
def session(qtbot, project):
    """An opened :class:`ui.session.Session`; ``session.messages`` collects its errors."""
    from ui.state import Session

    s = Session()
    s.messages = []
    s.error.connect(s.messages.append)
    assert s.open_project(project)
    yield s
    s.close()


def open_window(qtbot, project):
    """A shown main window on ``project``; closing it never asks (unsaved changes
    discarded)."""
    from PySide6.QtWidgets import QMessageBox

    from ui.views.main_window import MainWindow

    w = MainWindow()  # the 3D view decides: OpenGL on a real display, 2D offscreen
    w.ask_unsaved = lambda: QMessageBox.StandardButton.Discard
    qtbot.addWidget(w)
    w.resize(1400, 900)
    w.show()
    # on a real X server showing is asynchronous, and shortcuts and focus need the active
    # window (offscreen, a shown window is both at once)
    qtbot.waitUntil(lambda: w.windowHandle() is not None and w.windowHandle().isExposed())
    w.activateWindow()
    qtbot.waitUntil(w.isActiveWindow)
    assert w.open_project(project)
    return w


@pytest.fixture
def window_on(qtbot):
    """``window_on(project)``: :func:`open_window` for tests with projects of their own."""
    return lambda project: open_window(qtbot, project)


@pytest.fixture
def window(qtbot, project):
    """The main window on the project (:func:`open_window`)."""
    w = open_window(qtbot, project)
    yield w
    w.session.close()


@pytest.fixture
def wait_idle(qtbot):
    """``wait_idle(session)`` waits for the session's background task to end."""
    def wait(session, timeout=30000) -> None:
        qtbot.waitUntil(lambda: not session.busy, timeout=timeout)

    return wait


@pytest.fixture
def wheel():
    """``wheel(widget, dy=120)`` sends a mouse-wheel event to the middle of a widget."""
    from PySide6.QtCore import QPoint, QPointF, Qt
    from PySide6.QtGui import QWheelEvent
    from PySide6.QtWidgets import QApplication

    def send(widget, dy: int = 120) -> None:
        pos = QPointF(widget.rect().center())
        event = QWheelEvent(pos, QPointF(widget.mapToGlobal(pos.toPoint())), QPoint(0, 0),
                            QPoint(0, dy), Qt.MouseButton.NoButton,
                            Qt.KeyboardModifier.NoModifier, Qt.ScrollPhase.NoScrollPhase,
                            False)
        QApplication.sendEvent(widget, event)

    return send
