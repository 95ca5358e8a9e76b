"""Detections: the 2D marker centroids of every (half-)frame and view of a video, and their file.

Layout (ragged, flat). A *record* is one frame, or one half-frame when de-interlacing; records
are in time order. The markers of record ``r`` in view ``v`` are
``points[offsets[k]:offsets[k + 1]]`` with ``k = r * n_views + v``.

File format (``.npz``, written atomically; load with ``numpy.load(path, allow_pickle=False)``):

============  ====================  ==========================================================
key           dtype, shape          meaning
============  ====================  ==========================================================
points        float64 (n, 2)        centroids (x, y) in view image coordinates, see
                                    :mod:`videotrack.detect.views`
areas         int64 (n,)            region areas in pixels of the filtered image
offsets       int64 (R * V + 1,)    start of each (record, view) in ``points``
video_frames  int64 (R,)            video frame index of each record
parities      int8 (R,)             field parity of each record (0 even rows, 1 odd rows),
                                    -1 for whole frames
metadata      str (0-d)             JSON: format, version, settings and their hash, videos,
                                    frame rate, frame range, truncation
============  ====================  ==========================================================

The metadata records what is needed to tell stale detections (:func:`check_fresh`): the
detection settings (views, filters, markers, de-interlacing) with their SHA-256, and the
identity of each source video (name, path relative to the detections file when saved by
:func:`videotrack.detect.run.detect_project`, bytes, frame size, frame count, fps and the SHA-256
of its content, :func:`videotrack.project.identity.video_hash`). It also keeps what went wrong while
detecting, so later runs still report it: ``warnings`` (messages, paths relative to the
file's folder) and ``broken`` (videos that could not be read to their end: name, the frame
where decoding stopped, the frames announced, and for an image folder the image).
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kinematics.fileio import atomic_write
from videotrack.detect.deinterlace import NO_DEINTERLACE, Deinterlace
from videotrack.detect.filters import FilterChain
from videotrack.detect.markers import MarkerSettings
from videotrack.detect.views import View
from videotrack.errors import VideoTrackError

FORMAT = "videotrack-detections"
VERSION = 1
_ARRAYS = ("points", "areas", "offsets", "video_frames", "parities")


@dataclass(frozen=True)
class DetectSettings:
    """Everything that decides the detections of a video: views, filters, markers, fields."""

    views: tuple[View, ...]
    filters: FilterChain
    markers: MarkerSettings = field(default_factory=MarkerSettings)
    deinterlace: Deinterlace = NO_DEINTERLACE

    def __post_init__(self) -> None:
        object.__setattr__(self, "views", tuple(self.views))

    def to_dict(self) -> dict:
        """JSON-able settings as stored in the detections file."""
        return {
            "views": [v.to_dict() for v in self.views],
            "filters": self.filters.to_settings(),
            "markers": self.markers.to_dict(),
            "deinterlace": self.deinterlace.to_dict(),
        }

    def hash(self) -> str:
        """SHA-256 of the canonical JSON of :meth:`to_dict`."""
        return settings_hash(self.to_dict())


def settings_hash(settings: dict) -> str:
    text = json.dumps(settings, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True, eq=False)
class Detections:
    """Marker centroids of every record (frame or half-frame) and view; see the module doc."""

    points: np.ndarray
    areas: np.ndarray
    offsets: np.ndarray
    video_frames: np.ndarray
    parities: np.ndarray
    metadata: dict
    path: Path | None = None

    def __post_init__(self) -> None:
        problem = _layout_problem(self.points, self.areas, self.offsets, self.video_frames,
                                  self.parities, len(self.metadata.get("view_names", [])))
        if problem:
            raise VideoTrackError(f"inconsistent detections: {problem}", file=self.path)

    @property
    def view_names(self) -> list[str]:
        return list(self.metadata["view_names"])

    @property
    def n_views(self) -> int:
        return len(self.metadata["view_names"])

    @property
    def n_records(self) -> int:
        return len(self.video_frames)

    @property
    def frame_rate(self) -> float:
        """Records per second (twice the video's fps when de-interlaced)."""
        return float(self.metadata["frame_rate"])

    @property
    def times(self) -> np.ndarray:
        """Time of each record in seconds from the video's start, shape (R,)."""
        fps = self.metadata["videos"][0]["fps"]
        order = np.array(self.metadata["settings"]["deinterlace"]["field_order"] == "bottom")
        half = np.where(self.parities < 0, 0.0, np.where(order, 1 - self.parities,
                                                         self.parities) * 0.5)
        return (self.video_frames + half) / fps

    def counts(self) -> np.ndarray:
        """Markers per record and view, shape (R, V)."""
        return np.diff(self.offsets).reshape(self.n_records, self.n_views)

    def view_index(self, view: int | str) -> int:
        if isinstance(view, str):
            if view not in self.view_names:
                raise KeyError(f"no view {view!r}; views: {self.view_names}")
            return self.view_names.index(view)
        return int(view)

    def points_of(self, record: int, view: int | str) -> np.ndarray:
        """Centroids of one record and view, shape (n, 2) (a view into :attr:`points`)."""
        k = record * self.n_views + self.view_index(view)
        return self.points[self.offsets[k] : self.offsets[k + 1]]

    def areas_of(self, record: int, view: int | str) -> np.ndarray:
        k = record * self.n_views + self.view_index(view)
        return self.areas[self.offsets[k] : self.offsets[k + 1]]


def _layout_problem(points, areas, offsets, video_frames, parities, n_views) -> str | None:
    if points.ndim != 2 or points.shape[1] != 2 or points.dtype != np.float64:
        return f"points must be float64 (n, 2), got {points.dtype} {points.shape}"
    if areas.shape != (len(points),):
        return f"areas has shape {areas.shape}, points {points.shape}"
    if video_frames.ndim != 1 or parities.shape != video_frames.shape:
        return "video_frames and parities must be 1-D of the same length"
    if n_views < 1:
        return "no views"
    if offsets.shape != (len(video_frames) * n_views + 1,):
        return (f"offsets has {offsets.size} entries, expected records x views + 1 = "
                f"{len(video_frames) * n_views + 1}")
    if offsets[0] != 0 or offsets[-1] != len(points) or np.any(np.diff(offsets) < 0):
        return "offsets must rise from 0 to the number of points"
    if len(video_frames) and (video_frames.min() < 0 or video_frames.max() >= 2**53
                              or np.any(np.diff(video_frames) < 0)):
        return "video_frames must be frame numbers from 0 on, in order"
    if np.any((parities < -1) | (parities > 1)):
        return "parities must be -1 (a whole frame), 0 or 1 (a field)"
    return None  # (non-finite points are a warning of the fit: fit_warnings)


def _positive(value) -> bool:
    """Whether ``value`` (read from JSON) is a finite number > 0."""
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and np.isfinite(value) and value > 0)


