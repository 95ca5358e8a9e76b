"""A synthetic scene (:mod:`videotrack.synth.scene`) drawn as video frames: each view's
markers and ghosts as anti-aliased discs (:func:`videotrack.synth.render.render_markers`), views
side by side, stacked or separate, fields interlaced (:func:`iter_frames`); and the lossless
video (FFV1, MJPEG or a PNG folder) they are written to atomically (:class:`VideoSink`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

import cv2
import numpy as np

from videotrack.detect.marker_colours import bgr
from videotrack.errors import VideoTrackError
from videotrack.synth.render import render_markers
from videotrack.synth.scene import SynthOptions, SynthScene

CODECS = {"ffv1": ("FFV1", ".avi"), "mjpg": ("MJPG", ".avi"), "png": (None, "")}


def view_rois(sizes: Sequence[tuple[int, int]], layout: str) -> list[tuple[int, int, int, int]]:
    """(x, y, w, h) of each view in the composite frame (each at the origin if separate)."""
    rois, x, y = [], 0, 0
    for w, h in sizes:
        if layout == "separate":
            rois.append((0, 0, w, h))
        elif layout == "side-by-side":
            rois.append((x, 0, w, h))
            x += w
        else:
            rois.append((0, y, w, h))
            y += h
    return rois


def render_view_images(scene: SynthScene, sizes, options: SynthOptions, image: int,
                       rng: np.random.Generator) -> list[np.ndarray]:
    """The image of each view for one posture (markers, ghosts, noise): grey, or colour
    with coloured markers."""
    out = []
    for v, (w, h) in enumerate(sizes):
        seen = scene.visible[image, v]
        pts = scene.projections[image, v][seen]
        ghosts = scene.ghosts[image, v]
        on = np.isfinite(ghosts[:, 0])
        pts = np.concatenate([pts, ghosts[on]])
        shape, gain = (h, w), options.intensity
        if scene.marker_colour is not None:  # ghosts take the colours in turn
            palette = np.array([bgr(c, options.intensity) for c, _ in options.colours])
            which = np.concatenate([scene.marker_colour[seen],
                                    np.flatnonzero(on) % len(palette)])
            shape, gain = (h, w, 3), palette[which].reshape(-1, 3)
        out.append(render_markers(shape, pts, options.marker_diameter, gain,
                                  options.background, options.noise_sigma, rng))
    return out


def iter_frames(scene: SynthScene, sizes, options: SynthOptions) -> Iterable[list[np.ndarray]]:
    """Video frames: one list per frame with one image per output video."""
    rng = np.random.default_rng([options.seed, 1])
    rois = view_rois(sizes, options.layout)
    step = 2 if options.interlaced else 1
    for t in range(0, scene.angles_deg.shape[0], step):
        views = render_view_images(scene, sizes, options, t, rng)
        if options.interlaced:
            second = render_view_images(scene, sizes, options, t + 1, rng)
            first_rows = 0 if options.top_field_first else 1
            for a, b in zip(views, second, strict=True):
                a[1 - first_rows::2] = b[1 - first_rows::2]
        if options.layout == "separate":
            yield views
            continue
        width = max(x + w for x, _, w, _ in rois)
        height = max(y + h for _, y, _, h in rois)
        frame = np.full((height, width, *views[0].shape[2:]), round(options.background),
                        np.uint8)
        for (x, y, w, h), img in zip(rois, views, strict=True):
            frame[y:y + h, x:x + w] = img
        yield [frame]


class VideoSink:
    """Writes frames losslessly (FFV1 AVI or a PNG folder) and publishes atomically.

    Frames go to a temporary file (or folder) next to the target; :meth:`commit` moves it
    into place, and leaving the ``with`` block without commit removes it.
    """

    def __init__(self, path: str | os.PathLike, fps: float, codec: str = "ffv1") -> None:
        if codec not in CODECS:
            raise VideoTrackError(f"codec must be one of {', '.join(CODECS)}", field="codec")
        self.path, self.fps, self.codec = Path(path), float(fps), codec
        self._writer = None
        self._count = 0
        parent = self.path.parent
        parent.mkdir(parents=True, exist_ok=True)
        if codec == "png":
            self._tmp = Path(tempfile.mkdtemp(dir=parent, prefix=f".{self.path.name}."))
        else:
            fd, tmp = tempfile.mkstemp(dir=parent, prefix=f".{self.path.stem}.",
                                       suffix=self.path.suffix or ".avi")
            os.close(fd)
            self._tmp = Path(tmp)

    def write(self, frame: np.ndarray) -> None:
        if self.codec == "png":
            if not cv2.imwrite(str(self._tmp / f"frame_{self._count:06d}.png"), frame):
                raise VideoTrackError("cannot write PNG frame", file=self.path)
        else:
            if self._writer is None:
                fourcc = cv2.VideoWriter_fourcc(*CODECS[self.codec][0])
                h, w = frame.shape[:2]
                self._writer = cv2.VideoWriter(str(self._tmp), fourcc, self.fps, (w, h),
                                               isColor=frame.ndim == 3)
                if not self._writer.isOpened():
                    raise VideoTrackError(f"OpenCV cannot write {self.codec} video",
                                          file=self.path)
            self._writer.write(frame)
        self._count += 1

    def commit(self) -> Path:
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self.codec == "png" and self.path.exists():
            shutil.rmtree(self.path)
        os.replace(self._tmp, self.path)
        return self.path

    def __enter__(self) -> VideoSink:
        return self

    def __exit__(self, *exc) -> None:
        if self._writer is not None:
            self._writer.release()
        if self._tmp.exists():
            with contextlib.suppress(OSError):
                if self._tmp.is_dir():
                    shutil.rmtree(self._tmp)
                else:
                    self._tmp.unlink()
