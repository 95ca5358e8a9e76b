"""Atomic writing for libraries that write by file name (ezc3d, pynwb, pandas HDF)."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from videotrack.errors import VideoTrackError


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = "") -> Iterator[Path]:
    """A temporary path beside ``path`` to write to; on success it replaces ``path``, on any
    error it is removed and ``path`` is left as it was (never a half-written output)."""
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.",
                                   suffix=suffix or path.suffix)
    except OSError as err:
        raise VideoTrackError(f"cannot write file: {err.strerror}", file=path) from None
    os.close(fd)
    os.unlink(tmp)  # libraries that refuse to open an existing file get a free name
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError):
            raise VideoTrackError(f"cannot write file: {err.strerror or err}",
                                  file=path) from None
        raise


def frame_times(frames, rate: float) -> tuple:
    """Check a frame rate and frame numbers for a time-based format."""
    import numpy as np

    frames = np.asarray(frames, dtype=np.int64)
    if not (rate > 0 and np.isfinite(rate)):
        raise VideoTrackError(f"frame rate must be > 0, got {rate!r}", field="rate")
    return frames, frames / float(rate)


def column_names(names, path, what: str = "marker") -> list[str]:
    """Names as strings, refused when one repeats (a column of another tool's file each)."""
    names = [str(n) for n in names]
    seen = set()
    for n in names:
        if n in seen:
            raise VideoTrackError(f"{what} name {n!r} appears twice", file=path)
        seen.add(n)
    return names
