"""Frames from video files and image-sequence folders, one camera or several in sync.

:class:`VideoSource` reads one video (anything OpenCV's FFmpeg backend decodes: AVI with
DV/MJPG/FFV1, MP4/H.264, ...) or one folder of images (PNG/TIFF/JPEG/BMP, natural sort order)
with frame-exact random access and a fast sequential path; :class:`VideoSet` keeps several
synchronised sources (one per camera) at a common frame count.

Frame count. Opening trusts the container's count (cheap). Decoding verifies it: when a frame
before that count cannot be decoded (a truncated or damaged file) the source warns once, naming
the file, keeps every frame before the break and from then on reports the shorter count; a full
sequential pass warns when frames follow the announced end. :meth:`VideoSource.verify_frame_count`
decodes the whole file to count exactly.

Seeking. Intra-only codecs (FFV1, MJPEG, DV, PNG, raw) seek exactly. For other codecs the first
seek is checked against a sequential decode of an early frame; if they differ, the source
decodes sequentially from the start for every backward seek (slow, but exact) and warns.

Frames are ``uint8`` arrays, shape (height, width) in grey mode or (height, width, 3) BGR in
colour mode; pixel ``frame[i, j]`` has centre (x, y) = (j, i).

The decoders (FFmpeg, MJPEG packets, image files) are :mod:`videotrack.detect.video_backends`.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path

import cv2
import numpy as np

from videotrack.detect.video_backends import (
    DECODE_THREADS,  # noqa: F401  (public: the threads decoding MJPEG packets)
    IMAGE_EXTENSIONS,  # noqa: F401  (public: the files an image sequence holds)
    _Sequence,
    _video_backend,
    natural_key,  # noqa: F401  (public: the order of an image sequence)
)
from videotrack.errors import VideoTrackError, VideoTrackWarning

#: Highest frame index used to check that seeking is exact on codecs with inter frames.
_SEEK_PROBE_MAX = 50

#: Frame rate assumed for image sequences and videos that announce none.
DEFAULT_FPS = 25.0


def parse_frame_range(text: str) -> tuple[int, int | None]:
    """Parse ``"A:B"`` (start included, stop excluded), ``"A:"``, ``":B"`` or ``""`` (all).

    Returns ``(start, stop)`` with ``stop`` None for "to the end". Raises ValueError.
    """
    text = text.strip()
    if not text:
        return 0, None
    match = re.fullmatch(r"(\d*)\s*:\s*(\d*)", text)
    if not match:
        raise ValueError(f"frame range must look like 'A:B', 'A:' or ':B', got {text!r}")
    start = int(match.group(1)) if match.group(1) else 0
    stop = int(match.group(2)) if match.group(2) else None
    if stop is not None and stop <= start:
        raise ValueError(f"frame range {text!r} is empty (stop must exceed start)")
    return start, stop


def resolve_frames(frames, n_frames: int) -> range:
    """Frames to process as a ``range`` within ``0..n_frames``.

    ``frames`` is None (all), a ``range`` with step 1, a ``(start, stop)`` pair (stop may be
    None) or an ``"A:B"`` string. A stop beyond the end is clipped with a warning.
    """
    if frames is None:
        start, stop = 0, None
    elif isinstance(frames, str):
        try:
            start, stop = parse_frame_range(frames)
        except ValueError as err:
            raise VideoTrackError(str(err), field="frames") from None
    elif isinstance(frames, range):
        if frames.step != 1:
            raise VideoTrackError("frame range must have step 1", field="frames")
        start, stop = frames.start, frames.stop
    else:
        start, stop = frames
    if start < 0 or start >= n_frames:
        raise VideoTrackError(
            f"frame range starts at {start}, but the video has frames 0..{n_frames - 1}",
            field="frames",
        )
    if stop is None:
        stop = n_frames
    if stop > n_frames:
        warnings.warn(
            f"frame range ends at {stop}, but the video has {n_frames} frames; "
            f"processing frames {start}:{n_frames}",
            VideoTrackWarning,
            stacklevel=2,
        )
        stop = n_frames
    return range(start, stop)


class VideoSource:
    """One video file or image-sequence folder.

    Parameters
    ----------
    path : str or PathLike
        Video file or folder of images.
    colour : bool
        Return BGR frames, shape (h, w, 3); default grey frames, shape (h, w).
    fps : float, optional
        Frame rate overriding the container's (image sequences default to 25).
    threads : int
        FFmpeg decoding threads; 0 lets FFmpeg choose (MJPEG is decoded from its packets by
        libjpeg-turbo instead, in :data:`DECODE_THREADS` threads during sequential reads).

    Raises
    ------
    VideoTrackError
        Missing file, a format or codec that cannot be decoded, an empty folder.
    """

    def __init__(self, path, *, colour: bool = False, fps: float | None = None,
                 threads: int = 0) -> None:
        self.path = Path(path).absolute()
        self.colour = bool(colour)
        if not self.path.exists():
            raise VideoTrackError("no such file or folder", file=self.path)
        self.is_sequence = self.path.is_dir()
        self._backend = (_Sequence(self.path, self.colour) if self.is_sequence
                         else _video_backend(self.path, threads, self.colour))
        self.broken_at: int | None = None
        self._seek_exact: bool | None = True if self._backend.intra else None
        self._pos = 0
        self.container_frames = self._backend.container_frames
        self.n_frames = self.container_frames
        if fps is not None and fps > 0:
            self.fps = float(fps)
        else:
            self.fps = self._backend.fps or DEFAULT_FPS
            if not self._backend.fps and not self.is_sequence:
                warnings.warn(f"{self.path}: no frame rate in the file; assuming {DEFAULT_FPS} "
                              "fps (set video.fps)", VideoTrackWarning, stacklevel=2)
        first = self._backend.read()
        if first is None:
            raise VideoTrackError(
                "cannot decode the first frame (codec not supported by this OpenCV build, or "
                "a damaged file)", file=self._backend.files[0] if self.is_sequence else self.path
            )
        self._pos = 1
        self.height, self.width = first.shape[:2]
        self._first = self._convert(first)
        if self.n_frames == 0:  # the container does not say: count by decoding
            self.n_frames = self.container_frames = self._count()

    # -- properties -----------------------------------------------------------------------

    @property
    def shape(self) -> tuple[int, ...]:
        """Shape of a frame: (h, w) grey or (h, w, 3) colour."""
        return (self.height, self.width, 3) if self.colour else (self.height, self.width)

    def __len__(self) -> int:
        return self.n_frames

    def __repr__(self) -> str:
        return (f"VideoSource({str(self.path)!r}, {self.width}x{self.height}, "
                f"{self.n_frames} frames, {self.fps:g} fps)")

    def identity(self) -> dict:
        """What identifies this video in a detections file (JSON-able)."""
        if self.is_sequence:
            files = self._backend.files
            size = sum(p.stat().st_size for p in files)
        else:
            size = self.path.stat().st_size
        return {
            "path": str(self.path),
            "name": self.path.name,
            "bytes": int(size),
            "width": int(self.width),
            "height": int(self.height),
            "frames": int(self.container_frames),
            "fps": float(self.fps),
        }

    # -- reading --------------------------------------------------------------------------

    def read(self, index: int) -> np.ndarray:
        """Frame ``index`` (0-based), decoded frame-exactly; a new array.

        Raises
        ------
        VideoTrackError
            Index outside the video, or the frame cannot be decoded (the break is reported
            once as a :class:`VideoTrackWarning`).
        """
        index = int(index)
        if not 0 <= index < self.n_frames:
            raise VideoTrackError(
                f"frame {index} is outside the video's frames 0..{self.n_frames - 1}",
                file=self.path,
            )
        if index == 0 and self._first is not None:
            return self._first.copy()
        if index != self._pos:
            self._seek(index)
        frame = self._backend.read()
        if frame is None:
            self._broken(index)
            raise VideoTrackError(f"cannot decode frame {index}", file=self.path)
        self._pos = index + 1
        return self._convert(frame)

    def frames(self, start: int = 0, stop: int | None = None, *,
               reuse: bool = False) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(index, frame)`` for ``start <= index < stop``, decoding sequentially.

        Stops early, with a warning, at a frame that cannot be decoded. With ``reuse`` the
        same array is refilled for every frame (faster; copy a frame to keep it).
        """
        stop = self.n_frames if stop is None else min(stop, self.n_frames)
        raw = out = None
        index = start
        ahead = False
        try:
            while index < stop:
                if index == 0 and self._first is not None and self._pos != 0:
                    index += 1
                    yield 0, self._first.copy()  # decoded at open: no seek back to the start
                    continue
                if index != self._pos:  # (also after a read elsewhere while paused)
                    self._seek(index)
                    ahead = False  # a seek drops the frames decoded ahead
                if not ahead:  # from here on every frame is read in order
                    self._backend.start_ahead(stop - index)
                    ahead = True
                raw = self._backend.read(raw if reuse else None)
                if raw is None:
                    self._broken(index)
                    return
                self._pos = index + 1
                out = self._convert(raw, out if reuse else None)
                yield index, out
                index += 1
        finally:
            if self._backend.stop_ahead():
                self._pos = -1  # frames read ahead and dropped: the next read seeks
        if stop == self.n_frames == self.container_frames and self.broken_at is None:
            self._check_end()

    def verify_frame_count(self) -> int:
        """Decode the whole video to count its frames; warn if the container said otherwise.

        Returns the number of decodable frames, which becomes :attr:`n_frames`.
        """
        count = self._count()
        if count != self.container_frames:
            warnings.warn(
                f"{self.path}: the container says {self.container_frames} frames, "
                f"{count} decode; using {count}",
                VideoTrackWarning,
                stacklevel=2,
            )
            if count < self.container_frames:
                self.broken_at = count
        self.n_frames = count
        return count

    def close(self) -> None:
        self._backend.close()

    def __enter__(self) -> VideoSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- internals ------------------------------------------------------------------------

    def _convert(self, frame: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        channels = 1 if frame.ndim == 2 else frame.shape[2]
        if self.colour:
            if channels == 3:
                return frame
            code = cv2.COLOR_GRAY2BGR if channels == 1 else cv2.COLOR_BGRA2BGR
        else:
            if channels == 1:
                return frame if frame.ndim == 2 else frame[:, :, 0]
            code = cv2.COLOR_BGR2GRAY if channels == 3 else cv2.COLOR_BGRA2GRAY
        return cv2.cvtColor(frame, code, dst=out)

    def _count(self) -> int:
        self._backend.reopen()
        count = 0
        while self._backend.grab():
            count += 1
        self._pos = count
        return count

    def _seek(self, index: int) -> None:
        if self._seek_exact is None:
            self._seek_exact = self._probe_seek(index)
            if not self._seek_exact:
                warnings.warn(
                    f"{self.path}: seeking in this {self.codec!r} video is not frame-exact; "
                    "decoding sequentially instead (slow for backward jumps)",
                    VideoTrackWarning,
                    stacklevel=3,
                )
        if self._seek_exact:
            if self._backend.seek(index):
                self._pos = index
                return
            # A failed seek (e.g. past a break) leaves the decoder anywhere: start over.
            self._backend.reopen()
            self._pos = 0
        self._seek_sequential(index)

    @property
    def codec(self) -> str:
        return "image sequence" if self.is_sequence else self._backend.codec

    def _seek_sequential(self, index: int) -> None:
        if index < self._pos or self._pos < 0:  # behind, or position unknown
            self._backend.reopen()
            self._pos = 0
        while self._pos < index:
            if not self._backend.grab():
                self._broken(self._pos)
                raise VideoTrackError(f"cannot decode frame {self._pos}", file=self.path)
            self._pos += 1

    def _probe_seek(self, target: int) -> bool:
        """Whether seeking lands on the frame a sequential decode gives (checked once)."""
        probe = max(1, min(target, _SEEK_PROBE_MAX, self.n_frames - 1))
        self._seek_sequential(probe)
        expected = self._backend.read()
        if expected is None or not self._backend.seek(probe):
            self._pos = -1  # unknown: force the next read to seek
            return False
        got = self._backend.read()
        self._pos = probe + 1 if got is not None else -1
        return got is not None and np.array_equal(expected, got)

    def _broken(self, index: int) -> None:
        if self.broken_at is not None and index >= self.broken_at:
            return
        self.broken_at = index
        self.n_frames = index
        warnings.warn(
            f"{self.path}: decoding stopped at frame {index} of the {self.container_frames} the "
            f"container announces (truncated or damaged file); keeping frames 0..{index - 1}",
            VideoTrackWarning,
            stacklevel=3,
        )

    def _check_end(self) -> None:
        if self._backend.grab():
            self._pos += 1
            warnings.warn(
                f"{self.path}: more frames decode than the {self.container_frames} the container "
                "announces; only those are used (VideoSource.verify_frame_count counts them)",
                VideoTrackWarning,
                stacklevel=3,
            )


class VideoSet:
    """Synchronised videos, one per camera, read frame by frame together.

    The common frame count is the smallest of the sources' (a warning names the videos when
    they differ); it shrinks when decoding finds a break in any of them.
    """

    def __init__(self, sources: Sequence[VideoSource]) -> None:
        if not sources:
            raise VideoTrackError("no video given", field="video.path")
        self.sources = tuple(sources)
        counts = [s.n_frames for s in self.sources]
        if len(set(counts)) > 1:
            listing = ", ".join(f"{s.path.name}: {s.n_frames}" for s in self.sources)
            warnings.warn(
                f"synchronised videos have different frame counts ({listing}); using the "
                f"first {min(counts)} frames of each",
                VideoTrackWarning,
                stacklevel=2,
            )
        rates = {round(s.fps, 6) for s in self.sources}
        if len(rates) > 1:
            warnings.warn(
                "synchronised videos have different frame rates "
                f"({', '.join(f'{s.path.name}: {s.fps:g}' for s in self.sources)}); "
                f"using {self.sources[0].fps:g} fps",
                VideoTrackWarning,
                stacklevel=2,
            )

    @property
    def n_frames(self) -> int:
        return min(s.n_frames for s in self.sources)

    @property
    def fps(self) -> float:
        return self.sources[0].fps

    def __len__(self) -> int:
        return self.n_frames

    def __getitem__(self, i: int) -> VideoSource:
        return self.sources[i]

    def read(self, index: int) -> tuple[np.ndarray, ...]:
        """Frame ``index`` of every video."""
        return tuple(s.read(index) for s in self.sources)

    def frames(self, start: int = 0, stop: int | None = None, *,
               reuse: bool = False) -> Iterator[tuple[int, tuple[np.ndarray, ...]]]:
        """Yield ``(index, frames)`` with one frame per video; stops at the first break."""
        stop = self.n_frames if stop is None else min(stop, self.n_frames)
        iterators = [s.frames(start, stop, reuse=reuse) for s in self.sources]
        try:
            for items in zip(*iterators, strict=False):
                yield items[0][0], tuple(frame for _, frame in items)
        finally:
            for it in iterators:
                it.close()

    def identity(self) -> list[dict]:
        return [s.identity() for s in self.sources]

    def close(self) -> None:
        for s in self.sources:
            s.close()

    def __enter__(self) -> VideoSet:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_videos(paths, *, colour: bool = False, fps: float | None = None,
                threads: int = 0) -> VideoSet:
    """Open one video (a path) or several synchronised ones (a list of paths)."""
    if isinstance(paths, str | os.PathLike):
        paths = [paths]
    return VideoSet([VideoSource(p, colour=colour, fps=fps, threads=threads) for p in paths])


def as_video_set(source) -> VideoSet:
    """A :class:`VideoSet` for a VideoSource or VideoSet."""
    if isinstance(source, VideoSet):
        return source
    if isinstance(source, VideoSource):
        return VideoSet([source])
    raise TypeError(f"expected a VideoSource or VideoSet, got {type(source).__name__}")
