"""``videotrack gui``: the desktop program (PySide6 + pyqtgraph).

Qt is imported only when the command runs, so the rest of the command line never loads it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

EXAMPLES = """\
examples:
  # open a project: its video, views, chain, cameras, detections and results
  videotrack gui project.toml
  # one trial of a project folder (its config merged from the config.toml files above it)
  videotrack gui myproject --trial session1/trial01
  # start empty and open a project from the File menu
  videotrack gui

Without a display (e.g. over ssh) set QT_QPA_PLATFORM=offscreen for scripts, or use X
forwarding. VIDEOTRACK_NO_OPENGL=1 draws the 3D posture as three 2D projections, as it
is drawn where OpenGL runs only in software (llvmpipe); VIDEOTRACK_OPENGL=1 keeps the 3D
scene there.
See docs/gui.md for a tour with screenshots.
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "gui",
        help="open the desktop program: video with overlays, fitting, corrections",
        description=(
            "The VideoTrack window (paper Fig. 4): the per-frame error table, the video views "
            "with the detected markers and the projected chain, the 3D posture, fitting in "
            "the background, the chain editor, manual corrections and histograms."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("project", type=Path, nargs="?",
                   help="project file (TOML) to open, or with --trial a project folder")
    p.add_argument("--trial", metavar="NAME",
                   help="a trial of the project folder PROJECT, e.g. session1/trial01")
    p.set_defaults(func=run)


def run(args) -> int:
    from videotrack.errors import VideoTrackError

    if args.project is not None and not args.project.exists():
        raise VideoTrackError("no such project file or folder", file=args.project)
    if args.trial is not None and args.project is None:
        raise VideoTrackError("--trial needs the project folder", field="--trial")
    reason = _no_display()
    if reason:
        raise VideoTrackError(f"cannot start the GUI: {reason}")
    try:
        from ui.app import run as run_gui
    except ImportError as err:  # e.g. Qt's system libraries are missing
        raise VideoTrackError(f"cannot start the GUI: {err}") from None
    return run_gui(args.project, args.trial)


def _no_display() -> str:
    """Why Qt would abort for want of a display ('' when it should start): on Linux without
    DISPLAY or WAYLAND_DISPLAY and no other platform chosen, Qt's xcb plugin exits the process
    with "Reinstalling the application may fix this problem", which helps nobody."""
    import os

    if not sys.platform.startswith("linux"):
        return ""
    platform = os.environ.get("QT_QPA_PLATFORM", "")
    if platform and not platform.startswith(("xcb", "wayland")):
        return ""  # offscreen, vnc, eglfs, ...: the user chose one
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return ""
    return ("no display (neither DISPLAY nor WAYLAND_DISPLAY is set): run it on a desktop or "
            "with 'ssh -X', or set QT_QPA_PLATFORM=offscreen for scripts")
