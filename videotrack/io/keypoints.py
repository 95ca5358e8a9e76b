"""The keypoint façade: 2D keypoints of one camera from any pose-estimation tool.

:func:`read_keypoints` detects the file's format and hands it to the reader of that format
(one module per format under ``videotrack.io``); every reader returns a :class:`KeypointTracks`
in the same conventions: pixels of the full image, NaN where a keypoint is missing, scores in
[0, 1], frame numbers of the video. :func:`align_cameras` puts several cameras on common frames
and :func:`map_to_markers` renames keypoints to the chain's markers.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from videotrack.errors import VideoTrackError


@dataclass(frozen=True)
class KeypointFormat:
    """One keypoint file format of :data:`KEYPOINT_FORMATS`.

    ``module`` is the reader module under :mod:`videotrack.io` (imported when a file is
    read), whose ``read(path, individual=..., **options)`` returns a :class:`KeypointTracks`;
    ``options`` are the keywords of :func:`read_keypoints` it takes besides ``individual``.
    ``suffixes`` are the file suffixes it reads and ``folder`` whether it reads a folder.
    ``detect`` says whether :func:`detect_format` chooses it. A suffix one detected format
    alone reads is that format's; where several share one, the formats with ``sniff`` (a
    function of ``module`` telling from the file's content whether it is one) are asked in
    registry order, and the one without is the fallback. ``files`` names its files in
    messages.
    """

    name: str
    module: str
    suffixes: tuple[str, ...]
    files: str
    folder: bool = False
    sniff: str | None = None
    options: tuple[str, ...] = ()
    detect: bool = True

    def reader(self):
        """The reader module (``read``, and ``sniff`` where set)."""
        return importlib.import_module(f"videotrack.io.{self.module}")

    def claims(self, path: Path) -> bool:
        """Whether a folder or a file of this format's suffixes may be of this format."""
        return self.detect and (self.folder if path.is_dir()
                                else path.suffix.lower() in self.suffixes)

    def sniffs(self, path: Path) -> bool:
        """Whether this format's content test (``sniff``) takes ``path``."""
        return self.sniff is not None and bool(getattr(self.reader(), self.sniff)(path))


_H5 = (".h5", ".hdf5", ".hdf")

#: The keypoint formats, by the name ``--format`` and ``[keypoints] format`` give: the one
#: registry the CLI's choices, the config's validation, :func:`detect_format` and
#: :func:`read_keypoints` read. An ``anipose`` pose-2d file is a DeepLabCut h5 (read by the
#: DeepLabCut reader, detected as ``dlc``).
KEYPOINT_FORMATS: dict[str, KeypointFormat] = {f.name: f for f in (
    KeypointFormat("dlc", "dlc", (*_H5, ".csv"), "DeepLabCut .h5/.csv"),
    KeypointFormat("sleap", "sleap", (".slp", *_H5), "SLEAP .slp/.h5", sniff="is_analysis_h5"),
    KeypointFormat("openpose", "openpose", (".json",), "an OpenPose JSON folder",
                   folder=True, options=("model",)),
    KeypointFormat("lightning-pose", "lightning_pose", (".csv",), "a Lightning Pose .csv",
                   sniff="is_lightning_pose_csv"),
    KeypointFormat("anipose", "dlc", _H5, "an Anipose pose-2d .h5", detect=False),
)}

#: Format names :func:`read_keypoints` accepts (the keys of :data:`KEYPOINT_FORMATS`).
FORMATS = tuple(KEYPOINT_FORMATS)


