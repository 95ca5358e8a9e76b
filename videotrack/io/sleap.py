"""SLEAP keypoints: a labels file (``.slp``, read with ``sleap-io``) or an analysis ``.h5``
(``sleap-convert --format analysis``, read with ``h5py``).

Every track is an individual; without tracks the instances of a frame are taken in their
order. Hand-labelled (user) points carry no score: they count as certain (score 1).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from videotrack.errors import VideoTrackError
from videotrack.io.keypoints import KeypointTracks, make_tracks


def is_analysis_h5(path: Path) -> bool:
    """Whether an HDF5 file is a SLEAP analysis file (it has ``tracks`` and ``node_names``)."""
    import h5py
    try:
        with h5py.File(path, "r") as f:
            return "tracks" in f and "node_names" in f
    except (OSError, RuntimeError, ValueError, KeyError):  # HDF5's errors on a damaged file
        return False


def read(path: Path, individual: str | int | None = None) -> KeypointTracks:
    """Read a SLEAP ``.slp`` or analysis ``.h5`` file."""
    if Path(path).suffix.lower() == ".slp":
        names, tracks, data = _read_slp(path)
    else:
        names, tracks, data = _read_analysis(path)
    # data: (n_frames, n_tracks, n_nodes, 3) x, y, score
    if data.shape[0] == 0 or data.shape[1] == 0:
        raise VideoTrackError("no labelled frames", file=path)
    user = np.isfinite(data[..., :2]).all(axis=3) & ~np.isfinite(data[..., 2])
    data[..., 2][user] = 1.0
    i = _choose(tracks, individual, path)
    others = [j for j in range(data.shape[1]) if j != i]
    candidates = data[:, others] if others else None
    return make_tracks(names, data[:, i, :, :2], data[:, i, :, 2], np.arange(len(data)), path,
                       candidates=candidates, individual=tracks[i])


def _choose(tracks: list[str], individual, path) -> int:
    if individual is None:
        return 0
    if isinstance(individual, (int, np.integer)) or str(individual).isdigit():
        i = int(individual)
        if 0 <= i < len(tracks):
            return i
        raise VideoTrackError(f"track {i} out of range (the file has {len(tracks)}: "
                              f"{', '.join(tracks)})", file=path, field="individual")
    if str(individual) in tracks:
        return tracks.index(str(individual))
    raise VideoTrackError(f"no track {individual!r} (the file has {', '.join(tracks)})",
                          file=path, field="individual")


def _read_slp(path):
    try:
        import sleap_io as sio
    except ImportError:
        raise VideoTrackError("reading SLEAP .slp needs the 'sleap-io' package (pip install "
                              "'videotrack[markerless]'; or export an analysis .h5)",
                              file=path) from None
    try:
        labels = sio.load_slp(str(path), open_videos=False)
    except Exception as e:  # sleap-io raises h5py/KeyError/ValueError for broken files
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise VideoTrackError(f"not a SLEAP labels file ({msg})", file=path) from None
    if len(labels.videos) != 1:
        raise VideoTrackError(f"holds {len(labels.videos)} videos: export one camera per "
                              "file (sleap-convert, or Labels.extract in sleap-io)", file=path)
    if not labels.labeled_frames:
        raise VideoTrackError("no labelled frames", file=path)
    tracked = bool(labels.tracks)
    data = labels.numpy(video=0, untracked=not tracked, return_confidence=True)
    data = np.asarray(data, dtype=np.float64)
    tracks = ([t.name for t in labels.tracks] if tracked
              else [f"instance{i}" for i in range(data.shape[1])])
    return list(labels.skeleton.node_names), tracks, data


def _read_analysis(path):
    import h5py
    try:
        with h5py.File(path, "r") as f:
            missing = [k for k in ("tracks", "node_names") if k not in f]
            if missing:
                raise VideoTrackError(f"not a SLEAP analysis file: no {missing[0]!r} dataset",
                                      file=path)
            tracks_xy = np.asarray(f["tracks"][()], dtype=np.float64)
            names = [_text(n) for n in f["node_names"][()]]
            scores = (np.asarray(f["point_scores"][()], dtype=np.float64)
                      if "point_scores" in f else None)
            track_names = ([_text(n) for n in f["track_names"][()]]
                           if "track_names" in f else [])
    except VideoTrackError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as e:
        raise VideoTrackError(f"not a SLEAP analysis file ({e})", file=path) from None
    # stored transposed (MATLAB order): tracks (n_tracks, 2, n_nodes, n_frames)
    if tracks_xy.ndim != 4 or tracks_xy.shape[1] != 2 or tracks_xy.shape[2] != len(names):
        raise VideoTrackError(f"tracks of shape {tracks_xy.shape}: expected (tracks, 2, "
                              f"{len(names)} nodes, frames)", file=path, field="tracks")
    n_tracks, _, n_nodes, n_frames = tracks_xy.shape
    data = np.empty((n_frames, n_tracks, n_nodes, 3))
    data[..., :2] = tracks_xy.transpose(3, 0, 2, 1)
    if scores is not None and scores.shape == (n_tracks, n_nodes, n_frames):
        data[..., 2] = scores.transpose(2, 0, 1)
    else:
        data[..., 2] = np.nan  # no scores: user labels
    if len(track_names) != n_tracks:
        track_names = [f"track_{i}" for i in range(n_tracks)]
    return names, track_names, data


def _text(value) -> str:
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)
