"""A scripted correction session in the window (issue 15): how many actions it takes to fix
every wrong frame of a cluttered video.

Run from the repository root (offscreen Qt, no display needed)::

    python bench/bench_correction.py [--frames 200] [--ghosts 2] [--occlusions 0.02]
                                     [--out DIR] [--log]

Protocol: ``videotrack synth`` makes the paper's locust test video (``--frames`` frames in one
sequence, two views, ``--ghosts`` static ghost markers per view, ``--occlusions`` of the marker
images hidden) and ``videotrack detect`` detects it; default annealing. In the main window
(offscreen) *Fit all* (F5) fits it. Then a scripted user works through the video with the
keys of ``docs/gui.md``'s "Correcting a video", using ``truth.csv`` as their eyes: a posture
is *right* when every free axis is within 10° of the truth, *wrong* otherwise (the user sees
the model off the markers; they cannot see the numbers).

Home shows frame 0; Ctrl+→ (*next frame needing attention*) goes to the next flagged frame.
On each frame the user tries, in this order, and stops at the first that leaves it right:

1. **accept** (Ctrl+Return) when it is right already: this key also goes to the next frame;
2. **alternative posture** (A) when the frame is ``ambiguous`` and the other posture, drawn
   dashed in the views, is right;
3. **re-fit forward from the neighbour** (←, F9, →) when the frame before is corrected and
   right and was not carried forward yet (the run stops at once when this frame's error stays
   above the threshold: then nothing changed and nothing is undone);
4. **drag** the model marker farthest from where the user sees it onto its true image
   position (in the view where it is farthest and visible) — the drag pins the axes above
   the marker and re-fits the rest; at most two drags;
5. **type** the true value of the axis farthest off into its number box (pins it and re-fits
   the rest), axis after axis.

After a fix (2–5) the user spreads it with F9 when the next frame is flagged and wrong too
(a glance at the next red row), Ctrl+Z if that left it wrong; then, the next frames still
wrong, → to the last wrong frame of the stretch, fix it as above and press I (interpolate
between the two fixed ends); then Ctrl+→, until the window's summary says "0 to check".
Every key, drag and typed value is one action; all of them are counted, failed tries and
navigation included. The user keeps the bar the window shows after *Fit all* (walkthrough
step 2: the threshold the fit measured) and starts with Ctrl+→ (Home first when the window is
not at frame 0). Frames that are wrong but never flagged are reported apart: no user looking
only at flagged frames visits them (the flag's misses).

With ``--hide`` the user also uses H: on a visited frame where the video shows a marker
missing in a view (occluded in the truth) that is not marked yet, they select the
occlusion's rows (click, Shift+click: two actions), click the model marker, press H and F7
(five actions per marker and stretch), then go on as above.

Everything goes through the window: its actions (``ui/views/shortcuts.py``), the video view's
marker drag signal and the correction panel's number boxes; the session only reports.
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
from bench_gui import make_project, run_loop_until

import ui  # noqa: F401  (before the QApplication: ui sets the shared OpenGL context)
from kinematics.model.histograms import wrap_deg

#: A posture is right when every free axis is within this many degrees of the truth.
RIGHT_DEG = 10.0
#: Drags tried on one frame before typing axis values.
MAX_DRAGS = 2


class User:
    """The scripted user: presses the window's keys and counts them."""

    def __init__(self, app, window, truth_path: Path, log: bool, hide: bool = False) -> None:
        from ui import adapters
        from videotrack.results.tables import read_table

        self.app, self.window, self.s = app, window, window.session
        self.adapters, self.log = adapters, log
        body = self.s.body
        columns, table = read_table(truth_path)
        self.free = adapters.free_axes(body)
        labels = body.axis_labels
        self.truth = np.full((self.s.n_frames, body.n_axes), np.nan)
        for k in self.free:
            self.truth[:, k] = table[: self.s.n_frames, columns.index(labels[k])]
        #: true image position (u, v) and visibility per view and marker, per frame
        self.seen = {}
        for v, view in enumerate(self.s.view_names):
            for m, name in enumerate(body.marker_names):
                cols = [columns.index(f"{view}.{name}.{c}") for c in ("u", "v", "visible")]
                self.seen[v, m] = table[: self.s.n_frames][:, cols]
        self.hide = hide  # the user marks occluded markers hidden (H) where they see them
        self.actions = self.navigation = self.failed = 0
        self.by_kind: dict[str, int] = {}
        self.carried: set[int] = set()  # frames F9 already ran from

    # -- what the user sees ---------------------------------------------------------------
    def off_deg(self, frame: int, angles_deg=None) -> np.ndarray:
        """|posture − truth| per free axis (wrapped to ±180°) in ``frame``: the fitted
        posture, or ``angles_deg``; inf when not fitted."""
        if angles_deg is None:
            r = self.s.results.get(frame)
            if r is None:
                return np.full(len(self.free), np.inf)
            angles_deg = r.angles_deg
        return np.abs(wrap_deg(np.asarray(angles_deg, float)[self.free]
                               - self.truth[frame, self.free]))

    def right(self, frame: int, angles_deg=None) -> bool:
        """Whether the frame's posture (or ``angles_deg`` there) is right."""
        return bool(np.all(self.off_deg(frame, angles_deg) <= RIGHT_DEG))

    def wrong_frames(self) -> list[int]:
        return [f for f in range(self.s.n_frames) if not self.right(f)]

    def flagged(self) -> list[int]:
        return self.adapters.frames_to_check(self.s.results, self.s.threshold)

    # -- acting -----------------------------------------------------------------------------
    def press(self, name: str, kind: str, navigation: bool = False) -> None:
        """Trigger the window's action ``act_<name>`` (one key press) and wait for the
        window to be idle (a re-fit it started has arrived)."""
        self.count(kind, navigation)
        getattr(self.window, f"act_{name}").trigger()
        self.settle()

    def count(self, kind: str, navigation: bool = False) -> None:
        self.actions += 1
        self.navigation += navigation
        self.by_kind[kind] = self.by_kind.get(kind, 0) + 1

    def settle(self) -> None:
        run_loop_until(self.app, lambda: not self.s.busy and self.window.correction.pending
                       is None, 600)
        self.app.processEvents()

    def drag(self, frame: int) -> bool:
        """Drag the model marker farthest from its true position; False when none is seen
        off (every visible marker within 3 px)."""
        overlays = self.s.overlays()
        best = None
        for v, overlay in enumerate(overlays):
            for m, xy in enumerate(np.asarray(overlay.markers, float)):
                u, w, visible = self.seen[v, m][frame]
                d = float(np.hypot(xy[0] - u, xy[1] - w))
                if visible and np.isfinite(d) and (best is None or d > best[0]):
                    best = (d, v, m, u, w)
        if best is None or best[0] < 3.0:
            return False
        _, v, m, u, w = best
        self.count("drag marker")
        # the scatter's drop signal, as a mouse release over the view emits it
        self.window.video_views[v].markers.dragged.emit(m, float(u), float(w))
        self.settle()
        return True

    def type_axis(self, frame: int) -> None:
        """Type the true value of the axis farthest off into its number box."""
        k = self.free[int(np.argmax(self.off_deg(frame)))]
        box = self.window.correction.sliders.rows[k][2]
        self.count("typed value")
        box.setValue(float(self.truth[frame, k]))  # Enter in the box commits this value
        self.settle()

    def hide_occluded(self, f: int) -> bool:
        """With ``hide``: for each marker the user sees missing in a view of frame ``f``
        (occluded there in the truth) and not marked yet, mark it hidden over the occlusion
        from ``f`` on: click row ``f`` and Shift+click the occlusion's last row (the user
        steps there to see where it ends: counted as those two clicks), click the model
        marker, H, F7. Returns whether it marked anything."""
        from PySide6.QtCore import QItemSelectionModel

        s, table, done = self.s, self.window.table, False
        flags = QItemSelectionModel.SelectionFlag
        for (v, m), seen in self.seen.items():
            if seen[f, 2] != 0 or s.hidden_in_frame(f)[v, m]:
                continue
            end = f
            while end + 1 < s.n_frames and self.seen[v, m][end + 1, 2] == 0:
                end += 1
            table.selectionModel().clearSelection()
            for g in range(f, end + 1):
                index = table.proxy.index(table.row_of(g), 0)
                table.selectionModel().select(index, flags.Select | flags.Rows)
            self.count("select rows")
            if end > f:
                self.count("select rows")
            self.count("click marker")
            self.window.select_marker(v, m)
            self.press("hide_marker", "hide marker (H)")
            self.press("fit_selected", "fit selected (F7)")
            done = True
        return done

    # -- one frame --------------------------------------------------------------------------
    def fix(self, f: int) -> str:
        """Make frame ``f`` (shown) right; returns what did it."""
        s = self.s
        r = s.results.get(f)
        if (r is not None and r.status == "ambiguous" and len(r.candidates) >= 2
                and self.right(f, r.candidates[1].angles_deg)):
            # the views draw the alternative dashed: the user sees it is right, presses A
            self.press("swap", "alternative (A)")
            if self.right(f):
                return "alternative"
            self.press("undo", "undo a failed try")
            self.failed += 2
        prev = s.results.get(f - 1)
        if (f > 0 and f - 1 not in self.carried and prev is not None
                and prev.status == "corrected" and self.right(f - 1)):
            self.press("prev", "frame step", navigation=True)
            before = s.results.get(f)
            self.press("refit_forward", "re-fit forward (F9)")
            self.carried.add(f - 1)
            self.press("next", "frame step", navigation=True)
            if self.right(f):
                return "re-fit from neighbour"
            self.failed += 3
            if s.results.get(f) is not before:  # the run changed it for the worse
                self.press("undo", "undo a failed try")
                self.failed += 1
        for _ in range(MAX_DRAGS):
            if not self.drag(f):
                break
            if self.right(f):
                return "drag"
        for _ in self.free:
            self.type_axis(f)
            if self.right(f):
                return "typed value"
        return "not fixed"

    def spread(self, f: int, how: str, how_by: dict) -> None:
        """After fixing ``f``: F9 when the next frame is flagged and wrong too (the user
        glances at the next red row); Ctrl+Z when the run left it wrong."""
        s, nxt = self.s, f + 1
        if (how == "not fixed" or nxt >= s.n_frames or nxt not in set(self.flagged())
                or self.right(nxt)):
            return
        self.press("refit_forward", "re-fit forward (F9)")
        self.carried.add(f)
        if self.right(nxt):
            return
        self.failed += 1
        if s.can_undo and s.undo_label.startswith("re-fit forward"):
            self.press("undo", "undo a failed try")
            self.failed += 1
        self.bridge(f, how_by)

    def bridge(self, f: int, how_by: dict) -> None:
        """A wrong stretch after the fixed frame ``f``: → to its last frame, fix that one
        and press I (the pinned axes interpolated between the two ends, the rest
        re-fitted); the frames between become ``corrected``."""
        s, end = self.s, f
        while end + 1 < s.n_frames and not self.right(end + 1):
            self.press("next", "frame step", navigation=True)
            end += 1
        how_by[end] = self.fix(end)
        if end - f >= 2 and how_by[end] != "not fixed":
            self.press("interpolate", "interpolate (I)")
            for k in range(f + 1, end):
                how_by[k] = "interpolated" if self.right(k) else "interpolated, still wrong"

    def session(self) -> dict:
        """Work through the video; returns the visited frames and how each was fixed."""
        s, flagged = self.s, set(self.flagged())
        how: dict[int, str] = {}
        if not flagged:  # the summary says "0 to check"
            return how
        if s.frame != 0:
            self.press("first", "frame step", navigation=True)
        if s.frame not in flagged:
            self.press("next_bad", "next needing attention", navigation=True)
            if s.frame not in flagged:
                return how
        while True:
            f = s.frame
            if f in how:  # visited again: nothing more to do
                break
            if self.hide:
                self.hide_occluded(f)
            if self.right(f):
                how[f] = "accept"
                self.press("accept_next", "accept and next", navigation=True)
            else:
                how[f] = self.fix(f)
                self.spread(f, how[f], how)
                if not self.flagged():  # the summary says "0 to check": done
                    if self.log:
                        print(f"frame {f}: {how[f]} ({self.actions} actions so far)")
                    break
                self.press("next_bad", "next needing attention", navigation=True)
            if self.log:
                print(f"frame {f}: {how[f]} ({self.actions} actions so far)")
            if s.frame == f:  # Ctrl+→ found none after this one
                break
        return how


