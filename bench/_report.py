"""What every benchmark prints: the machine it ran on and a markdown table of figures."""

from __future__ import annotations

import os
import platform
import subprocess


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
