"""Screenshots of the correcting workflow for docs/gui.md, from a real window.

The real MainWindow grabbed (``QWidget.grab()``) on a virtual X server, the 3D view in
OpenGL (``VIDEOTRACK_OPENGL=1``: Mesa draws it in software there); without a display it runs
on Qt's offscreen platform (the 3D view then its 2D fallback). Saves into ``docs/img/``:

* ``gui_correcting.png`` — the main window on a cluttered 200-frame project (ghosts,
  flickering ghosts, occlusions) after *Fit all*, a wrong frame selected
  (wrong against the synthetic truth);
* ``gui_shortcuts.png`` — the shortcut sheet (``?``);
* ``gui_keypoints.png`` — a keypoint project (DeepLabCut files of three cameras, no video);
* ``gui_correction_panel.png`` — the posture, the correction panel with an axis typed in
  (pinned: bold) and the rest re-fitted, and the marker residual table;
* ``gui_hidden.png`` — a frame where a marker is occluded in one view, the marker marked
  hidden there (H: a cross, "hidden" in the residual table) and the frame fitted again.

Usage::

    QT_QPA_PLATFORM=xcb VIDEOTRACK_OPENGL=1 xvfb-run -a -s "-screen 0 1920x1200x24" \\
        python tools/make_gui_screenshots.py [--out docs/img] [--keep FOLDER]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "tools"))

import numpy as np  # noqa: E402
from gui_screenshots import settle  # noqa: E402

import ui  # noqa: F401,E402  (before the QApplication: ui sets the shared OpenGL context)

#: The cluttered project: the correction bench's harder set-up.
CLUTTER = ["--ghosts", "2", "--flicker-ghosts", "2", "--occlusions", "0.05",
           "--sequences", "5"]
#: Largest file written; bigger grabs are scaled down.
MAX_BYTES = 300_000


def save(widget, path: Path) -> None:
    """``widget.grab()`` as PNG, scaled down until it is under :data:`MAX_BYTES`."""
    from PySide6.QtCore import Qt

    image = widget.grab().toImage()
    scale = 1.0
    while True:
        shown = image if scale == 1.0 else image.scaledToWidth(
            int(image.width() * scale), Qt.TransformationMode.SmoothTransformation)
        shown.save(str(path))
        if path.stat().st_size < MAX_BYTES or scale < 0.4:
            break
        scale *= 0.85
    print(f"{path} ({shown.width()}x{shown.height()}, {path.stat().st_size // 1000} KB)")


def window_on(project: Path):
    from PySide6.QtWidgets import QApplication, QMessageBox

    from ui.views.main_window import MainWindow

    window = MainWindow()
    window.ask_unsaved = lambda: QMessageBox.StandardButton.Discard  # a demo: no saving
    window.resize(1400, 880)
    window.show()
    waited = 0
    while not window.windowHandle().isExposed():  # a real display shows asynchronously
        settle(QApplication.instance(), seconds=0.05)
        waited += 1
        if waited > 600:
            sys.exit("the window was never shown (30 s): is the display working?")
    assert window.open_project(project)
    return window


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "img")
    parser.add_argument("--keep", type=Path, help="make the projects here and keep them")
    args = parser.parse_args()

    from bench_correction import User
    from bench_gui import make_project
    from PySide6.QtWidgets import QApplication

    from videotrack.synth.keypoints import write_session

    app = QApplication.instance() or QApplication([])
    app.setApplicationName("VideoTrack")
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        project = make_project(root / "cluttered", 200, CLUTTER)
        window = window_on(project)
        s = window.session
        window.act_fit_all.trigger()
        settle(app, s)
        user = User(app, window, project.parent / "truth.csv", log=False)
        wrong = user.wrong_frames()
        # the wrong frame the user is sent to first (flagged), else the first wrong one
        flagged = [f for f in wrong if f in set(user.flagged())]
        frame = (flagged or wrong or [0])[0]
        s.set_frame(frame)
        window.table.follow(frame)
        settle(app, s, 0.5)
        print(f"frame {frame}: {s.results[frame].status}, error {s.results[frame].error:.1f}"
              f" px, off by up to {user.off_deg(frame).max():.0f}°")
        save(window, args.out / "gui_correcting.png")

        sheet = window.show_shortcuts()  # what the ? key runs
        sheet.resize(600, 1340)  # every row
        settle(app, seconds=0.3)
        save(sheet, args.out / "gui_shortcuts.png")
        sheet.close()

        # the user's correction: the axis farthest off typed in (pinned, the rest re-fitted)
        user.type_axis(frame)
        right = window.correction.parentWidget()  # posture | correction | residuals
        right.setSizes([230, 330, 190])
        settle(app, s, 0.5)
        save(right, args.out / "gui_correction_panel.png")

        # a marker occluded in one view (the truth says where), marked hidden there with H
        # and the frame fitted again (F6)
        right.setSizes([230, 230, 290])
        f, v, m = min((int(f), v, m) for (v, m), seen in user.seen.items()
                      for f in np.flatnonzero(seen[:, 2] == 0) if f != frame)
        s.set_frame(f)
        window.table.follow(f)
        settle(app, s, 0.3)
        window.select_marker(v, m)
        window.toggle_hidden()
        window.act_fit_current.trigger()
        settle(app, s, 0.5)
        print(f"frame {f}: {s.body.marker_names[m]} hidden in {s.view_names[v]}")
        save(window, args.out / "gui_hidden.png")
        window.close()
        s.close()

        write_session(root / "keypoints", 40, n_cameras=3, noise_px=1.0, bad_share=0.1,
                      project_text="[anneal]\nseed = 1\n")
        window = window_on(root / "keypoints" / "project.toml")
        s = window.session
        window.act_fit_all.trigger()
        settle(app, s)
        s.set_frame(12)
        window.table.follow(12)
        settle(app, s, 0.5)
        save(window, args.out / "gui_keypoints.png")
        window.close()
        s.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
