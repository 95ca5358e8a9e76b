"""Atomic file writing: every output of the project goes through :func:`atomic_write`;
and :func:`parse_toml`, which every TOML file is read by.

A reader (or a resumed batch job) sees either the old file or the complete new one, never a
half-written file: the data goes to a temporary file in the same folder, is flushed to disk,
and then replaces the target with ``os.replace`` (atomic on POSIX and Windows).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import tomllib
from collections.abc import Iterator
from pathlib import Path

from kinematics.errors import LocatedError


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", **open_kwargs) -> Iterator:
    """Open a temporary file for writing; on success it replaces ``path``.

    On any exception the temporary file is removed and ``path`` is left untouched.
    ``mode`` is ``"w"`` (text, UTF-8 unless ``encoding`` is given) or ``"wb"``.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    if mode == "w":
        open_kwargs.setdefault("encoding", "utf-8")
        open_kwargs.setdefault("newline", "\n")
    try:
        perms = path.stat().st_mode & 0o777 if path.exists() else 0o644
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as err:
        raise LocatedError(f"cannot write file: {err.strerror}", file=path) from None
    try:
        with os.fdopen(fd, mode, **open_kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, perms)  # mkstemp creates 0600 files; keep the target's permissions
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError):
            raise LocatedError(f"cannot write file: {err.strerror or err}", file=path) from None
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_write(path, "w") as fh:
        fh.write(text)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_write(path, "wb") as fh:
        fh.write(data)


def parse_toml(text: str) -> dict:
    """``tomllib.loads``, where a document nested too deep for its recursion (arrays in
    arrays a thousand deep) is a ``TOMLDecodeError`` at the line it nests deepest, as any
    other syntax error, not a ``RecursionError``."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        depth = best = 0
        line = where = 1
        for ch in text:
            if ch == "\n":
                line += 1
            elif ch in "[{":
                depth += 1
                if depth > best:
                    best, where = depth, line
            elif ch in "]}":
                depth -= 1
        raise tomllib.TOMLDecodeError(
            f"arrays or tables nested too deep (at line {where}, column 1)") from None
