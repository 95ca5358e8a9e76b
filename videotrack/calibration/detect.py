"""Board corners in the views of every camera: frame sampling, a progress bar, a cache.

A camera's source is a video file, a folder of images or a glob pattern of images
(``images/left*.jpg``). Frame ``i`` of every camera is the same instant: the same frame
indices are sampled, evenly, from all cameras. Corners are cached in one ``.npz`` file keyed
by the SHA-256 of the board, the source's content and the sampled frames, so a second run
(another --restarts, another output) does not detect again.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from kinematics.fileio import atomic_write
from videotrack.calibration.boards import Board
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.project.identity import content_hash, video_hash

__all__ = ["CACHE_MARK", "Source", "detect_all"]

#: Array that marks a corner cache file (for the never-overwrite guard).
CACHE_MARK = "calibration_corners"
_VERSION = 1


class Source:
    """The frames of one camera: a video, an image folder or a glob pattern of images."""

    def __init__(self, name: str, path: str) -> None:
        self.name, self.spec = name, str(path)
        if any(ch in self.spec for ch in "*?["):
            from videotrack.detect.video import natural_key  # img2 before img10

            self.files = sorted((Path(p) for p in glob.glob(self.spec) if Path(p).is_file()),
                                key=lambda p: natural_key(p.name))
            if not self.files:
                raise VideoTrackError("no image matches this pattern", file=self.spec,
                                      field=f"--camera {name}")
            self.video = None
            self.n_frames = len(self.files)
        else:
            from videotrack.detect.video import VideoSource

            self.files = None
            self.video = VideoSource(self.spec)
            self.n_frames = len(self.video)

    def read(self, index: int) -> np.ndarray:
        if self.video is not None:
            return self.video.read(index)
        image = cv2.imread(str(self.files[index]), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise VideoTrackError("cannot read this image", file=self.files[index])
        return image

    def label(self, index: int) -> str:
        return self.files[index].name if self.files is not None else f"frame {index}"

    def content(self) -> str:
        if self.files is None:
            return video_hash(self.spec)
        digest = hashlib.sha256()
        for f in self.files:
            digest.update(f"{f.name}\t{content_hash(f)}\n".encode())
        return digest.hexdigest()


@dataclass
class Corners:
    """Detected corners of one camera: ``uv[view, corner]`` in pixels, NaN where unseen."""

    name: str
    size: tuple[int, int]
    frames: np.ndarray  # (n_views,) source frame index of each view
    uv: np.ndarray  # (n_views, n_corners, 2)
    labels: list[str]

    @property
    def views_found(self) -> int:
        return int(np.any(np.isfinite(self.uv[..., 0]), axis=1).sum())


def sample_frames(n_frames: int, max_frames: int | None) -> np.ndarray:
    """At most ``max_frames`` indices spread evenly over ``range(n_frames)``."""
    if not max_frames or n_frames <= max_frames:
        return np.arange(n_frames)
    return np.unique(np.round(np.linspace(0, n_frames - 1, max_frames)).astype(int))


def _key(board: Board, source: Source, frames: np.ndarray) -> str:
    text = json.dumps([_VERSION, board.spec(), source.content(), frames.tolist()])
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _load_cache(path: Path | None) -> dict:
    if path is None or not path.is_file():
        return {}
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError):  # damaged or foreign: detect again, rewrite it
        return {}


def detect_all(board: Board, sources: list[Source], *, max_frames: int | None = 200,
               synchronised: bool = True, cache: str | os.PathLike | None = None,
               progress: bool = True) -> list[Corners]:
    """Detect the board in the sampled frames of every camera.

    Parameters
    ----------
    board : Board
    sources : list of Source
    max_frames : int, optional
        Frames sampled evenly per camera; None for all.
    synchronised : bool
        Sample the same frame indices in every camera (needed for extrinsics); with sources
        of different lengths, the shortest sets the range (with a warning).
    cache : path, optional
        ``.npz`` corner cache, read and rewritten.

    Raises
    ------
    VideoTrackError
        A camera in which the board is not found in any sampled frame.
    """
    from tqdm import tqdm

    cache = Path(cache) if cache is not None else None
    stored = _load_cache(cache)
    lengths = [s.n_frames for s in sources]
    if synchronised and len(set(lengths)) > 1:
        warnings.warn("the cameras have different frame counts ("
                      + ", ".join(f"{s.name} {s.n_frames}" for s in sources)
                      + "); using the first frames of each, assumed synchronised",
                      VideoTrackWarning, stacklevel=2)
    out, fresh = [], {CACHE_MARK: np.array(_VERSION)}
    for source in sources:
        frames = sample_frames(min(lengths) if synchronised else source.n_frames, max_frames)
        key = _key(board, source, frames)
        if f"{key}_uv" in stored:
            uv, size = stored[f"{key}_uv"], tuple(int(v) for v in stored[f"{key}_size"])
        else:
            uv = np.full((len(frames), board.n_corners, 2), np.nan)
            size = None
            for i, f in enumerate(tqdm(frames, desc=f"board in {source.name}", unit="frame",
                                       leave=False, disable=None if progress else True)):
                image = source.read(int(f))
                size = (image.shape[1], image.shape[0])
                ids, pts = board.detect(image)
                uv[i, ids] = pts
        fresh[f"{key}_uv"], fresh[f"{key}_size"] = uv, np.array(size)
        corners = Corners(source.name, size, frames, uv, [source.label(int(f)) for f in frames])
        if corners.views_found == 0:
            counted = ("markers along x and y, dictionary" if board.type == "aruco" else
                       "squares are counted, not inner corners")
            raise VideoTrackError(f"no {board.describe()} found in any of {len(frames)} "
                                  f"sampled frames; check the board config ({counted}) and "
                                  "the images", file=source.spec, field=f"--camera {source.name}")
        out.append(corners)
    if cache is not None:
        with atomic_write(cache, "wb") as fh:
            np.savez_compressed(fh, **fresh)
    return out
