"""How many CPU cores this process may use (its CPU affinity, not the machine's count: a
container or ``taskset`` may allow fewer than ``os.cpu_count()`` reports)."""

from __future__ import annotations

import os


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
