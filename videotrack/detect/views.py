"""Views: the rectangles of a video frame that each show the scene through one camera.

Coordinate convention (shared with the camera model). A view's *image* is its region of
interest (ROI) cut from the frame, mirrored left-right if ``flip_x`` and top-bottom if
``flip_y``, so that a view seen in a mirror looks like an ordinary camera image. Detections are
reported in this view image's pixel coordinates: origin at the centre of the view image's
top-left pixel, x to the right, y down, always at full-frame resolution (de-interlaced
half-frames are mapped back, see :mod:`videotrack.detect.deinterlace`). The camera of a view is
calibrated in exactly these coordinates: it projects world points to (u, v) = view (x, y).

Mapping to the video frame (for drawing), with ROI ``(x0, y0, w, h)``::

    x_frame = x0 + (w - 1 - x_view if flip_x else x_view)
    y_frame = y0 + (h - 1 - y_view if flip_y else y_view)

The flip maps pixel centres onto pixel centres, so it is exact and its own inverse.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from videotrack.detect.deinterlace import Deinterlace
from videotrack.errors import VideoTrackError, VideoTrackWarning


@dataclass(frozen=True)
class View:
    """One view of a video frame.

    Parameters
    ----------
    name : str
        Unique name.
    roi : tuple of int (x, y, width, height), optional
        Rectangle of the frame, in frame pixels (x, y of its top-left pixel); None for the whole
        frame (resolved by :meth:`resolved`).
    flip_x, flip_y : bool
        Mirror the view image left-right / top-bottom.
    camera : str, optional
        Camera name in the camera file; defaults to ``name``.
    video : int
        Index of the video (in a :class:`~videotrack.detect.video.VideoSet`) the view is cut from.
    hsv : ((h, s, v), (h, s, v)), optional
        The colour range this view keeps, in place of the filter chain's ``hsv_range`` step
        (one view per marker colour on the same camera); None keeps the chain's.
    """

    name: str
    roi: tuple[int, int, int, int] | None = None
    flip_x: bool = False
    flip_y: bool = False
    camera: str | None = None
    video: int = 0
    hsv: tuple[tuple[int, int, int], tuple[int, int, int]] | None = None

    def __post_init__(self) -> None:
        if self.roi is not None:
            roi = tuple(int(v) for v in self.roi)
            if len(roi) != 4:
                raise VideoTrackError(f"view {self.name!r}: roi must be (x, y, width, height)",
                                      field="roi")
            object.__setattr__(self, "roi", roi)
        if not self.camera:
            object.__setattr__(self, "camera", self.name)
        if self.hsv is not None:
            try:
                lower, upper = (tuple(int(c) for c in bound) for bound in self.hsv)
            except (TypeError, ValueError):
                lower = upper = ()
            if len(lower) != 3 or len(upper) != 3:
                raise VideoTrackError(f"view {self.name!r}: hsv needs a lower and an upper "
                                      "(hue, saturation, value)", field="hsv")
            object.__setattr__(self, "hsv", (lower, upper))

    # -- geometry -------------------------------------------------------------------------

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the view image; needs a resolved ROI."""
        self._need_roi()
        return self.roi[2], self.roi[3]

    def resolved(self, width: int, height: int, *, field: str | None = None) -> View:
        """This view with its ROI filled in (whole frame if None) and checked against a frame
        of ``width`` x ``height``.

        Raises
        ------
        VideoTrackError
            The ROI is empty or reaches outside the frame (``field`` names it in the error).
        """
        roi = self.roi if self.roi is not None else (0, 0, width, height)
        x, y, w, h = roi
        field = field or f"view {self.name!r} roi"
        if w < 1 or h < 1:
            raise VideoTrackError(f"ROI {list(roi)} is empty", field=field)
        if x < 0 or y < 0 or x + w > width or y + h > height:
            raise VideoTrackError(
                f"ROI [x={x}, y={y}, w={w}, h={h}] reaches outside the {width}x{height} frame "
                f"(x + w must be <= {width}, y + h <= {height})",
                field=field,
            )
        return replace(self, roi=roi)

    def roi_image(self, frame: np.ndarray) -> np.ndarray:
        """The ROI of ``frame`` as it is stored, not mirrored (a view, no copy)."""
        self._need_roi()
        x, y, w, h = self.roi
        return frame[y : y + h, x : x + w]

    def cut(self, frame: np.ndarray) -> np.ndarray:
        """The view image of ``frame``: ROI, mirrored as set (a view when not mirrored)."""
        return self.flip_image(self.roi_image(frame))

    def flip_image(self, image: np.ndarray) -> np.ndarray:
        """Mirror an ROI-sized image as set (its own inverse: also view → ROI orientation)."""
        return image[:: -1 if self.flip_y else 1, :: -1 if self.flip_x else 1]

    def roi_to_view(self, xy) -> np.ndarray:
        """Map points, shape (n, 2), from ROI coordinates (not mirrored) to view coordinates.

        Its own inverse: also maps view to ROI coordinates.
        """
        self._need_roi()
        out = np.array(xy, dtype=float).reshape(-1, 2)
        _, _, w, h = self.roi
        if self.flip_x:
            out[:, 0] = (w - 1) - out[:, 0]
        if self.flip_y:
            out[:, 1] = (h - 1) - out[:, 1]
        return out

    def to_frame(self, xy) -> np.ndarray:
        """Map points, shape (n, 2), from view coordinates to frame coordinates."""
        out = self.roi_to_view(xy)
        out += self.roi[:2]
        return out

    def from_frame(self, xy) -> np.ndarray:
        """Map points, shape (n, 2), from frame coordinates to view coordinates."""
        self._need_roi()
        return self.roi_to_view(np.asarray(xy, dtype=float).reshape(-1, 2) - self.roi[:2])

    def to_dict(self) -> dict:
        out = {"name": self.name, "roi": list(self.roi) if self.roi else [],
               "flip_x": self.flip_x, "flip_y": self.flip_y, "camera": self.camera,
               "video": self.video}
        if self.hsv is not None:  # only then: detections of views without it stay fresh
            out["hsv"] = [list(self.hsv[0]), list(self.hsv[1])]
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> View:
        """The view :meth:`to_dict` wrote (e.g. from a detections file's settings)."""
        return cls(d["name"], tuple(d.get("roi") or ()) or None, bool(d.get("flip_x")),
                   bool(d.get("flip_y")), d.get("camera") or None, int(d.get("video", 0)),
                   d.get("hsv") or None)

    def _need_roi(self) -> None:
        if self.roi is None:
            raise ValueError(f"view {self.name!r} has no ROI yet; call resolved(width, height)")


