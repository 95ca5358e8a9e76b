"""Shared by the docs generators in tools/: write a generated file, or check it is current."""

from __future__ import annotations

import os
from pathlib import Path

from kinematics.fileio import atomic_write_text


def update_generated_file(path: str | os.PathLike, text: str, check: bool, how: str) -> int:
    """Write a generated file (atomically), or with ``check`` only compare it.

    Returns an exit code: 1 when checking finds the file out of date (``how`` says how to
    regenerate it), else 0. Used by the docs generators in ``tools/``.
    """
    path = Path(path)
    current = path.read_text(encoding="utf-8") if path.exists() else ""
    if check:
        ok = text == current
        print(f"{path.name} is up to date" if ok else f"{path.name} is out of date: {how}")
        return 0 if ok else 1
    atomic_write_text(path, text)
    print(f"wrote {path}")
    return 0
