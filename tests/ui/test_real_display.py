"""The GUI tests again, on a real X server (Xvfb, OpenGL from Mesa) where one can be started.

The other GUI tests run on Qt's offscreen platform, where a shown window is exposed and active
at once and there is no OpenGL. A real X server differs exactly there: showing is
asynchronous, key shortcuts and focus need the active window, and the 3D view is a real
OpenGL scene. Without Xvfb and Qt's X libraries (the README's test section lists the Debian
packages) they are skipped.
"""

from __future__ import annotations

import os
import select
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ui.views.posture_view import SOFTWARE_RENDERERS

HERE = Path(__file__).resolve().parent
XVFB = shutil.which("Xvfb")
#: GUI test files that open no window (the session and the pure adapters; the command's
#: test sets its own display): the same offscreen as on X, so not run again here.
WINDOWLESS = {"test_adapters.py", "test_session.py", "test_cli_gui.py"}
#: Where to read what to install (the packages are listed there once).
INSTALL = "see the README's test section for the packages"


@pytest.fixture(scope="module")
def x_display():
    """A private Xvfb screen; yields its DISPLAY name."""
    if XVFB is None:
        pytest.skip(f"no Xvfb on this machine ({INSTALL})")
    read, write = os.pipe()
    # -displayfd: the server picks a free display number and writes it once it is ready
    server = subprocess.Popen(
        [XVFB, "-displayfd", str(write), "-screen", "0", "1920x1200x24", "-nolisten", "tcp"],
        pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write)
    try:
        ready, _, _ = select.select([read], [], [], 30)
        number = os.read(read, 16).decode().strip() if ready else ""
        if not number.isdigit():
            pytest.skip("Xvfb did not start")
        yield f":{number}"
    finally:
        os.close(read)
        server.terminate()
        server.wait(timeout=30)


def on_display(display: str, **more: str) -> dict:
    """This process's environment for a child on ``display``: Qt's X platform, none of the
    settings that choose the 3D view or add pytest options of the outer run."""
    drop = ("WAYLAND_DISPLAY", "VIDEOTRACK_NO_OPENGL", "VIDEOTRACK_OPENGL", "PYTEST_ADDOPTS",
            "PYTEST_PLUGINS", "COV_CORE_SOURCE", "COV_CORE_CONFIG", "COV_CORE_DATAFILE")
    env = {k: v for k, v in os.environ.items() if k not in drop}
    return {**env, "DISPLAY": display, "QT_QPA_PLATFORM": "xcb", **more}


PROBE = """
import ui
from PySide6.QtWidgets import QApplication
from ui.views.posture_view import opengl_choice, opengl_renderer
app = QApplication([])
print("|".join(map(str, (app.platformName(), opengl_renderer(), *opengl_choice()))))
"""


def run_probe(display: str, **more: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", PROBE], env=on_display(display, **more),
                          cwd=HERE.parents[1], capture_output=True, text=True, timeout=120)


def probe(display: str, **more: str) -> list[str]:
    """Platform, OpenGL renderer, whether the 3D view uses OpenGL and why not, as a window
    on ``display`` sees them."""
    run = run_probe(display, **more)
    assert run.returncode == 0, run.stderr[-3000:]
    return run.stdout.strip().splitlines()[-1].split("|")


@pytest.fixture(scope="module")
def x_qt(x_display):
    """The display, once Qt is seen to open windows on it with OpenGL (else skipped: Qt's
    X libraries or Mesa missing)."""
    run = run_probe(x_display)
    if run.returncode != 0 or "|None|" in run.stdout:
        pytest.skip(f"Qt cannot open OpenGL windows on Xvfb here ({INSTALL}): "
                    + (run.stderr.strip().splitlines() or ["no OpenGL"])[-1])
    return x_display


def test_the_3d_view_chooses_opengl_by_its_renderer(x_qt):
    """Xvfb has no GPU, so Mesa draws OpenGL on the CPU: the 3D view falls back to 2D
    (every frame step would pay for it) unless VIDEOTRACK_OPENGL=1 asks for it."""
    platform, renderer, use, why_not = probe(x_qt)
    assert platform == "xcb"
    assert any(name in renderer.lower() for name in SOFTWARE_RENDERERS), renderer
    assert use == "False" and "VIDEOTRACK_OPENGL=1" in why_not
    assert probe(x_qt, VIDEOTRACK_OPENGL="1")[2:] == ["True", ""]


def test_the_gui_tests_pass_on_the_x_server(x_qt):
    """Every GUI test that opens a window, in a real one, the 3D view in OpenGL."""
    files = sorted(str(f) for f in HERE.glob("test_*.py")
                   if f.name not in WINDOWLESS | {Path(__file__).name})
    try:
        run = subprocess.run(
            [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-x", *files],
            env=on_display(x_qt, VIDEOTRACK_OPENGL="1"), cwd=HERE.parents[1],
            capture_output=True, text=True, timeout=900)
    except subprocess.TimeoutExpired as err:
        out = err.stdout or ""  # bytes even with text=True (Python 3.11)
        out = out.decode(errors="replace") if isinstance(out, bytes) else out
        pytest.fail(f"the GUI tests on Xvfb ran past {err.timeout} s:\n{out[-6000:]}")
    assert run.returncode == 0, (run.stdout + run.stderr)[-6000:]
