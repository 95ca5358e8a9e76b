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


def print_markdown(header, rows) -> None:
    """Print ``rows`` (tuples, one value per column of ``header``) as a markdown table."""
    print("| " + " | ".join(header) + " |")
    print("|" + " --- |" * len(header))
    for r in rows:
        print("| " + " | ".join(str(v) for v in r) + " |")


#: ``videotrack synth`` clutter of the status benches: 2 static and 1 flickering ghost per
#: view, 2 % occluded marker images.
CLUTTER = ("--ghosts", "2", "--flicker-ghosts", "1", "--occlusions", "0.02")


def synth_locust(folder: Path, frames: int, seed: int, clutter: bool) -> None:
    """``videotrack synth``'s locust project in ``folder`` (movement and render seeded by
    ``seed``), with :data:`CLUTTER` if ``clutter``."""
    subprocess.run(["videotrack", "synth", str(folder), "--frames", str(frames),
                    "--motion-seed", str(seed), "--seed", str(seed),
                    *(CLUTTER if clutter else ())], check=True, capture_output=True)


def in_out_folder(out: Path | None, prefix: str, run: Callable[[Path, bool], int]) -> int:
    """``run(folder, keep)`` in ``out`` (created) or, without one, in a temporary folder that
    is removed afterwards (``keep`` False)."""
    if out is None:
        with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
            return run(Path(tmp), False)
    out.mkdir(parents=True, exist_ok=True)
    return run(out, True)
