"""The ``videotrack`` command: one sub-command per module in :mod:`videotrack.commands`.

Each command module provides ``add_parser(subparsers)``, which registers its parser and sets
``func`` to a callable taking the parsed arguments and returning an exit code. Errors a user
can cause (:class:`~kinematics.errors.LocatedError`) are printed as one line, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings

from kinematics.errors import LocatedError
from videotrack.errors import VideoTrackWarning

#: Sub-command modules, in the order ``--help`` lists them.
COMMAND_MODULES = (
    "videotrack.commands.chain",
    "videotrack.commands.synth",
    "videotrack.commands.detect",
    "videotrack.commands.fit",
    "videotrack.commands.histograms",
    "videotrack.commands.gui",
    "videotrack.commands.batch",
    "videotrack.commands.demo",
    "videotrack.commands.eval",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="videotrack",
        description=(
            "Model-based motion capture of marked animals: detect markers in videos, fit "
            "kinematic chains by simulated annealing, learn joint-angle histograms."
        ),
        epilog="Run 'videotrack COMMAND --help' for the options and examples of a command.",
    )
    parser.add_argument("--version", action="version", version=_version())
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).add_parser(subparsers)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return f"videotrack {version('videotrack')}"
    except PackageNotFoundError:  # running from a source tree
        return "videotrack (not installed)"


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one line on stderr, without disturbing a progress bar."""
    from tqdm import tqdm

    tqdm.write(f"videotrack: warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", VideoTrackWarning)
            warnings.showwarning = _show_warning
            return int(args.func(args) or 0)
    except LocatedError as err:
        print(f"videotrack: error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("videotrack: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
