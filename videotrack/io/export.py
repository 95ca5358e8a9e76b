"""Export a results CSV's 3D points and joint angles for OpenSim, biomechanics tools,
movement and NWB: the writer is chosen by the output's suffix."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from videotrack.errors import VideoTrackError

#: Output suffix -> what it holds.
EXPORTS = {".trc": "3D points (OpenSim)", ".mot": "joint angles (OpenSim)",
           ".c3d": "3D points and joint angles",
           ".nwb": "3D points, joint angles and their sd (NWB, ndx-pose; movement loads it)"}


def export_results(results, path: str | os.PathLike, *, units: str = "mm",
                   only_ok: bool = True, subject: str = "animal") -> Path:
    """Write the markers and joints (3D points) and the joint angles (degrees) of a
    :class:`~videotrack.results.files.Results` to ``path`` (``.trc``, ``.mot``, ``.c3d`` or
    ``.nwb``). Rows whose fit failed are missing (NaN) unless ``only_ok`` is False; the frame
    rate comes from the rows' times."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in EXPORTS:
        raise VideoTrackError(f"unknown export type {suffix or '(none)'!r} (one of "
                              f"{', '.join(EXPORTS)})", file=path)
    times = np.asarray(results.times, dtype=np.float64)
    steps = np.diff(times)
    if len(times) < 2 or not np.all(steps > 0):
        raise VideoTrackError("needs two or more rows with increasing times to know the "
                              "frame rate", file=path)
    rate = float(1.0 / np.median(steps))
    frames = np.rint(times * rate).astype(np.int64)
    names = [*results.marker_names, *results.joint_names]
    points = np.concatenate([results.markers, results.joints], axis=1).astype(np.float64)
    angles = np.asarray(results.angles_deg, dtype=np.float64).copy()
    sd = None if results.sd is None else np.asarray(results.sd, dtype=np.float64).copy()
    if only_ok:
        bad = ~results.ok_mask()
        points[bad] = np.nan
        angles[bad] = np.nan
        if sd is not None:
            sd[bad] = np.nan
    axes = list(results.axis_labels)
    if suffix == ".trc":
        from videotrack.io.trc import write_trc
        write_trc(path, names, points, frames, rate, units)
    elif suffix == ".mot":  # each axis' sd as a column of its own (OpenSim ignores it)
        from videotrack.io.mot import write_mot
        if sd is not None:
            axes, angles = axes + [f"{a}.sd" for a in axes], np.hstack([angles, sd])
        write_mot(path, axes, angles, frames, rate)
    elif suffix == ".c3d":
        from videotrack.io.c3d import write_c3d
        write_c3d(path, names, points, frames, rate, units, axes, angles)
    else:
        from videotrack.io.nwb import write_nwb
        write_nwb(path, names, points, frames, rate, units, angle_names=axes, angles=angles,
                  angle_sd=sd, subject=subject)
    return path