@dataclass(frozen=True, eq=False)
class KeypointTracks:
    """2D keypoints of one camera.

    Attributes
    ----------
    names : keypoint (body part) names
    xy : (n_frames, n_keypoints, 2) float64 pixels in the full image, NaN = missing
    score : (n_frames, n_keypoints) float64 in [0, 1], NaN where missing
    frames : (n_frames,) int64 frame numbers in the video
    source : the file it came from (for messages)
    candidates : optional (n_frames, n_candidates, n_keypoints, 3) x, y, score of other
        detections of the same keypoints (other animals or people), for the Viterbi filter
    individual : the individual (animal, track, person) these keypoints belong to, if chosen
    images : the rows are labelled images (a DeepLabCut ``CollectedData`` file), not a
        video's frames: their numbers come from the images' names, and images picked from
        a video are not neighbours in time
    """

    names: tuple[str, ...]
    xy: np.ndarray
    score: np.ndarray
    frames: np.ndarray
    source: str
    candidates: np.ndarray | None = None
    individual: str | None = None
    images: bool = False

    def __post_init__(self):
        n, k = len(self.frames), len(self.names)
        if self.xy.shape != (n, k, 2) or self.score.shape != (n, k):
            raise VideoTrackError(f"keypoints of shape {self.xy.shape} and scores of shape "
                                  f"{self.score.shape} do not match {n} frames x {k} keypoints",
                                  file=self.source)
        if len(set(self.names)) != k:
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise VideoTrackError(f"keypoint names repeat: {', '.join(dup)}", file=self.source)

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    @property
    def missing(self) -> np.ndarray:
        """(n_frames, n_keypoints) bool: keypoint not detected."""
        return ~np.isfinite(self.xy).all(axis=2)

    def replace(self, **changes) -> KeypointTracks:
        """A copy with some fields replaced."""
        from dataclasses import replace
        return replace(self, **changes)


def make_tracks(names, xy, score, frames, source, **extra) -> KeypointTracks:
    """Build :class:`KeypointTracks` in the common conventions from a reader's raw arrays:
    a point is missing where a coordinate or its score is not finite, scores are clipped to
    [0, 1] and NaN where missing, frames are int64 and sorted."""
    xy = np.array(xy, dtype=np.float64)
    score = np.array(score, dtype=np.float64)
    frames = np.asarray(frames, dtype=np.int64)
    order = np.argsort(frames, kind="stable")
    if np.any(np.diff(frames[order]) == 0):
        raise VideoTrackError("a frame appears twice", file=source)
    xy, score, frames = xy[order], score[order], frames[order]
    missing = ~np.isfinite(xy).all(axis=2) | ~np.isfinite(score)
    xy[missing] = np.nan
    score = np.clip(score, 0.0, 1.0)
    score[missing] = np.nan
    return KeypointTracks(tuple(str(n) for n in names), xy, score, frames, str(source), **extra)


def detect_format(path: str | os.PathLike) -> str:
    """The format of a keypoint file or folder (one of :data:`FORMATS`), from its suffix and,
    where formats share one, its content (:attr:`KeypointFormat.sniff`)."""
    path = Path(path)
    if not path.is_dir() and not path.is_file():
        raise VideoTrackError("no such keypoint file or folder", file=path)
    claims = [f for f in KEYPOINT_FORMATS.values() if f.claims(path)]
    if len(claims) == 1:
        return claims[0].name
    for fmt in claims:  # a suffix several formats share: content tests, then the fallback
        if fmt.sniffs(path):
            return fmt.name
    fallback = [f for f in claims if f.sniff is None]
    if fallback:
        return fallback[0].name
    files = [f.files for f in KEYPOINT_FORMATS.values() if f.detect]
    raise VideoTrackError("unknown keypoint file type (expected "
                          f"{', '.join(files[:-1])} or {files[-1]})", file=path)


