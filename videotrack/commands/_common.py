"""Shared by the commands that run :func:`videotrack.workflow.run.run_project`: its progress as
bars and its notes and warnings as lines on stderr (the library never prints)."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator

#: Exit status of fit, run and batch when a run is incomplete (its video could not be read to
#: the end, or not one frame was fitted) and --allow-incomplete was not given; 1 is an error.
EXIT_INCOMPLETE = 3

#: The bar of each step of a run.
BAR_NAMES = {"detect": "detecting", "fit": "fitting"}


@contextlib.contextmanager
def step_bars() -> Iterator:
    """A ``progress`` callback for :func:`~videotrack.workflow.run.run_project`: one bar per
    step on stderr (the fitting bar shows the share of bad frames), closed with the block."""
    from tqdm import tqdm

    bars: dict = {}

    def progress(p) -> None:
        bar = bars.get(p.step)
        if bar is None:
            for done in bars.values():
                done.close()
            bar = bars[p.step] = tqdm(total=p.total, desc=BAR_NAMES.get(p.step, p.step),
                                      unit="frame", file=sys.stderr, leave=False,
                                      disable=None)
        bar.total = p.total
        bar.update(p.done - bar.n)
        if p.step == "fit" and p.done:
            bar.set_postfix_str(f"bad {100 * p.bad / p.done:.1f}%", refresh=False)

    try:
        yield progress
    finally:
        for bar in bars.values():
            bar.close()


def note(line: str) -> None:
    """A note of a run (``log`` of run_project) as a line on stderr, above any bar."""
    from tqdm import tqdm

    tqdm.write(f"videotrack: {line}", file=sys.stderr)


def print_warnings(run) -> None:
    """The warnings a run collected, one line each on stderr (as the CLI prints warnings)."""
    for message in run.warnings:
        note(f"warning: {message}")


def incomplete_status(run, allowed: bool) -> int:
    """Exit status of a finished run: :data:`EXIT_INCOMPLETE` (said on stderr) when the run
    is incomplete and that is not ``allowed``, else 0."""
    if not run.incomplete:
        return 0
    note(f"incomplete: {run.incomplete}" + ("" if allowed else
                                             " (exit status 3; --allow-incomplete accepts it)"))
    return 0 if allowed else EXIT_INCOMPLETE
