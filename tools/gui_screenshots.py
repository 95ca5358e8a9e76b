"""Screenshots of the GUI for docs/gui.md, made offscreen on the demo project.

Makes the paper's locust test video (``videotrack synth``, with pixel noise and a ghost marker
per view), detects the markers, fits every frame with a shortened schedule, corrects one frame
by hand and learns the histograms, then saves:

* ``gui_main.png`` — the main window (Fig. 4 layout);
* ``gui_chain_editor.png`` — the chain editor;
* ``gui_histograms.png`` — the histogram view;
* ``gui_project_settings.png`` — the filter chain with its live preview.

Usage::

    python tools/gui_screenshots.py [--out docs/img] [--keep FOLDER]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import tomllib
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

REPO = Path(__file__).resolve().parents[1]


def make_project(folder: Path) -> Path:
    """Synthetic locust project, detected, with a short annealing schedule."""
    import tomli_w

    from videotrack.cli import main

    args = ["synth", str(folder), "--frames", "80", "--sequences", "2", "--noise", "3",
            "--ghosts", "1", "--occlusions", "0.02", "--motion-seed", "4"]
    if main(args) != 0 or main(["detect", str(folder / "project.toml")]) != 0:
        sys.exit("could not make the demo project")
    config = folder / "project.toml"
    raw = tomllib.loads(config.read_text(encoding="utf-8"))
    raw["anneal"] = {**raw.get("anneal", {}), "n_end": 7000, "n_l": 700, "n_tau": 300}
    config.write_text(tomli_w.dumps(raw), encoding="utf-8")
    return config


def settle(app, session=None, seconds: float = 0.3) -> None:
    """Process events until the session is idle and the widgets have painted."""
    end = time.monotonic() + seconds
    while time.monotonic() < end or (session is not None and session.busy):
        app.processEvents()
        time.sleep(0.01)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "img")
    parser.add_argument("--keep", type=Path, help="make the demo project here and keep it")
    args = parser.parse_args()

    from PySide6.QtWidgets import QApplication, QMessageBox

    from ui.views.main_window import MainWindow
    from videotrack.results.tables import read_table

    app = QApplication.instance() or QApplication([])
    app.setApplicationName("VideoTrack")
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp) / "locust-demo"
        config = make_project(folder)
        window = MainWindow()
        window.resize(1600, 980)
        window.show()
        window.open_project(config)
        s = window.session
        s.fit()
        settle(app, s)
        errors = {f: r.error for f, r in s.results.items()}
        worst = max(errors, key=errors.get)
        # the worst frame fixed by hand, as a user would: the femur-tibia angle set to what
        # the video shows (here: the ground truth), the rest re-fitted
        columns, truth = read_table(folder / "truth.csv")
        s.set_frame(worst)
        s.correct({8: float(truth[worst, columns.index("J2.gamma")])})
        settle(app, s)
        print(f"frame {worst}: error {errors[worst]:.1f} px, corrected "
              f"{s.results[worst].error:.1f} px")
        s.learn_histograms()
        good = sorted(f for f, r in s.results.items() if r.status == "ok")
        s.set_frame(good[len(good) // 2])
        window.table.follow(s.frame)
        settle(app, s, 0.5)
        window.grab().save(str(args.out / "gui_main.png"))

        editor = window.open_chain_editor()
        editor.resize(1000, 620)
        editor.select("segment", "femur")
        settle(app, seconds=0.3)
        editor.grab().save(str(args.out / "gui_chain_editor.png"))
        editor.reject()

        hist = window.open_histograms()
        hist.axes.setCurrentRow(8)  # J2.gamma
        settle(app, seconds=0.3)
        hist.grab().save(str(args.out / "gui_histograms.png"))
        hist.close()

        settings = window.open_project_dialog()
        settings.resize(1250, 760)
        settings.tabs.setCurrentIndex(1)
        settings.wait_preview()
        settle(app, seconds=0.3)
        settings.grab().save(str(args.out / "gui_project_settings.png"))
        settings.reject()

        window.ask_unsaved = lambda: QMessageBox.StandardButton.Discard  # a demo: no saving
        window.close()
        s.close()
    for name in ("main", "chain_editor", "histograms", "project_settings"):
        print(args.out / f"gui_{name}.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
