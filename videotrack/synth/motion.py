"""Angle trajectories for synthetic videos: smooth random motion, and CSV files.

The paper validated its accuracy on 10 concatenated movement sequences (668 frames,
Sect. 3.2); :func:`smooth_random_motion` makes the same kind of input for any chain: each
sequence moves every free axis smoothly between random key postures inside the axis range,
and consecutive sequences are independent (a cut, as in a concatenated video).
"""

from __future__ import annotations

import csv
import itertools
import os

import numpy as np
from scipy.interpolate import CubicSpline

from kinematics.model import Body
from videotrack.errors import VideoTrackError


def smooth_random_motion(
    body: Body,
    n_frames: int,
    n_sequences: int = 1,
    keys_per_sequence: int = 4,
    margin: float = 0.05,
    seed: int = 0,
) -> np.ndarray:
    """Smooth random postures within the chain's axis ranges.

    Parameters
    ----------
    n_frames : int
        Total number of postures.
    n_sequences : int
        Independent sequences, concatenated (each about ``n_frames / n_sequences`` long).
    keys_per_sequence : int
        Random key postures per sequence, joined by a clamped cubic spline; more keys give
        faster movement.
    margin : float
        Keys stay this fraction of the range away from its ends, so the spline's overshoot
        stays inside the range.
    seed : int
        Seed of the random generator (results are reproducible).

    Returns
    -------
    angles_deg : ndarray, shape (n_frames, n_axes)
        Locked axes stay at their locked value.
    """
    if n_frames < 1 or n_sequences < 1 or n_sequences > n_frames:
        raise VideoTrackError(
            f"need 1 <= sequences ({n_sequences}) <= frames ({n_frames})", field="motion"
        )
    if keys_per_sequence < 2:
        raise VideoTrackError("need at least 2 key postures per sequence", field="motion")
    rng = np.random.default_rng(seed)
    lo, hi = body.ranges_deg().T
    span = hi - lo
    locked = body.locked_mask()
    fixed = np.where(locked, lo, 0.0)
    bounds = np.r_[sequence_starts(n_frames, n_sequences), n_frames]
    out = np.empty((n_frames, body.n_axes))
    for start, stop in itertools.pairwise(bounds):
        length = stop - start
        keys = lo + span * rng.uniform(margin, 1 - margin, size=(keys_per_sequence, body.n_axes))
        if length == 1:
            out[start] = keys[0]
            continue
        t_keys = np.linspace(0, length - 1, keys_per_sequence)
        spline = CubicSpline(t_keys, keys, axis=0, bc_type="clamped")
        out[start:stop] = np.clip(spline(np.arange(length)), lo, hi)
    out[:, locked] = fixed[locked]
    return out


def sequence_starts(n_frames: int, n_sequences: int) -> np.ndarray:
    """First frame of each of the concatenated sequences of :func:`smooth_random_motion`."""
    return np.linspace(0, n_frames, n_sequences + 1).round().astype(int)[:-1]


def read_angles_csv(path: str | os.PathLike, body: Body) -> np.ndarray:
    """Read an angle trajectory: one row per frame, one column per axis named ``joint.axis``
    (degrees). Columns of locked axes may be left out (they take the locked value); other
    columns (e.g. ``frame``) are ignored. Returns (n_frames, n_axes) degrees."""
    refs = body.axis_refs()
    try:
        with open(path, newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            if header is None:
                raise VideoTrackError("file is empty", file=path)
            columns = {name.strip(): k for k, name in enumerate(header)}
            missing = [r.label for r in refs if r.label not in columns and not r.axis.locked]
            if missing:
                raise VideoTrackError(f"no column for axis {missing[0]}", file=path, line=1)
            rows = []
            for line_no, row in enumerate(reader, start=2):
                if not row:
                    continue
                values = []
                for r in refs:
                    if r.label not in columns:
                        values.append(r.axis.locked_deg)
                        continue
                    text = row[columns[r.label]] if columns[r.label] < len(row) else ""
                    try:
                        v = float(text)
                    except ValueError:
                        raise VideoTrackError(f"'{text}' is not a number", file=path,
                                              line=line_no, field=r.label) from None
                    if not np.isfinite(v):
                        raise VideoTrackError("value is not finite", file=path, line=line_no,
                                              field=r.label)
                    values.append(v)
                rows.append(values)
    except OSError as err:
        raise VideoTrackError(f"cannot read angles: {err.strerror}", file=path) from None
    if not rows:
        raise VideoTrackError("no frames in file", file=path)
    return np.array(rows, dtype=float)
