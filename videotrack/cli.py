"""The ``videotrack`` command: one sub-command per module in :mod:`videotrack.commands`.

Each command module provides ``add_parser(subparsers)``, which registers its parser and sets
``func`` to a callable taking the parsed arguments and returning an exit code. Errors a user
can cause (:class:`~kinematics.errors.LocatedError`) are printed as one line, never a traceback;
so are a missing optional dependency (naming the extra to install), a file the system refuses
(:class:`OSError`) and, as a last resort, an unexpected error (with a hint to report it).
VideoTrack's own warnings are printed as one line each; other libraries' warnings (numpy's
"All-NaN slice encountered" ...) are kept from the user, since the code turns the conditions
behind them into its own messages. ``VIDEOTRACK_DEBUG=1`` shows both in full, tracebacks
included.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import sys
import warnings

from kinematics.errors import LocatedError
from videotrack.errors import VideoTrackWarning

# FFmpeg prints its own lines ("[ffv1 @ 0x...] slice count 18 is invalid") on damaged videos;
# VideoTrack reports those as one-line warnings. OpenCV reads this once, when its FFmpeg
# backend starts, which may be before videotrack.detect.video is imported (a user's value wins).
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

#: Sub-command modules, in the order ``--help`` lists them.
COMMAND_MODULES = (
    "videotrack.commands.chain",
    "videotrack.commands.synth",
    "videotrack.commands.calibrate",
    "videotrack.commands.detect",
    "videotrack.commands.keypoints",
    "videotrack.commands.triangulate",
    "videotrack.commands.fit",
    "videotrack.commands.histograms",
    "videotrack.commands.gui",
    "videotrack.commands.batch",
    "videotrack.commands.demo",
    "videotrack.commands.eval",
    "videotrack.commands.export",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="videotrack",
        description=(
            "Model-based motion capture of marked animals: detect markers in videos, fit "
            "kinematic chains by simulated annealing, learn joint-angle histograms."
        ),
        epilog="Run 'videotrack COMMAND --help' for the options and examples of a command. "
               "Set VIDEOTRACK_DEBUG=1 to see tracebacks and the warnings of libraries.",
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


#: Optional dependencies by top-level module: the extra of ``pip install 'videotrack[EXTRA]'``.
OPTIONAL_EXTRAS = {"dask": "dask", "distributed": "dask", "sleap_io": "markerless",
                   "ezc3d": "markerless", "pynwb": "markerless", "ndx_pose": "markerless"}


def _debug() -> bool:
    return os.environ.get("VIDEOTRACK_DEBUG", "") not in ("", "0")


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """VideoTrack's warnings as one line on stderr, without disturbing a progress bar; other
    libraries' warnings go to :func:`_stray_warning`."""
    from tqdm import tqdm

    if not issubclass(category, VideoTrackWarning):
        _stray_warning(message, category, filename, lineno)
        return
    tqdm.write(f"videotrack: warning: {message}", file=sys.stderr)


def _stray_warning(message, category, filename, lineno) -> None:
    """A warning of another library (numpy, OpenCV, matplotlib ...). The conditions behind them
    are turned into VideoTrack's own messages where they matter, so they are shown only with
    VIDEOTRACK_DEBUG=1 (the tests replace this function to catch any that leak)."""
    if _debug():
        from tqdm import tqdm

        tqdm.write(f"videotrack: debug: {category.__name__} at {filename}:{lineno}: "
                   f"{message}", file=sys.stderr)


def _missing_module(err: ModuleNotFoundError) -> str:
    """The one-line message for a module that is not installed."""
    name = (err.name or "").split(".")[0]
    extra = OPTIONAL_EXTRAS.get(name)
    if extra is not None:
        return (f"this needs the optional dependency '{name}', which is not installed: "
                f"python -m pip install 'videotrack[{extra}]'")
    return (f"the module '{err.name}' is missing: VideoTrack's installation is incomplete "
            "(python -m pip install videotrack)")


def _os_error(err: OSError) -> str:
    what = err.strerror or str(err)
    where = err.filename if err.filename is not None else None
    if where is None:
        return what
    where = os.fspath(where)
    if err.filename2 is not None:
        where += f" -> {os.fspath(err.filename2)}"
    return f"{where}: {what}"


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
    except BrokenPipeError:  # e.g. 'videotrack chain show ... | head' stopped reading
        with contextlib.suppress(OSError, ValueError, AttributeError):
            # no second error at exit, when Python flushes stdout again
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except Exception as err:  # the last resort: still one line, never a traceback
        if _debug():
            raise
        print(f"videotrack: error: {_unexpected(err)}", file=sys.stderr)
        return 1


def _unexpected(err: Exception) -> str:
    if isinstance(err, ModuleNotFoundError):
        return _missing_module(err)
    if isinstance(err, MemoryError):
        return "out of memory"
    if isinstance(err, UnicodeDecodeError):
        return (f"an input file is not text in UTF-8 ({err.reason} at byte {err.start}): "
                "is it the right file?")
    if isinstance(err, OSError):
        return _os_error(err)
    text = " ".join(str(err).split()) or "(no message)"
    return (f"internal error: {type(err).__name__}: {text} (this is a bug in VideoTrack: "
            "please report it with the output of the same command run with "
            "VIDEOTRACK_DEBUG=1)")


if __name__ == "__main__":
    sys.exit(main())
