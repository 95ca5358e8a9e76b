"""The 3D posture of the current frame (Fig. 4, part 3).

With OpenGL it is a rotatable :mod:`pyqtgraph.opengl` scene; where OpenGL cannot be had
(remote sessions, the ``offscreen`` platform, ``VIDEOTRACK_NO_OPENGL=1``) it falls back to
three orthographic 2D projections: side (x–y), top (x–z) and front (z–y).
World axes as in the shipped chains: x anterior, y dorsal (up), z to the right.
"""

from __future__ import annotations

import os

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import QGridLayout, QLabel, QWidget

from ui import style

#: The fallback's projections: title, world axis index horizontal, vertical, invert vertical.
PROJECTIONS = (("side (x, y)", 0, 1, False), ("top (x, z)", 0, 2, True),
               ("front (z, y)", 2, 1, False))


def opengl_available() -> bool:
    """Whether an OpenGL context can be created (and the user has not turned it off)."""
    from PySide6.QtGui import QGuiApplication, QOpenGLContext

    if os.environ.get("VIDEOTRACK_NO_OPENGL") or QGuiApplication.platformName() in (
            "offscreen", "minimal"):
        return False
    try:
        import pyqtgraph.opengl  # noqa: F401  (needs PyOpenGL)
    except Exception:
        return False
    context = QOpenGLContext()
    return bool(context.create())


class PostureView(QWidget):
    """Draws a :class:`ui.adapters.PostureGeometry`; ``use_opengl`` None decides itself."""

    def __init__(self, parent=None, use_opengl: bool | None = None) -> None:
        super().__init__(parent)
        self.opengl = opengl_available() if use_opengl is None else use_opengl
        layout = QGridLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        if self.opengl:
            self._build_gl(layout)
        else:
            self._build_2d(layout)

    # -- OpenGL -------------------------------------------------------------------------
    def _build_gl(self, layout) -> None:
        import pyqtgraph.opengl as gl

        self.gl_view = gl.GLViewWidget()
        self.gl_view.setBackgroundColor("#202020")
        self.gl_view.setCameraPosition(distance=400, elevation=25, azimuth=-60)
        grid = gl.GLGridItem()
        grid.setSize(400, 400)
        grid.setSpacing(20, 20)
        self.gl_view.addItem(grid)
        self.gl_lines = gl.GLLinePlotItem(mode="lines", width=3,
                                          color=pg.mkColor(style.SKELETON).getRgbF())
        self.gl_markers = gl.GLScatterPlotItem(size=12, color=pg.mkColor(style.MARKER).getRgbF())
        self.gl_view.addItem(self.gl_lines)
        self.gl_view.addItem(self.gl_markers)
        layout.addWidget(self.gl_view, 0, 0)

    # -- fallback -----------------------------------------------------------------------
    def _build_2d(self, layout) -> None:
        self.plots = []
        self.items = []
        cells = ((0, 0), (0, 1), (1, 0))
        for (row, col), (title, _, _, invert) in zip(cells, PROJECTIONS, strict=True):
            w = pg.PlotWidget()
            w.setTitle(title, size="10pt")
            w.setAspectLocked(True)
            w.showGrid(True, True, alpha=0.25)
            w.invertY(invert)
            style.cache_axes(w.getPlotItem())
            lines = pg.PlotCurveItem(pen=style.skeleton_pen(), connect="pairs")
            markers = pg.ScatterPlotItem(**style.marker_style())
            w.addItem(lines)
            w.addItem(markers)
            self.plots.append(w)
            self.items.append((lines, markers))
            layout.addWidget(w, row, col)
        note = QLabel("3D posture: OpenGL is not available here, so it is shown as three "
                      "projections (world x anterior, y up, z right).")
        note.setWordWrap(True)
        note.setStyleSheet("color: grey")
        layout.addWidget(note, 1, 1)

    def set_extent(self, centre, reach: float) -> None:
        """Show the cube ``centre ± reach`` (world units), so the body never leaves it."""
        c = np.asarray(centre, dtype=float)
        if self.opengl:
            self.gl_view.setCameraPosition(distance=3.0 * reach)
            self.gl_view.opts["center"] = pg.Vector(c[0], -c[2], c[1])
            return
        for (_, h, v, _), plot in zip(PROJECTIONS, self.plots, strict=True):
            plot.setRange(xRange=(c[h] - reach, c[h] + reach),
                          yRange=(c[v] - reach, c[v] + reach), padding=0.05)

    # -- content ------------------------------------------------------------------------
    def set_geometry(self, geometry) -> None:
        """Draw a posture (None clears)."""
        if geometry is None:
            lines = markers = np.empty((0, 3))
        else:
            lines, markers = geometry.lines(), geometry.markers
        if self.opengl:
            # GL's z is up: world (x, y, z) -> GL (x, -z, y)
            def to_gl(p):
                return np.column_stack([p[:, 0], -p[:, 2], p[:, 1]]) if len(p) else p

            self.gl_lines.setData(pos=to_gl(lines))
            self.gl_markers.setData(pos=to_gl(markers))
            return
        for (_, h, v, _), (line_item, marker_item) in zip(PROJECTIONS, self.items,
                                                          strict=True):
            line_item.setData(lines[:, h], lines[:, v])
            marker_item.setData(markers[:, h], markers[:, v])

    def projections(self) -> list[np.ndarray]:
        """Fallback only: the (x, y) data of the marker items of each projection."""
        return [np.column_stack(m.getData()) for _, m in self.items]

    def gl_markers_world(self) -> np.ndarray:
        """OpenGL only: the markers the 3D scene holds, back in world coordinates."""
        p = np.asarray(self.gl_markers.pos, dtype=float).reshape(-1, 3)
        return np.column_stack([p[:, 0], p[:, 2], -p[:, 1]])
