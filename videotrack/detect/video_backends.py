"""The decoding backends of :class:`videotrack.detect.video.VideoSource`: one video file through
OpenCV's FFmpeg backend (:class:`_Capture`), MJPEG decoded from its packets by libjpeg-turbo
(:class:`_Packets`), and a folder of images (:class:`_Sequence`).

Every backend reads frames in order (``read``, ``grab``), seeks (``seek``: True where the
position is reached), starts over (``reopen``), may decode ahead during a sequential read
(``start_ahead``, ``stop_ahead``) and says ``intra`` (seeking is exact), ``container_frames``
and ``fps`` (0: not announced).
"""

from __future__ import annotations

import os
import re
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from videotrack.cores import available_cores
from videotrack.errors import VideoTrackError

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