def _metadata_problem(meta: dict) -> str | None:
    """What is wrong with the parts of a detections file's metadata that are read (a file
    edited by hand or damaged), or None."""
    names = meta.get("view_names")
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        return "view_names must be a list of names"
    if not _positive(meta.get("frame_rate")):
        return f"frame_rate must be a number > 0, got {meta.get('frame_rate')!r}"
    videos = meta.get("videos")
    if (not isinstance(videos, list) or not videos
            or not all(isinstance(v, dict) and _positive(v.get("fps")) for v in videos)):
        return "videos must be a list of tables, each with its fps (a number > 0)"
    settings = meta.get("settings")
    if not isinstance(settings, dict) or not isinstance(
            (settings.get("deinterlace") or {}).get("field_order"), str):
        return "settings must be a table with deinterlace.field_order"
    broken = meta.get("broken") or []
    if not isinstance(broken, list) or not all(
            isinstance(b, dict) and isinstance(b.get("video"), str)
            and isinstance(b.get("frame"), int) and isinstance(b.get("announced"), int)
            and isinstance(b.get("file"), str | None) for b in broken):
        return "broken must be a list of tables with video, frame, announced and file"
    frames = meta.get("frames")
    if not (isinstance(frames, list) and len(frames) == 2
            and all(isinstance(f, int) and not isinstance(f, bool) for f in frames)):
        return f"frames must be the first and the end frame, got {frames!r}"
    warned = meta.get("warnings") or []
    if not isinstance(warned, list) or not all(isinstance(w, str) for w in warned):
        return "warnings must be a list of texts"
    return None


def build_detections(per_record: list[list[tuple[np.ndarray, np.ndarray]]],
                     video_frames, parities, metadata: dict) -> Detections:
    """Pack per-record, per-view ``(points, areas)`` lists into a :class:`Detections`."""
    counts = [len(p) for rec in per_record for p, _ in rec]
    flat_p = [p for rec in per_record for p, _ in rec]
    flat_a = [a for rec in per_record for _, a in rec]
    offsets = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    return Detections(
        points=np.concatenate(flat_p).astype(np.float64).reshape(-1, 2)
        if flat_p else np.empty((0, 2)),
        areas=np.concatenate(flat_a).astype(np.int64) if flat_a else np.empty(0, np.int64),
        offsets=offsets,
        video_frames=np.asarray(video_frames, np.int64),
        parities=np.asarray(parities, np.int8),
        metadata=metadata,
    )


