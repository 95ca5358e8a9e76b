"""OpenSim marker files (``.trc``): 3D points per frame, tab-separated.

Five header lines (file type; the names of the values; rate, counts, units; marker names,
each over its X/Y/Z columns; ``X1 Y1 Z1 ...``), then one row per frame: the 1-based frame
number, the time in seconds and X, Y, Z per marker. A missing point is empty fields.
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
class Markers3D:
    """3D marker trajectories: names, frame numbers (0-based), points (n_frames, n, 3)."""

    names: tuple[str, ...]
    frames: np.ndarray
    points: np.ndarray
    rate: float
    units: str


def _num(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.6f}"


def write_trc(path: str | os.PathLike, names, points, frames, rate: float,
              units: str = "mm") -> None:
    """Write 3D points (n_frames, n_markers, 3) in ``units`` to an OpenSim TRC file.

    Frame numbers are VideoTrack's 0-based ones; the file numbers them from 1 and gives
    ``OrigDataStartFrame`` as the first frame + 1, as OpenSim does.
    """
    points = np.asarray(points, dtype=np.float64)
    names = column_names(names, path)
    frames, times = frame_times(frames, rate)
    if points.ndim != 3 or points.shape[1:] != (len(names), 3) or len(points) != len(frames):
        raise VideoTrackError(f"points of shape {points.shape} do not match {len(frames)} "
                              f"frames x {len(names)} markers x 3", file=path)
    bad = [n for n in names if not n or any(c in n for c in "\t\r\n")]
    if bad:
        raise VideoTrackError(f"marker name {bad[0]!r} cannot be written to a TRC file",
                              file=path)
    n, m = len(frames), len(names)
    start = int(frames[0]) + 1 if n else 1
    head = [
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t"
        "OrigDataStartFrame\tOrigNumFrames",
        f"{rate:g}\t{rate:g}\t{n}\t{m}\t{units}\t{rate:g}\t{start}\t{n}",
        "Frame#\tTime\t" + "\t".join(f"{name}\t\t" for name in names).rstrip("\t"),
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, m + 1)),
        "",
    ]
    with atomic_write(path) as fh:
        fh.write("\n".join(head) + "\n")
        for f, t, row in zip(frames, times, points.reshape(n, -1), strict=True):
            fh.write(f"{f + 1}\t{t:.6f}\t" + "\t".join(_num(v) for v in row) + "\n")


def read_trc(path: str | os.PathLike) -> Markers3D:
    """Read an OpenSim TRC file (ours, Pose2Sim's, OpenSim's examples)."""
    try:
        lines = Path(path).read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise VideoTrackError(f"cannot read: {e}", file=path) from None
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise VideoTrackError("not a TRC file: no 'PathFileType' line", file=path, line=1)
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    info = dict(zip((k.strip() for k in keys), (v.strip() for v in values), strict=False))
    try:
        rate = float(info["DataRate"])
        n_markers = int(info["NumMarkers"])
    except (KeyError, ValueError):
        raise VideoTrackError("no DataRate/NumMarkers", file=path, line=3) from None
    cells = lines[3].split("\t")
    names = tuple(c.strip() for c in cells[2:] if c.strip())
    if len(names) != n_markers:
        raise VideoTrackError(f"{len(names)} marker names, NumMarkers says {n_markers}",
                              file=path, line=4)
    frames, rows = [], []
    for ln, line in enumerate(lines[5:], 6):
        if not line.strip():
            continue
        cells = line.split("\t")
        try:
            frames.append(int(float(cells[0])) - 1)
            vals = [float(c) if c.strip() else np.nan for c in cells[2:2 + 3 * n_markers]]
        except (ValueError, IndexError):
            raise VideoTrackError("not a number", file=path, line=ln) from None
        vals += [np.nan] * (3 * n_markers - len(vals))
        rows.append(vals)
    points = np.asarray(rows, dtype=np.float64).reshape(len(rows), n_markers, 3)
    return Markers3D(names, np.asarray(frames, np.int64), points, rate,
                     info.get("Units", ""))