def check_views(views: Sequence[View], sizes: Sequence[tuple[int, int]]) -> tuple[View, ...]:
    """Resolve every view against the frame sizes ``(width, height)`` of its video.

    Warns (:class:`~videotrack.errors.VideoTrackWarning`) when a video looks like a scaled
    copy of the one the views were drawn on (:func:`scaled_video_problem`).

    Raises
    ------
    VideoTrackError
        No views, duplicate names, a view of a video that is not there, an ROI outside the
        frame (saying which frame size the views need); the field is ``views[i]...`` as in
        the project file.
    """
    out = _resolve(views, sizes)
    for video, (width, height) in enumerate(sizes):
        problem = scaled_video_problem(views, video, width, height)
        if problem:
            warnings.warn(problem, VideoTrackWarning, stacklevel=2)
    return out


def _resolve(views: Sequence[View], sizes: Sequence[tuple[int, int]]) -> tuple[View, ...]:
    """:func:`check_views` without its warnings."""
    if not views:
        raise VideoTrackError("no views", field="views")
    names = [v.name for v in views]
    for i, view in enumerate(views):
        if names.index(view.name) != i:
            raise VideoTrackError(f"view name {view.name!r} is used twice",
                                  field=f"views[{i}].name")
    out = []
    for i, view in enumerate(views):
        if not 0 <= view.video < len(sizes):
            raise VideoTrackError(
                f"view {view.name!r} is cut from video {view.video}, but there are "
                f"{len(sizes)} video(s) (0-based)", field=f"views[{i}].video")
        width, height = sizes[view.video]
        try:
            out.append(view.resolved(width, height, field=f"views[{i}].roi"))
        except VideoTrackError as err:
            need = _needed_size(views, view.video)
            if need is not None and (need[0] > width or need[1] > height):
                err.message += (f"; the views need a frame of at least {need[0]}x{need[1]}: "
                                "is this the video they were set up for?")
            raise
    return tuple(out)