def save_detections(detections: Detections, path: str | os.PathLike) -> Path:
    """Write ``detections`` to ``path`` (.npz) atomically: a temporary file in the same folder
    replaces the target only when complete, so a failed write leaves no partial file.

    Returns the path written.
    """
    path = Path(path)
    meta = json.dumps(detections.metadata, sort_keys=True)
    with atomic_write(path, "wb") as fh:
        np.savez_compressed(fh, metadata=np.array(meta),
                            **{k: getattr(detections, k) for k in _ARRAYS})
    return path


def load_detections(path: str | os.PathLike) -> Detections:
    """Read a detections file written by :func:`save_detections` (exact round trip).

    Raises
    ------
    VideoTrackError
        Missing file, not a detections file, unknown version, inconsistent arrays.
    """
    path = Path(path)
    if path.is_file() and not zipfile.is_zipfile(path):
        raise VideoTrackError("not a detections file (not an .npz archive)", file=path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in (*_ARRAYS, "metadata") if k not in data.files]
            if missing:
                raise VideoTrackError(f"not a detections file (no {missing[0]!r} array)",
                                      file=path)
            arrays = {k: data[k] for k in _ARRAYS}
            meta_text = str(data["metadata"])
    except FileNotFoundError:
        raise VideoTrackError("no such detections file", file=path) from None
    except (OSError, ValueError, zipfile.BadZipFile) as err:
        raise VideoTrackError(f"cannot read detections file: {err}", file=path) from None
    try:
        metadata = json.loads(meta_text)
    except json.JSONDecodeError as err:
        raise VideoTrackError(f"metadata is not JSON: {err}", file=path) from None
    if not isinstance(metadata, dict) or metadata.get("format") != FORMAT:
        found = metadata.get("format") if isinstance(metadata, dict) else None
        raise VideoTrackError(f"not a detections file (format {found!r})",
                              file=path)
    if metadata.get("version") != VERSION:
        raise VideoTrackError(
            f"detections format version {metadata.get('version')} is not supported "
            f"(this VideoTrack reads version {VERSION}); re-run 'videotrack detect'", file=path)
    problem = _metadata_problem(metadata)
    if problem:
        raise VideoTrackError(f"damaged detections file: {problem}; re-run 'videotrack "
                              "detect --force'", file=path, field="metadata")
    return Detections(**arrays, metadata=metadata, path=path)


def check_fresh(detections: Detections, videos, settings: DetectSettings,
                frames: range | None = None) -> None:
    """Raise if ``detections`` were not made from ``videos`` with ``settings``.

    Parameters
    ----------
    detections : Detections
    videos : VideoSet or VideoSource
        The video(s) the detections should come from (compared by bytes, frame size, frame
        count, fps and the SHA-256 of the content; name and folder may differ).
    settings : DetectSettings
        Compared by hash.
    frames : range, optional
        Frames the detections must cover.

    Raises
    ------
    VideoTrackError
        Stale detections, saying what differs; field ``settings``, ``video`` or ``frames``.
    """
    from videotrack.detect.video import as_video_set
    from videotrack.project.identity import video_hash

    meta = detections.metadata
    where = detections.path
    stored = meta.get("settings", {})
    if meta.get("settings_hash") != settings.hash():
        current = settings.to_dict()
        changed = [k for k in current if current[k] != stored.get(k)] or ["settings"]
        raise VideoTrackError(
            f"stale detections: made with other {', '.join(changed)} settings; run "
            "'videotrack detect --force' to redo them", file=where, field="settings")
    video_set = as_video_set(videos)
    now = video_set.identity()
    before = meta.get("videos", [])
    if len(now) != len(before):
        raise VideoTrackError(
            f"stale detections: made from {len(before)} video(s), now {len(now)}",
            file=where, field="video")
    for old, new, source in zip(before, now, video_set.sources, strict=True):
        differ = [k for k in ("bytes", "width", "height", "frames", "fps")
                  if old.get(k) != new[k]]
        if differ:
            detail = ", ".join(f"{k} {old.get(k)!r} -> {new[k]!r}" for k in differ)
            raise VideoTrackError(
                f"stale detections: made from another video ({detail})", file=where,
                field="video")
        if "sha256" not in old:
            raise VideoTrackError(
                "stale detections: made by an earlier VideoTrack that did not record the "
                "video's content hash", file=where, field="video")
        if old["sha256"] != video_hash(source.path):
            raise VideoTrackError(
                f"stale detections: made from another video of the same size "
                f"({new['name']}: other content)", file=where, field="video")
    if frames is not None and len(frames):
        start, stop = meta["frames"]
        wanted_stop = frames.stop
        if meta.get("broken_at") is not None:  # the same truncated video cannot give more
            wanted_stop = min(wanted_stop, meta["broken_at"])
        if frames.start < start or wanted_stop > stop:
            raise VideoTrackError(
                f"detections cover frames {start}:{stop}, not {frames.start}:{frames.stop}",
                file=where, field="frames")
