"""Markers of several colours: which marker has which colour, how a colour is drawn and the
HSV range that finds it again.

A project films markers of several colours (each leg its own, left and right apart, …) as
one view per camera and colour: the views share the camera and its ROI, each keeps only its
colour (``[[views]] hsv_lower``/``hsv_upper`` in place of the filter chain's ``hsv_range``
step) and is matched to the chain's markers of that colour only (``model_markers``; the fit:
``Fitter(view_markers=...)``). ``videotrack synth --colour red=L* --colour green=R*`` draws
such a video and writes these views.
"""

from __future__ import annotations

from collections.abc import Sequence
from fnmatch import fnmatchcase

import numpy as np

from videotrack.errors import VideoTrackError

#: colour name -> (B, G, R) at full intensity (0..1) and its OpenCV hue (0..179)
PALETTE = {
    "red": ((0.0, 0.0, 1.0), 0),
    "yellow": ((0.0, 1.0, 1.0), 30),
    "green": ((0.0, 1.0, 0.0), 60),
    "cyan": ((1.0, 1.0, 0.0), 90),
    "blue": ((1.0, 0.0, 0.0), 120),
    "magenta": ((1.0, 0.0, 1.0), 150),
}
#: hue half-width of a colour's range (OpenCV hue units: 2 degrees each); the palette's hues
#: lie 30 apart
HUE_TOLERANCE = 12
#: lowest saturation a colour's range keeps (a grey background or ghost has none)
MIN_SATURATION = 80


def parse_colour(text: str) -> tuple[str, tuple[str, ...]]:
    """``"red=LF_*,LM_*"`` -> ("red", ("LF_*", "LM_*")) (a ``--colour`` argument)."""
    name, sep, patterns = text.partition("=")
    name = name.strip().lower()
    if not sep or not patterns.strip():
        raise VideoTrackError(f"give COLOUR=MARKERS, e.g. red=LF_*,LM_*; got {text!r}",
                              field="--colour")
    if name not in PALETTE:
        raise VideoTrackError(f"unknown colour {name!r} (colours: {', '.join(PALETTE)})",
                              field="--colour")
    return name, tuple(p.strip() for p in patterns.split(",") if p.strip())


def check_colours(colours: Sequence[tuple[str, Sequence[str]]]) -> None:
    """Known colour names, each used once."""
    seen = set()
    for name, _ in colours:
        if name not in PALETTE:
            raise VideoTrackError(f"unknown colour {name!r} (colours: {', '.join(PALETTE)})",
                                  field="colours")
        if name in seen:
            raise VideoTrackError(f"colour {name!r} is given twice: list all its markers in "
                                  f"one entry", field="colours")
        seen.add(name)


def markers_matching(patterns: Sequence[str], marker_names: Sequence[str], file=None,
                     where: str = "model_markers") -> list[str]:
    """The markers (in ``marker_names``' order) that names or shell patterns (``LF_*``)
    pick; a pattern that picks none is an error naming it (field ``where[j]``)."""
    picked = set()
    for j, pattern in enumerate(patterns):
        hits = {m for m in marker_names if fnmatchcase(m, pattern)}
        if not hits:
            raise VideoTrackError(f"{pattern!r} names no marker (markers: "
                                  f"{', '.join(marker_names)})", file=file,
                                  field=f"{where}[{j}]")
        picked |= hits
    return [m for m in marker_names if m in picked]


def colour_of_markers(colours: Sequence[tuple[str, Sequence[str]]],
                      names: Sequence[str]) -> np.ndarray:
    """(n_markers,) index into ``colours`` of each marker; every marker needs exactly one
    colour, and every pattern must name a marker."""
    check_colours(colours)
    out = np.full(len(names), -1, np.int64)
    index = {m: k for k, m in enumerate(names)}
    for c, (colour, patterns) in enumerate(colours):
        picked = markers_matching(patterns, names, where=f"colours.{colour}")
        for k in (index[m] for m in picked):
            if out[k] not in (-1, c):
                raise VideoTrackError(f"marker {names[k]!r} is both {colours[out[k]][0]} "
                                      f"and {colour}", field="colours")
            out[k] = c
    left = [names[k] for k in np.flatnonzero(out < 0)]
    if left:
        raise VideoTrackError(f"marker {left[0]!r} has no colour: give every marker one",
                              field="colours")
    return out


def bgr(colour: str, intensity: float) -> np.ndarray:
    """The (B, G, R) a marker of ``colour`` adds to the background at full coverage."""
    return intensity * np.asarray(PALETTE[colour][0])


def hsv_range(colour: str, min_value: int) -> tuple[list[int], list[int]]:
    """``hsv_lower``, ``hsv_upper`` that keep ``colour`` (brighter than ``min_value``); a
    range across hue 0 wraps, as the ``hsv_range`` filter step reads it."""
    hue = PALETTE[colour][1]
    lower = (hue - HUE_TOLERANCE) % 180
    upper = (hue + HUE_TOLERANCE) % 180
    return [lower, MIN_SATURATION, int(min_value)], [upper, 255, 255]
