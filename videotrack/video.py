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
"""

from __future__ import annotations

import os
import re
import warnings
from collections import deque
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from videotrack.cores import available_cores
from videotrack.errors import VideoTrackError, VideoTrackWarning

# Silence FFmpeg's own console messages (e.g. on truncated files): problems are reported as
# one-line warnings instead. Must be set before the first VideoCapture; a user's value wins.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

#: File name endings read as image sequences.
IMAGE_EXTENSIONS = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")

#: Codecs (FOURCC, lower case) whose every frame is a keyframe: seeking is exact.
INTRA_CODECS = frozenset(
    {"ffv1", "mjpg", "avrn", "dvsd", "dv25", "dv50", "dvcp", "dvpp", "dvh1", "dvhd", "png ",
     "mpng", "rawv", "raw ", "y800", "grey", "i420", "yuy2", "uyvy", "hfyu", "ffvh", "utvd",
     "mjp2", "tiff", "bgr ", "dib "}
)

#: Pixel formats (OpenCV's CAP_PROP_CODEC_PIXEL_FORMAT FOURCC) decoded straight to grey.
_GREY_PIXEL_FORMATS = frozenset({"Y800", "GREY", "Y8  ", "GRAY"})

#: Codecs (FOURCC, lower case) whose packets are whole JPEG images: their frames are decoded
#: from the packets by OpenCV's libjpeg-turbo (:class:`_Packets`).
JPEG_CODECS = frozenset({"mjpg"})  # OpenCV names MJPEG so in AVI, MOV and MP4 alike

#: A packet's decode may differ from FFmpeg's by rounding (the colour conversion, in grey
#: the BGR round trip): at most this mean absolute difference in grey levels on the first
#: frame, else the packets are not taken for the frames.
_PACKET_TOLERANCE = 3.0

#: Threads decoding MJPEG packets ahead of a sequential read (libjpeg-turbo releases the
#: GIL), and packets each keeps in flight.
DECODE_THREADS = min(4, available_cores())
_AHEAD_PER_THREAD = 2

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


def natural_key(name: str) -> list:
    """Sort key that orders ``img2.png`` before ``img10.png``."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def _fourcc(value: float) -> str:
    v = int(value)
    return "".join(chr((v >> (8 * i)) & 0xFF) for i in range(4))


class _Capture:
    """OpenCV VideoCapture backend; positions are indices of the next frame returned."""

    def __init__(self, path: Path, threads: int) -> None:
        self.path = path
        self.threads = threads
        self.cap = self._open()
        self.codec = _fourcc(self.cap.get(cv2.CAP_PROP_FOURCC)).lower()
        pixel_format = _fourcc(self.cap.get(cv2.CAP_PROP_CODEC_PIXEL_FORMAT))
        # Grey sources decode straight to one channel, skipping a BGR round trip.
        self.raw_grey = pixel_format in _GREY_PIXEL_FORMATS
        self._apply_format()
        self.intra = self.codec in INTRA_CODECS
        count = self.cap.get(cv2.CAP_PROP_FRAME_COUNT)
        self.container_frames = int(count) if count == count and count > 0 else 0
        fps = self.cap.get(cv2.CAP_PROP_FPS)
        self.fps = float(fps) if fps == fps and 0 < fps < 1e6 else 0.0

    def _open(self) -> cv2.VideoCapture:
        params = [cv2.CAP_PROP_N_THREADS, self.threads] if self.threads > 0 else []
        # OpenCV logs its own warning for files it cannot open; ours is the one-line error.
        level = cv2.utils.logging.getLogLevel()
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
        try:
            cap = cv2.VideoCapture(str(self.path), cv2.CAP_FFMPEG, params)
        finally:
            cv2.utils.logging.setLogLevel(level)
        if not cap.isOpened():
            raise VideoTrackError(
                "cannot open as a video: not a format or codec OpenCV's FFmpeg backend reads",
                file=self.path,
            )
        return cap

    def _apply_format(self) -> None:
        if self.raw_grey:
            self.cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)

    def reopen(self) -> None:
        self.cap.release()
        self.cap = self._open()
        self._apply_format()

    def read(self, out=None):
        ok, frame = self.cap.read(out) if out is not None else self.cap.read()
        return frame if ok else None

    def grab(self) -> bool:
        return bool(self.cap.grab())

    def seek(self, index: int) -> bool:
        """Seek by the container; True if OpenCV reports the position as reached."""
        self.cap.set(cv2.CAP_PROP_POS_FRAMES, index)
        return int(self.cap.get(cv2.CAP_PROP_POS_FRAMES)) == index

    def start_ahead(self, count: int) -> None:
        """FFmpeg decodes in order, in its own threads: nothing to start."""

    def stop_ahead(self) -> int:
        return 0

    def close(self) -> None:
        self.cap.release()


