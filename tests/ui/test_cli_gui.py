"""``videotrack gui``: the command is listed without loading Qt and starts the window."""

from __future__ import annotations

import subprocess
import sys

import pytest

from videotrack.cli import main


def test_gui_command_help_and_missing_project(capsys, tmp_path):
    with pytest.raises(SystemExit) as exit_:
        main(["gui", "--help"])
    assert exit_.value.code == 0
    assert "videotrack gui project.toml" in capsys.readouterr().out
    assert main(["gui", str(tmp_path / "nope.toml")]) == 1
    assert "nope.toml: no such project file or folder" in capsys.readouterr().err


def test_gui_without_a_display_is_a_one_line_error():
    import os

    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    out = subprocess.run([sys.executable, "-m", "videotrack", "gui"], capture_output=True,
                         text=True, env=env, timeout=120)
    assert out.returncode == 1
    assert out.stderr.strip().startswith("videotrack: error: cannot start the GUI: no display")
    assert len(out.stderr.strip().splitlines()) == 1


def test_cli_does_not_load_qt():
    code = ("import sys, videotrack.cli\n"
            "videotrack.cli.build_parser()\n"
            "sys.exit(any(m.split('.')[0] in ('PySide6', 'pyqtgraph', 'ui') "
            "for m in sys.modules))\n")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_gui_command_opens_the_window(project):
    # in a fresh interpreter: quitting the application would end this one's event loops
    code = f"""
import os, sys
os.environ["QT_QPA_PLATFORM"] = "offscreen"
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication
app = QApplication([])
from ui.views.main_window import MainWindow
from videotrack.cli import main

def close_soon():
    for w in QApplication.topLevelWidgets():
        if isinstance(w, MainWindow) and w.isVisible():
            print(w.session.n_frames, w.session.view_names, w.errors)
            w.close()
    app.quit()

QTimer.singleShot(500, close_soon)
sys.exit(main(["gui", {str(project)!r}]))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "12 ['side', 'top'] []"
