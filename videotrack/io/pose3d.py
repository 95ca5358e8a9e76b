"""Anipose's ``pose-3d`` CSV: triangulated 3D points, one row per frame.

Columns, as ``anipose triangulate`` writes them: for every body part ``<bp>_x, <bp>_y,
<bp>_z, <bp>_error, <bp>_ncams, <bp>_score``; then ``M_00 .. M_22`` and ``center_0 .. 2``
(Anipose's optional alignment of the axes: the stored points are ``p @ M.T - center``, M the
identity and center 0 without it) and ``fnum`` (frame number). Missing values are empty
fields, as pandas writes NaN. Any extra column is ignored when reading.
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass

import numpy as np

from kinematics.fileio import atomic_write_text
from videotrack.errors import VideoTrackError
from videotrack.results.tables import read_table

__all__ = ["FIELDS", "Pose3D", "is_pose3d", "read_pose3d", "write_pose3d"]

#: Per-body-part column suffixes, in Anipose's order.
FIELDS = ("x", "y", "z", "error", "ncams", "score")


@dataclass(frozen=True, eq=False)
class Pose3D:
    """Contents of a pose-3d file.

    Attributes
    ----------
    names : body part names
    xyz : (n_frames, n_points, 3) as stored (aligned by M and center, if Anipose did)
    error : (n_frames, n_points) mean reprojection error, px
    ncams : (n_frames, n_points) float, cameras used (NaN where the file has none)
    score : (n_frames, n_points)
    frames : (n_frames,) int64 (``fnum``)
    M : (3, 3); center : (3,)
    """

    names: tuple[str, ...]
    xyz: np.ndarray
    error: np.ndarray
    ncams: np.ndarray
    score: np.ndarray
    frames: np.ndarray
    M: np.ndarray
    center: np.ndarray

    def world(self) -> np.ndarray:
        """The points in the calibration's frame, undoing Anipose's alignment."""
        return (self.xyz + self.center) @ self.M


def _number(value: float) -> str:
    return "" if not np.isfinite(value) else repr(float(value))


def write_pose3d(path: str | os.PathLike, names, xyz, error, ncams, score, frames=None, *,
                 M=None, center=None) -> None:
    """Write a pose-3d CSV atomically (a temporary file, then renamed).

    Parameters
    ----------
    names : n_points body part names
    xyz : (n_frames, n_points, 3); error, ncams, score : (n_frames, n_points)
    frames : (n_frames,) frame numbers (default 0, 1, ...)
    M, center : Anipose's axis alignment (default identity and 0): the points are written as
        given, M and center only recorded
    """
    names = [str(n) for n in names]
    xyz = np.asarray(xyz, dtype=np.float64)
    n_frames = xyz.shape[0]
    if xyz.shape != (n_frames, len(names), 3):
        raise VideoTrackError(f"expected points of shape (frames, {len(names)}, 3), got "
                              f"{xyz.shape}", file=path, field="xyz")
    per_point = [np.asarray(a, dtype=np.float64) for a in (error, ncams, score)]
    if any(a.shape != xyz.shape[:2] for a in per_point):
        raise VideoTrackError("error, ncams and score must have one value per frame and "
                              "point", file=path, field="xyz")
    frames = np.arange(n_frames) if frames is None else np.asarray(frames, dtype=np.int64)
    M = np.eye(3) if M is None else np.asarray(M, dtype=np.float64).reshape(3, 3)
    center = np.zeros(3) if center is None else np.asarray(center, dtype=np.float64).ravel()
    header = [f"{n}_{f}" for n in names for f in FIELDS]
    header += [f"M_{i}{j}" for i in range(3) for j in range(3)]
    header += [f"center_{i}" for i in range(3)] + ["fnum"]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    tail = [_number(v) for v in (*M.ravel(), *center)]
    for f in range(n_frames):
        row = []
        for p in range(len(names)):
            ncam = per_point[1][f, p]
            row += [_number(v) for v in xyz[f, p]]
            row += [_number(per_point[0][f, p]),
                    str(int(ncam)) if np.isfinite(ncam) else "", _number(per_point[2][f, p])]
        writer.writerow([*row, *tail, str(int(frames[f]))])
    atomic_write_text(path, out.getvalue())


def _header_names(header: list[str], path) -> list[str]:
    names = [h[: -len("_x")] for h in header if h.endswith("_x")]
    names = [n for n in names if all(f"{n}_{f}" in header for f in FIELDS)]
    if not names:
        raise VideoTrackError("not an Anipose pose-3d CSV: no <bodypart>_x/_y/_z/_error/"
                              "_ncams/_score columns", file=path, line=1)
    return names


def is_pose3d(path: str | os.PathLike) -> bool:
    """Whether ``path`` starts like a pose-3d CSV (the header has a full body part)."""
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            header = next(csv.reader(fh))
        _header_names(header, path)
    except (OSError, UnicodeDecodeError, StopIteration, csv.Error, VideoTrackError):
        return False
    return True


def read_pose3d(path: str | os.PathLike) -> Pose3D:
    """Read a pose-3d CSV (Anipose's or :func:`write_pose3d`'s).

    Raises
    ------
    VideoTrackError
        One line naming the file, line and column of a problem.
    """
    header, values = read_table(path)
    names = _header_names(header, path)
    col = {h: i for i, h in enumerate(header)}

    def take(suffix):
        return values[:, [col[f"{n}_{suffix}"] for n in names]]

    xyz = np.stack([take(a) for a in "xyz"], axis=-1)
    M = np.eye(3)
    center = np.zeros(3)
    if len(values) and all(f"M_{i}{j}" in col for i in range(3) for j in range(3)):
        M = values[0, [col[f"M_{i}{j}"] for i in range(3) for j in range(3)]].reshape(3, 3)
    if len(values) and all(f"center_{i}" in col for i in range(3)):
        center = values[0, [col[f"center_{i}"] for i in range(3)]]
    if "fnum" in col:
        fnum = values[:, col["fnum"]]
        if not np.all(np.isfinite(fnum) & (fnum == np.round(fnum))):
            raise VideoTrackError("fnum must hold whole frame numbers", file=path, field="fnum")
        frames = fnum.astype(np.int64)
    else:
        frames = np.arange(len(values), dtype=np.int64)
    return Pose3D(tuple(names), xyz, take("error"), take("ncams"), take("score"), frames,
                  M, center)