class _Packets:
    """MJPEG decoded from its packets: FFmpeg only demuxes (OpenCV's raw mode,
    ``CAP_PROP_FORMAT = -1``), and libjpeg-turbo (``cv2.imdecode``) decodes a grey frame
    from the JPEG's luma alone, skipping the chroma, the YUV→BGR conversion and the
    BGR→grey one (3x faster, docs/benchmarks.md "End to end", and without their rounding:
    the grey levels are the encoded ones). In a sequential read (:meth:`start_ahead`) the
    next packets are decoded ahead in threads. A packet libjpeg refuses (damaged, cut off)
    is decoded by FFmpeg, as before, through ``plain``, a capture of the same file.
    Positions: :attr:`next` is the index of the next packet the capture reads."""

    def __init__(self, plain: _Capture, colour: bool) -> None:
        self.plain = plain
        self.path, self.codec, self.intra = plain.path, plain.codec, plain.intra
        self.raw_grey = False
        self.container_frames, self.fps = plain.container_frames, plain.fps
        self.flag = (cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE) | \
            cv2.IMREAD_IGNORE_ORIENTATION  # as FFmpeg: no EXIF rotation
        self.cap: cv2.VideoCapture | None = None
        self.next = 0
        self._pending: deque | None = None  # (index, future) decoded ahead
        self._ahead_left = 0
        self._pool: ThreadPoolExecutor | None = None
        self.usable = self._open_raw() and self._matches(colour)
        if self.usable:
            self.reopen()
        elif self.cap is not None:
            self.cap.release()

    def _open_raw(self) -> bool:
        self.cap = self.plain._open()
        self.next = 0
        return bool(self.cap.set(cv2.CAP_PROP_FORMAT, -1))

    def _matches(self, colour: bool) -> bool:
        """Whether packets are the frames: the first decodes to FFmpeg's first frame
        within rounding (a packet of two interlaced fields, or a codec variant, does not),
        and seeking lands on the packets read in order (OpenCV 5.0 seeks to packet 1 one
        packet late: :meth:`seek` steps there; another version might err elsewhere)."""
        reference = self.plain.read()
        self.plain.seek(0)
        packets = []
        for _ in range(3):
            ok, packet = self.cap.read()
            if not ok:
                break
            packets.append(packet.tobytes())
        if reference is None or not packets:
            return False
        image = _decode_jpeg(np.frombuffer(packets[0], np.uint8), self.flag)
        expected = reference if colour or reference.ndim == 2 else \
            cv2.cvtColor(reference, cv2.COLOR_BGR2GRAY)
        if (image is None or image.shape != expected.shape
                or cv2.absdiff(image, expected).mean() > _PACKET_TOLERANCE):
            return False
        for k in range(1, len(packets)):
            self.seek(k)
            ok, packet = self.cap.read()
            if not ok or packet.tobytes() != packets[k]:
                return False
        return True

    def _frame(self, index: int, image):
        """Packet ``index`` as decoded, or by FFmpeg where libjpeg refused it."""
        if image is not None:
            return image
        return self.plain.read() if self.plain.seek(index) else None

    def read(self, out=None):
        if self._pending is not None:
            return self._next_ahead()
        ok, packet = self.cap.read()
        if not ok:
            return None
        self.next += 1
        return self._frame(self.next - 1, _decode_jpeg(packet, self.flag))

    def grab(self) -> bool:
        if self._pending is not None:  # in order: take the next frame decoded ahead
            return self._next_ahead() is not None
        ok = bool(self.cap.grab())
        self.next += ok
        return ok

    def seek(self, index: int) -> bool:
        """Seek by the container; True if OpenCV reports the position as reached."""
        self.stop_ahead()
        if index == 1:  # OpenCV 5.0 lands on packet 2: go to 0 and step over one
            self.cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            self.cap.grab()
        else:
            self.cap.set(cv2.CAP_PROP_POS_FRAMES, index)
        self.next = index
        return int(self.cap.get(cv2.CAP_PROP_POS_FRAMES)) == index

    def reopen(self) -> None:
        self.stop_ahead()
        self.cap.release()
        self._open_raw()

    def start_ahead(self, count: int) -> None:
        """Decode the next ``count`` packets ahead, in threads, for the reads that follow
        (``imdecode`` releases the GIL). Moving the capture (seek, reopen) drops them."""
        self.stop_ahead()
        if count < 2 or DECODE_THREADS < 2:
            return
        self._pool = ThreadPoolExecutor(DECODE_THREADS, thread_name_prefix="videotrack-decode")
        self._pending = deque()
        self._ahead_left = count

    def stop_ahead(self) -> int:
        """End :meth:`start_ahead`; the number of frames read ahead but not returned (the
        capture stands that many frames past the last one :meth:`read` returned)."""
        if self._pending is None:
            return 0
        left = len(self._pending)
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = self._pending = None
        return left

    def _next_ahead(self):
        while self._ahead_left > 0 and len(self._pending) < _AHEAD_PER_THREAD * DECODE_THREADS:
            ok, packet = self.cap.read()  # demuxing only: cheap
            if not ok:
                self._ahead_left = 0
                break
            future = self._pool.submit(_decode_jpeg, packet, self.flag)
            self._pending.append((self.next, future))
            self.next += 1
            self._ahead_left -= 1
        if not self._pending:
            return None
        index, future = self._pending.popleft()
        return self._frame(index, future.result())

    def close(self) -> None:
        self.stop_ahead()
        self.cap.release()
        self.plain.close()


