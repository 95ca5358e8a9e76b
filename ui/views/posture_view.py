"""The 3D posture of the current frame (Fig. 4, part 3).

With OpenGL it is a rotatable :mod:`pyqtgraph.opengl` scene; where OpenGL cannot be had
(remote sessions, the ``offscreen`` platform, ``VIDEOTRACK_NO_OPENGL=1``) or draws only in
software (:data:`SOFTWARE_RENDERERS`, unless ``VIDEOTRACK_OPENGL=1``) it falls back to three
orthographic 2D projections: side (x–y), top (x–z) and front (z–y).
World axes as in the shipped chains: x anterior, y dorsal (up), z to the right.
"""

from __future__ import annotations

import os

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import QGridLayout, QLabel, QWidget

from ui.views import style

#: The fallback's projections: title, world axis index horizontal, vertical, invert vertical.
PROJECTIONS = (("side (x, y)", 0, 1, False), ("top (x, z)", 0, 2, True),
               ("front (z, y)", 2, 1, False))


#: Renderers that draw OpenGL on the CPU (Mesa's llvmpipe, softpipe and swrast, Google's
#: SwiftShader, Windows' GDI Generic and Basic Render Driver). Once a window holds an OpenGL
#: view, Qt composes every repaint of the whole window through OpenGL; drawn on the CPU that
#: made a frame step 42 ms instead of 18 ms and playback 24 frames/s instead of 45 (docs/gui.md).
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "software rasterizer", "swiftshader",
                      "gdi generic", "basic render")


def opengl_renderer() -> str | None:
    """The OpenGL renderer's name (``GL_RENDERER``), or None where no context can be made."""
    from PySide6.QtGui import QOffscreenSurface, QOpenGLContext

    context = QOpenGLContext()
    if not context.create():
        return None
    surface = QOffscreenSurface()
    surface.setFormat(context.format())
    surface.create()
    try:
        if not context.makeCurrent(surface):
            return None
        return str(context.functions().glGetString(0x1F01) or "")  # GL_RENDERER
    finally:
        context.doneCurrent()
        surface.destroy()


def opengl_choice() -> tuple[bool, str]:
    """Whether the 3D view draws with OpenGL, and if not, why (for the fallback's note).

    ``VIDEOTRACK_NO_OPENGL=1`` turns it off, ``VIDEOTRACK_OPENGL=1`` keeps it on a renderer
    that draws in software.
    """
    from PySide6.QtGui import QGuiApplication

    if os.environ.get("VIDEOTRACK_NO_OPENGL"):
        return False, "turned off by VIDEOTRACK_NO_OPENGL"
    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        return False, "no display"
    try:
        import pyqtgraph.opengl  # noqa: F401  (needs PyOpenGL)
    except Exception:
        return False, "PyOpenGL cannot be loaded"
    renderer = opengl_renderer()
    if renderer is None:
        return False, "OpenGL is not available here"
    if not os.environ.get("VIDEOTRACK_OPENGL") and any(
            name in renderer.lower() for name in SOFTWARE_RENDERERS):
        return False, (f"OpenGL draws in software here ({renderer.split(' (')[0]}), which "
                       "would slow every frame step; VIDEOTRACK_OPENGL=1 uses it anyway")
    return True, ""


def opengl_available() -> bool:
    """Whether the 3D view will draw with OpenGL (:func:`opengl_choice`)."""
    return opengl_choice()[0]


class PostureView(QWidget):
    """Draws a :class:`ui.adapters.PostureGeometry`; ``use_opengl`` None decides itself."""

    def __init__(self, parent=None, use_opengl: bool | None = None) -> None:
        super().__init__(parent)
        self.opengl, why_not = (opengl_choice() if use_opengl is None else
                                (use_opengl, "turned off"))
        layout = QGridLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        if self.opengl:
            self._build_gl(layout)
        else:
            self._build_2d(layout, why_not)

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
    def _build_2d(self, layout, why_not: str) -> None:
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
        note = QLabel(f"3D posture as three projections (world x anterior, y up, z right): "
                      f"{why_not}.")
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
