"""Keep numba's cache of compiled kernels out of the installed package.

numba's default (``cache=True``) writes ``__pycache__/*.nbi|nbc`` beside the source files, i.e.
into site-packages. pip does not know those files, so after ``pip uninstall`` (or an upgrade,
or switching to an editable install) the package folder survives as an empty namespace package
that shadows the new install. Here the cache goes to the user's cache folder instead,
``$XDG_CACHE_HOME/videotrack/numba/<digest>`` (``~/.cache/...``; ``%LOCALAPPDATA%`` on
Windows), unless ``NUMBA_CACHE_DIR`` is set. numba keys the cache by source path, so installs
never mix; but it checks only a kernel's own file, and a kernel compiles in the kernels of
other modules it calls (``fit_frames`` the refinement's): ``<digest>`` is of every kernel
module's source, so a change to any of them compiles afresh instead of reusing stale code.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from numba.core import config


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or (
        os.environ.get("LOCALAPPDATA") if os.name == "nt" else None)
    return Path(base or Path.home() / ".cache") / "videotrack" / "numba"


def kernels_digest() -> str:
    """A digest of the source of every kernel module of the package."""
    paths = sorted(Path(__file__).parent.glob("*.py"))
    try:
        if paths:
            return hashlib.sha256(b"".join(path.read_bytes() for path in paths)).hexdigest()[:12]
    except OSError:
        pass
    return "unknown"  # sources not shipped (a frozen app): numba cannot cache them either


if not config.CACHE_DIR:  # must run before any kernel module is decorated
    config.CACHE_DIR = str(default_cache_dir() / kernels_digest())
