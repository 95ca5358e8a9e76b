"""OpenSim motion files (``.mot``): joint angles (or any coordinates) per time, in degrees.

A header ending in ``endheader`` (name, ``version=1``, ``nRows``, ``nColumns`` counting the
time column, ``inDegrees=yes``), then a tab-separated table with a ``time`` column.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinematics.fileio import atomic_write
from videotrack.errors import VideoTrackError
from videotrack.io._files import column_names, frame_times


@dataclass(frozen=True, eq=False)
class Motion:
    """Columns of a motion file: names, times (n,), values (n, n_columns), in degrees?"""

    names: tuple[str, ...]
    time: np.ndarray
    values: np.ndarray
    in_degrees: bool


def write_mot(path: str | os.PathLike, names, angles, frames, rate: float,
              title: str = "Coordinates") -> None:
    """Write joint angles (n_frames, n_columns) in degrees; missing values as ``nan``
    (OpenSim reads them as NaN)."""
    angles = np.asarray(angles, dtype=np.float64)
    names = column_names(names, path, "column")
    frames, times = frame_times(frames, rate)
    if angles.shape != (len(frames), len(names)):
        raise VideoTrackError(f"angles of shape {angles.shape} do not match {len(frames)} "
                              f"frames x {len(names)} columns", file=path)
    bad = [n for n in names if not n or any(c.isspace() for c in n)]
    if bad:
        raise VideoTrackError(f"column name {bad[0]!r} cannot be written to a .mot file",
                              file=path)
    head = [title, "version=1", f"nRows={len(frames)}", f"nColumns={len(names) + 1}",
            "inDegrees=yes", "", "Angles are in degrees.", "", "endheader",
            "time\t" + "\t".join(names)]
    with atomic_write(path) as fh:
        fh.write("\n".join(head) + "\n")
        for t, row in zip(times, angles, strict=True):
            fh.write(f"{t:.6f}\t" + "\t".join(f"{v:.6f}" if np.isfinite(v) else "nan"
                                              for v in row) + "\n")


def read_mot(path: str | os.PathLike) -> Motion:
    """Read an OpenSim ``.mot``/``.sto`` table (ours or OpenSim's)."""
    try:
        lines = Path(path).read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise VideoTrackError(f"cannot read: {e}", file=path) from None
    try:
        end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    except StopIteration:
        raise VideoTrackError("not an OpenSim motion file: no 'endheader' line",
                              file=path) from None
    header = {k.strip().lower(): v.strip() for k, _, v in
              (line.partition("=") for line in lines[:end] if "=" in line)}
    in_degrees = header.get("indegrees", "yes").lower() == "yes"
    if end + 1 >= len(lines):
        raise VideoTrackError("no column names after 'endheader'", file=path, line=end + 1)
    names = lines[end + 1].split()
    if not names or names[0].lower() != "time":
        raise VideoTrackError("the first column must be 'time'", file=path, line=end + 2)
    rows = []
    for ln, line in enumerate(lines[end + 2:], end + 3):
        if not line.strip():
            continue
        cells = line.split()
        if len(cells) != len(names):
            raise VideoTrackError(f"{len(cells)} values, {len(names)} columns", file=path,
                                  line=ln)
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            raise VideoTrackError("not a number", file=path, line=ln) from None
    data = np.asarray(rows, dtype=np.float64).reshape(len(rows), len(names))
    return Motion(tuple(names[1:]), data[:, 0], data[:, 1:], in_degrees)
