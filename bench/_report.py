"""What every benchmark prints: the machine it ran on and a markdown table of figures."""

from __future__ import annotations

import os
import platform
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path


def machine() -> str:
    """CPU model (from lscpu where available) and the number of CPUs."""
    try:
        text = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
        name = next((ln.split(":", 1)[1].strip() for ln in text.splitlines()
                     if ln.startswith("Model name")), "")
    except OSError:
        name = ""
    return f"{name or platform.processor() or platform.machine()}, {os.cpu_count()} CPUs"


def print_table(rows, target: str = "goal", results=("result",)) -> None:
    """Print (measurement, result, target) rows as a markdown table; with several
    ``results`` column names, rows are (measurement, one value per result column, target)."""
    width = max(len(r[0]) for r in rows)
    print(f"| {'measurement'.ljust(width)} | {' | '.join(results)} | {target} |")
    print(f"| {'-' * width} |{' --- |' * len(results)} --- |")
    for name, *values, goal in rows:
        print(f"| {name.ljust(width)} | {' | '.join(str(v) for v in values)} | {goal} |")


def in_out_folder(out: Path | None, prefix: str, run: Callable[[Path, bool], int]) -> int:
    """``run(folder, keep)`` in ``out`` (created) or, without one, in a temporary folder that
    is removed afterwards (``keep`` False)."""
    if out is None:
        with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
            return run(Path(tmp), False)
    out.mkdir(parents=True, exist_ok=True)
    return run(out, True)