def measure(project: Path, log: bool, hide: bool = False) -> list[tuple]:
    from PySide6.QtWidgets import QApplication, QMessageBox

    from ui.views.main_window import MainWindow

    app = QApplication.instance() or QApplication([])
    window = MainWindow(use_opengl=False)
    window.ask_unsaved = lambda: QMessageBox.StandardButton.Discard
    window.resize(1400, 900)
    window.show()
    assert window.open_project(project)
    s = window.session
    app.processEvents()

    t0 = time.perf_counter()
    window.act_fit_all.trigger()
    run_loop_until(app, lambda: not s.busy, 3600)
    fit_s = time.perf_counter() - t0
    if len(s.results) != s.n_frames:  # no figures from a fit that failed
        raise SystemExit(f"Fit all fitted {len(s.results)} of {s.n_frames} frames: "
                         f"{window.errors}")
    user = User(app, window, project.parent / "truth.csv", log, hide)
    wrong0 = set(user.wrong_frames())
    flagged0 = set(user.flagged())  # at the bar the window shows: the fit's threshold
    missed = sorted(wrong0 - flagged0)

    t0 = time.perf_counter()
    how = user.session()
    work_s = time.perf_counter() - t0
    wrong1 = user.wrong_frames()
    left_flagged = sorted(set(wrong1) & set(user.flagged()))
    window.session.close()
    window.close()

    fixes = {k: sum(v == k for v in how.values()) for k in dict.fromkeys(how.values())}
    print(f"Fit all: {len(s.results)} frames in {fit_s:.1f} s; session {work_s:.1f} s")
    print("frames by how they were done:", fixes)
    print("actions by kind:", user.by_kind)
    print("wrong, never flagged (after Fit all):", missed)
    print("wrong at the end:", wrong1)
    return [
        ("frames (fitted by Fit all)", f"{s.n_frames} ({len(s.results)})", "—"),
        ("wrong frames after Fit all (> 10° on an axis)", len(wrong0), "—"),
        (f"frames flagged at the fit's threshold, {s.threshold:.1f} px (wrong among them)",
         f"{len(flagged0)} ({len(wrong0 & flagged0)})", "—"),
        ("frames visited", len(how), "—"),
        ("actions (of which navigation keys; failed tries)",
         f"{user.actions} ({user.navigation}; {user.failed})", "—"),
        ("actions per wrong frame", f"{user.actions / len(wrong0):.2f}" if wrong0 else
         "— (none wrong)", "≤ 2"),
        ("… without navigation keys (accepts of right frames are navigation)",
         f"{(user.actions - user.navigation) / len(wrong0):.2f}" if wrong0 else "—", "—"),
        ("actions per visited frame", f"{user.actions / max(len(how), 1):.2f}", "—"),
        ("wrong flagged frames left", len(left_flagged), "0"),
        ("wrong frames never flagged (the flag's misses), after Fit all", len(missed), "—"),
        ("wrong frames left, all (misses included)", len(wrong1), "—"),
    ]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--ghosts", type=int, default=2)
    parser.add_argument("--occlusions", type=float, default=0.02)
    parser.add_argument("--synth", default="", help="more 'videotrack synth' options, "
                        "e.g. \"--sequences 5 --flicker-ghosts 2\"")
    parser.add_argument("--out", type=Path, help="keep the project here")
    parser.add_argument("--log", action="store_true", help="print every visited frame")
    parser.add_argument("--hide", action="store_true", help="the user also marks markers "
                        "they see occluded hidden (H) over the occlusion, then F7")
    args = parser.parse_args(argv)

    def run(folder: Path, _keep: bool) -> int:
        project = make_project(folder, args.frames, ["--ghosts", str(args.ghosts),
                                                     "--occlusions", str(args.occlusions),
                                                     *args.synth.split()])
        rows = measure(project, args.log, args.hide)
        print(f"\nsynth: --frames {args.frames} --ghosts {args.ghosts} --occlusions "
              f"{args.occlusions} {args.synth}".rstrip() + (" ; user marks occlusions (H)"
                                                            if args.hide else ""))
        print(f"machine: {machine()}; QT_QPA_PLATFORM={os.environ['QT_QPA_PLATFORM']}")
        print_table(rows)
        return 0

    return in_out_folder(args.out, "bench-correction-", run)


if __name__ == "__main__":
    sys.exit(main())