def read_keypoints(path: str | os.PathLike, format: str | None = None, *,
                   individual: str | int | None = None, crop_offset=(0.0, 0.0),
                   frame_offset: int = 0, model: str | None = None) -> KeypointTracks:
    """Read the 2D keypoints of one camera.

    Parameters
    ----------
    path : a DeepLabCut/Anipose ``.h5``/``.csv``, SLEAP ``.slp``/analysis ``.h5``, a folder
        of OpenPose JSON files (one per frame) or a Lightning Pose ``.csv``
    format : one of :data:`FORMATS`; detected from the file when None
    individual : the animal/track/person: a name or an index; default the first (OpenPose:
        the person with the largest bounding box; ``"confident"`` the most confident one)
    crop_offset : (x, y) pixels added to every keypoint (the tracker ran on a cropped video)
    frame_offset : added to every frame number (the tracked video started later)
    model : OpenPose keypoint model (``BODY_25``, ``BODY_25B``, ``COCO``) naming the points

    Raises
    ------
    VideoTrackError
        A one-line error naming the file (and line or field) for an unreadable file.
    """
    name = detect_format(path) if format is None else str(format).lower().replace("_", "-")
    if name not in KEYPOINT_FORMATS:
        raise VideoTrackError(f"unknown keypoint format {format!r} (one of "
                              f"{', '.join(FORMATS)})", file=path, field="format")
    fmt = KEYPOINT_FORMATS[name]
    options = {k: v for k, v in {"model": model}.items() if k in fmt.options}
    tracks = fmt.reader().read(Path(path), individual=individual, **options)
    return shift(tracks, crop_offset, frame_offset)


def shift(tracks: KeypointTracks, crop_offset=(0.0, 0.0), frame_offset: int = 0
          ) -> KeypointTracks:
    """Move keypoints from a cropped video into the full image and renumber the frames."""
    off = np.asarray(crop_offset, dtype=np.float64)
    if off.shape != (2,) or not np.all(np.isfinite(off)):
        raise VideoTrackError(f"crop offset must be two numbers (x, y), got {crop_offset!r}",
                              file=tracks.source, field="crop_offset")
    if int(frame_offset) != frame_offset:
        raise VideoTrackError(f"frame offset must be an integer, got {frame_offset!r}",
                              file=tracks.source, field="frame_offset")
    if not off.any() and not frame_offset:
        return tracks
    cand = tracks.candidates
    if cand is not None:
        cand = cand.copy()
        cand[..., :2] += off
    return tracks.replace(xy=tracks.xy + off, frames=tracks.frames + int(frame_offset),
                          candidates=cand)


def align_cameras(tracks: Mapping[str, KeypointTracks], names: Sequence[str] | None = None
                  ) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, np.ndarray]:
    """Put the keypoints of several cameras on common frames and keypoints.

    Parameters
    ----------
    tracks : camera name -> its keypoints (the cameras' order is kept)
    names : the keypoints to keep, in this order; default every keypoint of any camera, in
        order of first appearance. A camera without one of them has it missing.

    Returns
    -------
    names : tuple of str
    frames : (n_frames,) int64, the union of the cameras' frames
    xy : (n_cams, n_frames, n_kp, 2), NaN-filled
    score : (n_cams, n_frames, n_kp), NaN-filled
    """
    cams = list(tracks.values())
    if not cams:
        raise VideoTrackError("no cameras to align", field="keypoints")
    if names is None:
        names = list(dict.fromkeys(n for t in cams for n in t.names))
    else:
        names = [str(n) for n in names]
        known = {n for t in cams for n in t.names}
        unknown = [n for n in names if n not in known]
        if unknown:
            raise VideoTrackError(f"no camera has keypoint(s) {', '.join(unknown)}",
                                  file=cams[0].source, field="keypoints")
    frames = np.unique(np.concatenate([t.frames for t in cams])).astype(np.int64)
    xy = np.full((len(cams), len(frames), len(names), 2), np.nan)
    score = np.full((len(cams), len(frames), len(names)), np.nan)
    for c, t in enumerate(cams):
        rows = np.searchsorted(frames, t.frames)
        pos = {n: i for i, n in enumerate(t.names)}
        dst = [j for j, n in enumerate(names) if n in pos]
        src = [pos[names[j]] for j in dst]
        xy[c, rows[:, None], np.asarray(dst, dtype=np.intp)[None, :]] = t.xy[:, src]
        score[c, rows[:, None], np.asarray(dst, dtype=np.intp)[None, :]] = t.score[:, src]
    return tuple(names), frames, xy, score


