"""One video view: the view image with detected centroids (or a keypoint project's labelled
keypoints) and the projected model.

Coordinates are the view image's pixels, as the cameras project and the detections are
stored: the image is placed so that pixel ``(i, j)`` is centred on ``(x, y) = (j, i)`` and
the y axis points down. Model markers can be dragged with the left mouse button; dragging
anywhere else pans the view.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal

from ui.views import style


def display_image(image: np.ndarray) -> np.ndarray:
    """A view image as pyqtgraph shows it: grey as it is, OpenCV's BGR turned to RGB."""
    return image[..., ::-1] if image.ndim == 3 else image


class DraggableScatter(pg.ScatterPlotItem):
    """Scatter whose points can be dragged; emits ``dragged(index, x, y)`` on release and
    ``moving(index, x, y)`` while the mouse moves."""

    dragged = Signal(int, float, float)
    moving = Signal(int, float, float)

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._drag: int | None = None
        self.draggable = True

    def mouseDragEvent(self, ev) -> None:
        if ev.button() != Qt.MouseButton.LeftButton or not self.draggable:
            ev.ignore()
            return
        if ev.isStart():
            hits = self.pointsAt(ev.buttonDownPos())
            if len(hits) == 0:
                ev.ignore()
                return
            self._drag = int(hits[0].index())
        if self._drag is None:
            ev.ignore()
            return
        ev.accept()
        pos = ev.pos()
        if ev.isFinish():
            index, self._drag = self._drag, None
            self.dragged.emit(index, pos.x(), pos.y())
        else:
            self.moving.emit(self._drag, pos.x(), pos.y())


#: A click picks a detection within this many screen pixels.
PICK_PX = 10.0


