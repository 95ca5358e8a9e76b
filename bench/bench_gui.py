"""Responsiveness of the window (issue 15, item 1): event-loop stalls while fitting, cancel
latency, frame steps and playback.

Run from the repository root (offscreen Qt, no display needed)::

    python bench/bench_gui.py [--frames 200] [--ghosts 2] [--occlusions 0.02] [--out DIR]

or in a real window on a virtual X server (the 3D view there is its 2D fallback, as Mesa
draws OpenGL in software; ``VIDEOTRACK_OPENGL=1`` in front measures it in OpenGL)::

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1920x1200x24" python bench/bench_gui.py

Protocol: ``videotrack synth`` makes the paper's locust test video (``--frames`` frames, two
views, with ``--ghosts`` static ghost markers per view and ``--occlusions`` of the marker images
hidden) and ``videotrack detect`` detects it; the project's annealing parameters are the
defaults (no schedule shortened). In the main window (the 3D view as the window chooses it:
OpenGL with a hardware renderer or ``VIDEOTRACK_OPENGL=1``, else its 2D fallback):

* **stall during Fit all**: a 10-ms QTimer records when it fires while *Fit all* runs; a
  stall is the gap between two firings (10 ms when nothing blocks). p95 and max over the fit.
* **cancel latency**: *Fit all* again; after 1 s *Cancel*; the time until the task has ended
  (the window is idle again), event loop running; and the time until the cancelled fit has
  stopped computing in the background (the fitter stops only where it hands results over).
* **frame step (idle)**: the → action followed by processing the events it posted (redraw of
  views, table, timeline, posture and residual table), over 2 × 100 steps; median and p90.
* **playback**: Space, then frames shown per second over 3 s (the video's rate is the cap,
  at most 50 frames/s).

Figures go to stdout as a markdown table with their goals.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np
from _report import in_out_folder, machine, print_table

import ui  # noqa: F401  (before the QApplication: ui sets the shared OpenGL context)
from videotrack.cli import main as cli


def make_project(folder: Path, frames: int, synth_args: list[str]) -> Path:
    """``videotrack synth`` (one motion sequence unless ``synth_args`` say otherwise), then
    ``videotrack detect``; returns the project file."""
    args = ["synth", str(folder), "--frames", str(frames), "--sequences", "1", *synth_args,
            "--force"]
    assert cli(args) == 0
    assert cli(["detect", str(folder / "project.toml")]) == 0
    return folder / "project.toml"


def run_loop_until(app, done, timeout_s: float) -> None:
    """Process events until ``done()`` (an event loop that the timers can fire in)."""
    from PySide6.QtCore import QEventLoop, QTimer

    loop = QEventLoop()
    poll = QTimer(interval=5)
    poll.timeout.connect(lambda: loop.quit() if done() else None)
    QTimer.singleShot(int(timeout_s * 1000), loop.quit)
    poll.start()
    loop.exec()
    poll.stop()


def measure(project: Path) -> list[tuple]:
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication, QMessageBox

    from ui.views.main_window import MainWindow

    app = QApplication.instance() or QApplication([])
    window = MainWindow()  # the 3D view in OpenGL on a real display, its 2D fallback offscreen
    window.ask_unsaved = lambda: QMessageBox.StandardButton.Discard
    window.resize(1400, 900)
    window.show()
    run_loop_until(app, lambda: window.windowHandle().isExposed(), 30)
    window.activateWindow()
    assert window.open_project(project)
    s = window.session
    app.processEvents()
    view_3d = "OpenGL" if window.posture_view.opengl else "2D fallback"

    # a first fit of one frame compiles / loads the numba kernels outside the figures
    s.fit([0], "warm-up")
    run_loop_until(app, lambda: not s.busy, 600)

    ticks: list[float] = []
    timer = QTimer(interval=10)
    timer.timeout.connect(lambda: ticks.append(time.perf_counter()))
    timer.start()
    t0 = time.perf_counter()
    window.act_fit_all.trigger()
    run_loop_until(app, lambda: not s.busy, 3600)
    fit_s = time.perf_counter() - t0
    timer.stop()
    gaps = np.diff(ticks) * 1000 if len(ticks) > 1 else np.array([np.nan])
    n_fitted = len(s.results)

    s.undo()  # the fit again from nothing, to cancel it
    window.act_fit_all.trigger()
    run_loop_until(app, lambda: False, 1.0)
    t_cancel = time.perf_counter()
    window.act_cancel.trigger()
    run_loop_until(app, lambda: not s.busy, 600)
    cancel_s = time.perf_counter() - t_cancel
    run_loop_until(app, lambda: not s._released, 600)  # the fit let go runs out
    runout_s = time.perf_counter() - t_cancel

    steps = []
    for _ in range(2):
        s.set_frame(0)
        app.processEvents()
        for _ in range(min(100, s.n_frames - 1)):
            t = time.perf_counter()
            window.act_next.trigger()
            app.processEvents()
            steps.append((time.perf_counter() - t) * 1000)
    steps = np.array(steps)

    s.set_frame(0)
    app.processEvents()
    target = min(s.fps, 50.0)
    window.act_play.trigger()
    start_frame, t = s.frame, time.perf_counter()
    run_loop_until(app, lambda: s.frame >= s.n_frames - 1, 3.0)
    played = (s.frame - start_frame) / (time.perf_counter() - t)
    if window.playing:
        window.act_play.trigger()
    window.session.close()
    window.close()

    return [
        ("3D view", view_3d, "—"),
        (f"Fit all: {n_fitted} frames in {fit_s:.1f} s, event-loop stall p95",
         f"{np.percentile(gaps, 95):.0f} ms", "≤ 50 ms"),
        ("Fit all: event-loop stall max", f"{np.max(gaps):.0f} ms", "≤ 200 ms"),
        ("cancel latency (Esc → window idle)", f"{cancel_s:.2f} s", "≤ 0.2 s"),
        ("… the cancelled fit computes on in the background for", f"{runout_s:.2f} s",
         "—"),
        ("frame step idle, median", f"{np.median(steps):.1f} ms", "≤ 30 ms"),
        ("frame step idle, p90", f"{np.percentile(steps, 90):.1f} ms", "—"),
        (f"playback (video {s.fps:g} frames/s)", f"{played:.1f} frames/s",
         f"≥ {min(25.0, target):g} frames/s"),
    ]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--ghosts", type=int, default=2)
    parser.add_argument("--occlusions", type=float, default=0.02)
    parser.add_argument("--out", type=Path, help="keep the project here")
    args = parser.parse_args(argv)

    def run(folder: Path, _keep: bool) -> int:
        project = make_project(folder, args.frames, ["--ghosts", str(args.ghosts),
                                                     "--occlusions", str(args.occlusions)])
        rows = measure(project)
        print(f"\nmachine: {machine()}; QT_QPA_PLATFORM={os.environ['QT_QPA_PLATFORM']}")
        print_table(rows)
        return 0

    return in_out_folder(args.out, "bench-gui-", run)


if __name__ == "__main__":
    sys.exit(main())