def marker_index(keypoint_names: Sequence[str], marker_names: Sequence[str],
                 mapping: Mapping[str, str] | None = None, *, source: str | None = None
                 ) -> np.ndarray:
    """For each chain marker the index of its keypoint, -1 for markers without one.

    ``mapping`` is keypoint name -> marker name (the project's ``[keypoints] markers`` table);
    without it a keypoint maps to the marker of the same name.
    """
    keypoint_names = [str(n) for n in keypoint_names]
    marker_names = [str(m) for m in marker_names]
    if mapping is None:
        mapping = {n: n for n in keypoint_names if n in marker_names}
    kp_pos = {n: i for i, n in enumerate(keypoint_names)}
    index = np.full(len(marker_names), -1, dtype=np.intp)
    m_pos = {m: i for i, m in enumerate(marker_names)}
    for kp, marker in mapping.items():
        if kp not in kp_pos:
            raise VideoTrackError(f"keypoint {kp!r} is not in the keypoint file (it has "
                                  f"{', '.join(keypoint_names)})", file=source,
                                  field="keypoints.markers")
        if marker not in m_pos:
            raise VideoTrackError(f"marker {marker!r} (for keypoint {kp!r}) is not a marker "
                                  "of the chain", file=source, field="keypoints.markers")
        if index[m_pos[marker]] >= 0:
            raise VideoTrackError(f"marker {marker!r} is given two keypoints", file=source,
                                  field="keypoints.markers")
        index[m_pos[marker]] = kp_pos[kp]
    if not np.any(index >= 0):
        raise VideoTrackError("no keypoint maps to a marker of the chain (name them alike or "
                              "map them in [keypoints] markers)", file=source,
                              field="keypoints.markers")
    return index


def map_to_markers(tracks: KeypointTracks, marker_names: Sequence[str],
                   mapping: Mapping[str, str] | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The keypoints in the chain's marker order.

    Returns ``xy`` (n_frames, n_markers, 2) and ``score`` (n_frames, n_markers), NaN for
    markers without a keypoint. See :func:`marker_index` for ``mapping``.
    """
    index = marker_index(tracks.names, marker_names, mapping, source=tracks.source)
    xy = np.full((tracks.n_frames, len(index), 2), np.nan)
    score = np.full((tracks.n_frames, len(index)), np.nan)
    has = index >= 0
    xy[:, has] = tracks.xy[:, index[has]]
    score[:, has] = tracks.score[:, index[has]]
    return xy, score


#: Version of the keypoints ``.npz`` written by :func:`write_npz`.
NPZ_FORMAT = 1


def write_npz(path: str | os.PathLike, tracks: Mapping[str, KeypointTracks]) -> None:
    """Write the keypoints of several cameras, aligned (:func:`align_cameras`), to one
    ``.npz``: ``cameras`` (n_cams,), ``names`` (n_kp,), ``frames`` (n_frames,), ``xy``
    (n_cams, n_frames, n_kp, 2) and ``score`` (n_cams, n_frames, n_kp), NaN where missing,
    ``sources`` (n_cams,) and ``keypoints_format`` (its version)."""
    from kinematics.fileio import atomic_write

    names, frames, xy, score = align_cameras(tracks)
    with atomic_write(path, "wb") as fh:
        np.savez_compressed(fh, keypoints_format=np.int64(NPZ_FORMAT),
                            cameras=np.array(list(tracks), dtype=str),
                            names=np.array(names, dtype=str), frames=frames, xy=xy,
                            score=score,
                            sources=np.array([t.source for t in tracks.values()], dtype=str))


def read_npz(path: str | os.PathLike) -> dict[str, KeypointTracks]:
    """The cameras' keypoints of a file written by :func:`write_npz`."""
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as z:
            if "keypoints_format" not in z.files:
                raise VideoTrackError("not a keypoints .npz (no 'keypoints_format')", file=path)
            data = {k: z[k] for k in ("cameras", "names", "frames", "xy", "score")}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as e:
        raise VideoTrackError(f"not a keypoints .npz ({e})", file=path) from None
    names = tuple(str(n) for n in data["names"])
    return {str(cam): KeypointTracks(names, data["xy"][c], data["score"][c],
                                     data["frames"].astype(np.int64), str(path))
            for c, cam in enumerate(data["cameras"])}