class VideoView(pg.GraphicsLayoutWidget):
    """The image of one view with its overlays.

    Signals
    -------
    markerDragged(view, marker, x, y)
        A model marker was dropped at (x, y) in view pixels.
    markerSelected(view, marker)
        A model marker was clicked (or dragged): the one the marker nudge keys move.
    detectionRemoved(view, x, y)
        Shift+click on the detection at (x, y): remove it (a ghost).
    detectionAdded(view, x, y)
        Ctrl+click at (x, y): add a detection there (the window snaps it to the marker).
    detectionMoved(view, x0, y0, x1, y1)
        The detection at (x0, y0) was dragged to (x1, y1).
    """

    markerDragged = Signal(int, int, float, float)
    markerSelected = Signal(int, int)
    detectionRemoved = Signal(int, float, float)
    detectionAdded = Signal(int, float, float)
    detectionMoved = Signal(int, float, float, float, float)

    def __init__(self, index: int, name: str, parent=None) -> None:
        super().__init__(parent)
        self.index = index
        self.name = name
        self.setMinimumSize(200, 160)
        self.plot = self.addPlot()
        self.plot.setTitle(name, size="11pt")
        self.plot.invertY(True)
        self.plot.setAspectLocked(True)
        self.plot.showGrid(False, False)
        for side in ("left", "bottom"):
            self.plot.getAxis(side).setStyle(tickFont=_small_font())
        style.cache_axes(self.plot)
        self.image = pg.ImageItem()
        self.plot.addItem(self.image)
        self.detected = DraggableScatter(**style.detection_style())
        self.detected.dragged.connect(self._detection_dropped)
        self.detected.moving.connect(self._detection_moving)
        self._detected_xy = np.empty((0, 2))
        self.lines = pg.PlotCurveItem(pen=style.skeleton_pen(), connect="pairs")
        self.residual_lines = pg.PlotCurveItem(pen=style.residual_pen(), connect="pairs")
        # an ambiguous frame's other posture (what A would swap to), under the fitted one
        self.alternative_lines = pg.PlotCurveItem(pen=style.alternative_pen(), connect="pairs")
        self.alternative_markers = pg.ScatterPlotItem(**style.alternative_marker_style())
        self.markers = DraggableScatter(**style.marker_style())
        self.markers.setZValue(10)
        self.markers.dragged.connect(self._dropped)
        self.markers.moving.connect(self._moving)
        self.markers.sigClicked.connect(
            lambda _item, points, _ev: self.markerSelected.emit(self.index,
                                                                int(points[0].index())))
        self.selection = pg.ScatterPlotItem(**style.selected_marker_style())
        self.selection.setZValue(11)
        self.selected: int | None = None  # model marker ringed (nudge keys), or None
        # labelled keypoints: one colour per marker (the model marker's), faded by score
        self.keypoints = pg.ScatterPlotItem(**style.keypoint_style())
        self._keypoints = np.empty((0, 3))
        for item in (self.detected, self.keypoints, self.alternative_lines,
                     self.alternative_markers, self.lines, self.residual_lines, self.markers,
                     self.selection):
            self.plot.addItem(item)
        self.labels: list[pg.TextItem] = []
        self.info = pg.TextItem(anchor=(0, 0), color="#ffffff", fill=pg.mkBrush(0, 0, 0, 140))
        self.info.setZValue(20)
        self.plot.addItem(self.info)
        self._marker_xy = np.empty((0, 2))
        self._marker_colours: list | None = None
        self._hidden = np.zeros(0, bool)  # model markers marked hidden in this view
        self._size: tuple[int, int] | None = None
        #: (x0, x1, y0, y1) shown first instead of the whole image (a keypoint project's
        #: keypoints: a small animal in a large frame), or None.
        self.home: tuple[float, float, float, float] | None = None
        self._shown: np.ndarray | None = None
        self.scene().sigMouseClicked.connect(self._clicked)

    # -- content ------------------------------------------------------------------------
    def set_image(self, image: np.ndarray | None) -> None:
        if image is self._shown and image is not None:
            return  # the same picture (a blank canvas): no redraw on a frame step
        self._shown = image
        if image is None:
            self.image.clear()
            return
        self.image.setImage(display_image(image), autoLevels=False, levels=(0, 255))
        h, w = image.shape[:2]
        self.image.setRect(-0.5, -0.5, w, h)  # pixel centres on integer coordinates
        if self._size != (w, h):
            self._size = (w, h)
            x0, x1, y0, y1 = self.home or (-0.5, w - 0.5, -0.5, h - 0.5)
            self.plot.setRange(xRange=(x0, x1), yRange=(y0, y1), padding=0.01)
            self.info.setPos(max(x0, -0.5), max(y0, -0.5))  # in sight at the start

    def set_detections(self, points: np.ndarray) -> None:
        self._detected_xy = np.asarray(points, float).reshape(-1, 2)
        self.detected.setData(pos=self._detected_xy, data=np.arange(len(self._detected_xy)))

    def set_keypoints(self, keypoints: np.ndarray | None) -> None:
        """Draw labelled keypoints, (n_markers, 3) x, y, score in the model's marker order
        (NaN rows are missing and not drawn); None clears. Marker k gets the colour of
        :func:`ui.views.style.colour` (k), its opacity the score."""
        kp = np.empty((0, 3)) if keypoints is None else np.asarray(keypoints, float)
        self._keypoints = kp
        shown = np.flatnonzero(np.isfinite(kp[:, :2]).all(axis=1)) if len(kp) else []
        pens = [style.keypoint_pen(k, kp[k, 2]) for k in shown]
        self.keypoints.setData(pos=kp[shown, :2] if len(shown) else np.empty((0, 2)),
                               pen=pens, data=np.asarray(shown, int))

    def set_hidden(self, hidden) -> None:
        """Which model markers are marked hidden in this view ((n_markers,) of bool): they
        are drawn as crosses. Takes effect with the next overlay."""
        self._hidden = np.asarray(hidden, bool).ravel()

    def set_marker_colours(self, on: bool) -> None:
        """Fill each model marker with its keypoints' colour (keypoint projects)."""
        self._marker_colours = on or None

    @property
    def editable(self) -> bool:
        """Whether markers and detections may be dragged and detections edited."""
        return self.markers.draggable

    @editable.setter
    def editable(self, on: bool) -> None:
        self.markers.draggable = self.detected.draggable = bool(on)

    def set_overlay(self, overlay, names=()) -> None:
        """Draw a :class:`ui.adapters.ViewOverlay` (None clears), with marker names."""
        if overlay is None:
            self._marker_xy = np.empty((0, 2))
            self._set_markers(self._marker_xy)
            self.lines.setData([], [])
            self._set_labels([], [])
            return
        self._marker_xy = np.asarray(overlay.markers, float)
        self._set_markers(self._marker_xy)
        lines = np.asarray(overlay.lines, float).reshape(-1, 2)
        self.lines.setData(lines[:, 0], lines[:, 1])
        self._set_labels(names, self._marker_xy)

    def set_alternative(self, overlay) -> None:
        """Draw the alternative posture's :class:`ui.adapters.ViewOverlay` (None clears)."""
        if overlay is None:
            self.alternative_lines.setData([], [])
            self.alternative_markers.setData(pos=np.empty((0, 2)))
            return
        lines = np.asarray(overlay.lines, float).reshape(-1, 2)
        self.alternative_lines.setData(lines[:, 0], lines[:, 1])
        self.alternative_markers.setData(pos=np.asarray(overlay.markers, float))

    def set_residuals(self, matched) -> None:
        """Draw each model marker's residual: a line from the marker to the point it is
        measured to, ``matched`` (n_markers, 2) in the overlay's marker order (NaN rows: none,
        e.g. hidden); None clears."""
        xy = self._marker_xy
        m = np.empty((0, 2)) if matched is None else np.asarray(matched, float)[:len(xy)]
        ok = np.isfinite(m).all(axis=1) & np.isfinite(xy[:len(m)]).all(axis=1)
        pairs = np.stack([xy[:len(m)][ok], m[ok]], axis=1).reshape(-1, 2)
        self.residual_lines.setData(pairs[:, 0], pairs[:, 1])

    def set_info(self, text: str) -> None:
        self.info.setText(text)

    def _set_labels(self, names, xy) -> None:
        while len(self.labels) < len(names):
            label = pg.TextItem(color=style.MARKER, anchor=(-0.25, 1.1))
            label.setFont(_small_font())
            self.plot.addItem(label)
            self.labels.append(label)
        for k, label in enumerate(self.labels):
            visible = k < len(names) and np.all(np.isfinite(xy[k]))
            label.setVisible(bool(visible))
            if visible:
                label.setText(names[k])
                label.setPos(*xy[k])

    # -- dragging -----------------------------------------------------------------------
    def _set_markers(self, xy: np.ndarray) -> None:
        brush = ([style.marker_brush(k) for k in range(len(xy))] if self._marker_colours
                 else None)
        extra = {"brush": brush} if brush is not None else {}
        if self._hidden[:len(xy)].any():
            extra["symbol"] = [style.HIDDEN_SYMBOL if k < len(self._hidden) and self._hidden[k]
                               else "o" for k in range(len(xy))]
        self.markers.setData(pos=xy, data=np.arange(len(xy)), **extra)
        k = self.selected
        shown = k is not None and k < len(xy) and bool(np.all(np.isfinite(xy[k])))
        self.selection.setData(pos=xy[k:k + 1] if shown else np.empty((0, 2)))

    def select_marker(self, index: int | None) -> None:
        """Ring model marker ``index`` (None: none)."""
        self.selected = index
        self._set_markers(self._marker_xy)

    def marker_xy(self, index: int) -> tuple[float, float]:
        """Where model marker ``index`` is drawn (view pixels)."""
        return float(self._marker_xy[index, 0]), float(self._marker_xy[index, 1])

    def show_marker_at(self, index: int, x: float, y: float) -> None:
        """Draw one model marker moved to (x, y) until the overlay is drawn again."""
        self._moving(index, x, y)

    def _moving(self, index: int, x: float, y: float) -> None:
        if self.selected != index:
            self.markerSelected.emit(self.index, index)
        xy = self._marker_xy.copy()
        xy[index] = (x, y)
        self._set_markers(xy)

    def _dropped(self, index: int, x: float, y: float) -> None:
        self._set_markers(self._marker_xy)
        self.markerDragged.emit(self.index, index, x, y)

    # -- editing detections -------------------------------------------------------------
    def scene_pos(self, x: float, y: float):
        """Scene position of view pixel (x, y) (for mouse events)."""
        from PySide6.QtCore import QPointF

        return self.plot.vb.mapViewToScene(QPointF(x, y))

    def pick_detection(self, scene_pos) -> int | None:
        """The detection within :data:`PICK_PX` screen pixels of a scene position."""
        best, best_d = None, PICK_PX
        for k, (x, y) in enumerate(self._detected_xy):
            p = self.scene_pos(x, y)
            d = float(np.hypot(p.x() - scene_pos.x(), p.y() - scene_pos.y()))
            if d <= best_d:
                best, best_d = k, d
        return best

    def _clicked(self, ev) -> None:
        mods = ev.modifiers()
        if (ev.button() != Qt.MouseButton.LeftButton or not self.editable
                or not self.plot.vb.sceneBoundingRect().contains(ev.scenePos())):
            return
        if mods & Qt.KeyboardModifier.ShiftModifier:
            k = self.pick_detection(ev.scenePos())
            if k is not None:
                ev.accept()
                self.detectionRemoved.emit(self.index, *map(float, self._detected_xy[k]))
        elif mods & Qt.KeyboardModifier.ControlModifier:
            ev.accept()
            p = self.plot.vb.mapSceneToView(ev.scenePos())
            self.detectionAdded.emit(self.index, p.x(), p.y())

    def _detection_moving(self, index: int, x: float, y: float) -> None:
        xy = self._detected_xy.copy()
        xy[index] = (x, y)
        self.detected.setData(pos=xy, data=np.arange(len(xy)))

    def _detection_dropped(self, index: int, x: float, y: float) -> None:
        x0, y0 = map(float, self._detected_xy[index])
        self.detected.setData(pos=self._detected_xy, data=np.arange(len(self._detected_xy)))
        self.detectionMoved.emit(self.index, x0, y0, x, y)

    # -- for tests and screenshots ------------------------------------------------------
    def drawn(self) -> dict[str, np.ndarray]:
        """The data the items hold: ``markers``, ``hidden`` (which markers are drawn as
        hidden), ``lines`` and ``residuals`` (pairs: marker, the point it is measured to),
        ``detections``, ``keypoints`` (x, y, marker index) and ``alternative`` (the markers
        of the alternative posture, empty when none is drawn)."""
        mx, my = self.markers.getData()
        lx, ly = self.lines.getData()
        rx, ry = self.residual_lines.getData()
        dx, dy = self.detected.getData()
        kx, ky = self.keypoints.getData()
        ax, ay = self.alternative_markers.getData()
        return {"markers": np.column_stack([mx, my]),
                "hidden": np.asarray([p.symbol() == style.HIDDEN_SYMBOL
                                      for p in self.markers.points()], bool),
                "lines": np.column_stack([lx, ly]) if lx is not None else np.empty((0, 2)),
                "residuals": (np.column_stack([rx, ry]) if rx is not None
                              else np.empty((0, 2))),
                "detections": np.column_stack([dx, dy]),
                "keypoints": np.column_stack([kx, ky, np.asarray(
                    self.keypoints.data["data"], float)]),
                "alternative": np.column_stack([ax, ay])}


def _small_font():
    from PySide6.QtGui import QFont

    font = QFont()
    font.setPointSize(8)
    return font