def _needed_size(views: Sequence[View], video: int) -> tuple[int, int] | None:
    """The frame size the explicit ROIs of one video's views reach, or None without any."""
    rois = [v.roi for v in views if v.video == video and v.roi is not None]
    if not rois:
        return None
    return max(x + w for x, _, w, _ in rois), max(y + h for _, y, _, h in rois)


def scaled_video_problem(views: Sequence[View], video: int, width: int, height: int
                         ) -> str | None:
    """A message when video ``video`` (``width`` x ``height``) looks like a scaled copy of
    the one its views were drawn on, else None.

    The views' ROIs then reach only a top-left part of the frame that has the frame's own
    proportions (e.g. ROIs up to 720x288 in a 1440x576 frame): markers appear at other
    positions, and every fit would fail. Views of the whole frame (no ROI) are not judged.
    """
    if any(v.roi is None for v in views if v.video == video):
        return None
    need = _needed_size(views, video)
    if need is None:
        return None
    sx, sy = width / need[0], height / need[1]
    if sx < 1.1 or sy < 1.1 or abs(sx / sy - 1.0) > 0.01:
        return None
    return (f"video {video} is {width}x{height} pixels, but its views' ROIs reach only the "
            f"top-left {need[0]}x{need[1]} (the frame is {sx:.3g} times larger in both "
            "directions): is this the video the views were set up for? If it was recorded "
            "at another resolution, scale the ROIs and the cameras")


def check_camera_sizes(views: Sequence[View], sizes: Sequence[tuple[int, int]],
                       cameras: Mapping[str, object]) -> None:
    """Refuse views whose size differs from the image size their camera declares.

    ``cameras`` maps view names to cameras (as a project's model does); a camera without an
    ``image_size`` is not judged. A camera projects to the view image's pixels, so a view
    of another size (a video larger or smaller than the calibration's, a changed ROI) puts
    every projected marker in the wrong place and every fit would fail.

    Raises
    ------
    VideoTrackError
        Naming the view, both sizes and what to do; field ``views[i]``.
    """
    for i, view in enumerate(_resolve(views, sizes)):
        camera = cameras.get(view.name)
        size = getattr(camera, "image_size", None)
        if size is None or tuple(int(v) for v in size) == view.size:
            continue
        what = "the whole frame" if views[i].roi is None else "its ROI"
        raise VideoTrackError(
            f"view {view.name!r} is {view.size[0]}x{view.size[1]} pixels ({what}), but its "
            f"camera {view.camera!r} is calibrated for {size[0]}x{size[1]} images: is this "
            "the video the views and cameras were set up for? (set the view's roi, or the "
            "camera's size, to match)", field=f"views[{i}]")


@dataclass(frozen=True)
class Plane:
    """One image the filters run on: a view of one field (or of the whole frame).

    It is cut from the frame without mirroring (mirroring a mask or a filter result commutes
    with every filter, whose kernels are symmetric), so only points are mirrored, exactly.
    """

    view: View
    parity: int | None
    deinterlace: Deinterlace

    def extract(self, frame: np.ndarray) -> np.ndarray:
        """The plane's image of a full frame (a strided view unless line-doubled)."""
        return self.deinterlace.field_image(self.view.roi_image(frame), self.parity,
                                            row0=self.view.roi[1])

    def from_view_image(self, image: np.ndarray) -> np.ndarray:
        """The plane's image of a view-sized image given in view orientation (e.g. a mask)."""
        return self.deinterlace.field_image(self.view.flip_image(image), self.parity,
                                            row0=self.view.roi[1])

    def to_view(self, xy: np.ndarray) -> np.ndarray:
        """Map points, shape (n, 2), from plane image coordinates to view coordinates."""
        out = np.array(xy, dtype=float).reshape(-1, 2)
        out[:, 1] = self.deinterlace.to_full_y(out[:, 1], self.parity, row0=self.view.roi[1])
        return self.view.roi_to_view(out)

    def from_view(self, xy) -> np.ndarray:
        """Inverse of :meth:`to_view`."""
        out = self.view.roi_to_view(xy)
        out[:, 1] = self.deinterlace.from_full_y(out[:, 1], self.parity, row0=self.view.roi[1])
        return out
