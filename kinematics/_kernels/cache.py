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
The digest covers the modules of the records kernels take too (:data:`RECORD_MODULES`):
numba's cache index pickles an argument's NamedTuple class by module and name, so a record
moved to another module made every cached kernel fail to load ("Can't get attribute").
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


#: Modules (relative to the package root) defining the NamedTuple records kernels take as
#: arguments: BodyArrays, CameraArrays, FoldedBody, DofArrays, Schedule, ErrorArgs,
#: FitOutputs, Partitions, ObservationArrays.
RECORD_MODULES = ("model/packing.py", "cameras/models.py", "fit/problem.py",
                  "fit/partitions.py", "observe/observations.py")


def kernels_digest() -> str:
    """A digest of the source of every kernel module of the package and of the modules of
    the records the kernels take."""
    root = Path(__file__).parents[1]
    paths = [*sorted(Path(__file__).parent.glob("*.py")),
             *(root / name for name in RECORD_MODULES)]
    try:
        if paths:
            return hashlib.sha256(b"".join(path.read_bytes() for path in paths)).hexdigest()[:12]
    except OSError:
        pass
    return "unknown"  # sources not shipped (a frozen app): numba cannot cache them either


if not config.CACHE_DIR:  # must run before any kernel module is decorated
    config.CACHE_DIR = str(default_cache_dir() / kernels_digest())
