"""Colours, pens and sizes shared by every view, so an overlay looks the same everywhere.

Chosen to stand out on dark marker videos and on bright ones: detections are hollow green
rings, model markers filled orange dots with a dark rim, the skeleton cyan; an ambiguous
frame's alternative posture dashed violet with hollow markers.
"""

from __future__ import annotations

import pyqtgraph as pg
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import QGraphicsItem

DETECTION = "#39ff14"
MARKER = "#ff7f0e"
MARKER_RIM = "#1a1a1a"
SKELETON = "#00d5ff"
RESIDUAL = "#ff3030"  # marker → the point it is measured to
PINNED = "#ff3df2"
CURRENT_FRAME = "#ffd400"
ERROR_CURVE = "#e8e8e8"
THRESHOLD = "#ff5050"
ALTERNATIVE = "#d39bff"  # an ambiguous frame's other posture, the one A swaps to
STALE_TEXT = "#d97400"  # the warning that errors are of an earlier chain
BAD_ROW = QColor("#ffd2d2")
CORRECTED_ROW = QColor("#d5e6ff")
UNFITTED_TEXT = QColor("#8a8a8a")
TEXT_ON_SHADE = QColor("#111111")

#: Screen sizes in pixels (independent of zoom).
DETECTION_SIZE = 18
MARKER_SIZE = 11
LINE_WIDTH = 2.5

#: Colours of curves (one per axis) and of view rectangles.
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#bcbd22", "#17becf", "#7f7f7f")


def configure() -> None:
    """Global pyqtgraph options: images indexed [row, column] like NumPy and OpenCV."""
    pg.setConfigOptions(imageAxisOrder="row-major", antialias=True)


def colour(i: int) -> str:
    return PALETTE[i % len(PALETTE)]


def detection_style() -> dict:
    return {"symbol": "o", "size": DETECTION_SIZE, "pen": pg.mkPen(DETECTION, width=2.2),
            "brush": None, "pxMode": True}


def marker_style() -> dict:
    return {"symbol": "o", "size": MARKER_SIZE, "pen": pg.mkPen(MARKER_RIM, width=1.2),
            "brush": pg.mkBrush(MARKER), "pxMode": True}


#: A model marker marked hidden in a view: a cross, not a disc (it is not matched there).
HIDDEN_SYMBOL = "x"


def selected_marker_style() -> dict:
    """A ring around the model marker the marker nudge keys move."""
    return {"symbol": "o", "size": MARKER_SIZE + 10, "pen": pg.mkPen("#ffffff", width=1.5),
            "brush": None, "pxMode": True}


def keypoint_style() -> dict:
    return {"symbol": "o", "size": DETECTION_SIZE, "brush": None, "pxMode": True}


#: Opacity of a keypoint scored 0 (one scored 1 is opaque): faint, but still there.
KEYPOINT_MIN_ALPHA = 0.25


def keypoint_pen(marker: int, score: float):
    """The ring of marker ``marker``'s keypoint: its colour, opacity by score."""
    c = QColor(colour(marker))
    s = float(score) if score == score else 1.0  # NaN (no score given): certain
    c.setAlphaF(KEYPOINT_MIN_ALPHA + (1 - KEYPOINT_MIN_ALPHA) * min(max(s, 0.0), 1.0))
    return pg.mkPen(c, width=2.2)


def marker_brush(marker: int):
    """A model marker filled with its keypoints' colour."""
    return pg.mkBrush(colour(marker))


def residual_pen():
    """The line from a model marker to the point it is measured to (its residual)."""
    return pg.mkPen(RESIDUAL, width=1.2)


def skeleton_pen():
    return pg.mkPen(SKELETON, width=LINE_WIDTH)


def alternative_pen():
    """The skeleton of the posture A would swap to: dashed, thinner than the fitted one."""
    return pg.mkPen(ALTERNATIVE, width=1.5, style=Qt.PenStyle.DashLine)


def alternative_marker_style() -> dict:
    """Its markers: hollow rings, so the fitted markers and the detections stay readable."""
    return {"symbol": "o", "size": MARKER_SIZE, "pen": pg.mkPen(ALTERNATIVE, width=1.5),
            "brush": None, "pxMode": True}


def cache_drawing(*items) -> None:
    """Keep what these items draw as a pixmap until they change: a frame step then repaints
    axes (tick labels, grids) and long curves from the cache instead of drawing them again
    (most of a frame step's time without it)."""
    for item in items:
        item.setCacheMode(QGraphicsItem.CacheMode.DeviceCoordinateCache)


def cache_axes(plot) -> None:
    """:func:`cache_drawing` for a plot's visible axes."""
    cache_drawing(*(plot.getAxis(side) for side in ("left", "bottom")))