def _video_backend(path: Path, threads: int, colour: bool):
    """The backend reading a video file: MJPEG from its packets where they are the frames,
    else FFmpeg's decoder."""
    plain = _Capture(path, threads)
    if plain.codec in JPEG_CODECS:
        packets = _Packets(plain, colour)
        if packets.usable:
            return packets
        plain.reopen()
    return plain


def _decode_jpeg(packet, flag: int):
    """A packet decoded as a JPEG image; None for an empty or damaged one."""
    if packet is None or packet.size == 0:
        return None
    try:
        return cv2.imdecode(packet, flag)
    except cv2.error:
        return None


class _Sequence:
    """Image-sequence backend: one image file per frame."""

    intra = True
    raw_grey = False
    fps = 0.0

    def __init__(self, folder: Path, colour: bool) -> None:
        self.files = sorted(
            (p for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file()),
            key=lambda p: natural_key(p.name),
        )
        if not self.files:
            raise VideoTrackError(
                f"folder holds no images ({', '.join(IMAGE_EXTENSIONS)})", file=folder
            )
        self.flag = cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE
        self.container_frames = len(self.files)
        self.pos = 0
        self.shape = None

    def read(self, out=None):
        if self.pos >= len(self.files):
            return None
        path = self.files[self.pos]
        image = cv2.imread(str(path), self.flag)
        if image is None:
            return None
        if self.shape is None:
            self.shape = image.shape
        elif image.shape != self.shape:
            raise VideoTrackError(
                f"image has size {image.shape[1]}x{image.shape[0]}, the sequence's first image "
                f"{self.shape[1]}x{self.shape[0]}",
                file=path,
            )
        self.pos += 1
        return image

    def grab(self) -> bool:
        if self.pos >= len(self.files):
            return False
        self.pos += 1
        return True

    def seek(self, index: int) -> bool:
        self.pos = index
        return True

    def reopen(self) -> None:
        self.pos = 0

    def start_ahead(self, count: int) -> None:
        pass

    def stop_ahead(self) -> int:
        return 0

    def close(self) -> None:
        pass


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
