"""C3D files (biomechanics' binary exchange format), written and read with ``ezc3d``.

3D points are POINT entries in ``POINT:UNITS`` (mm by default); a missing point has residual
-1. Joint angles, in degrees, follow the Vicon convention: one angle "point" per joint whose
X, Y, Z are its axes' angles, labelled ``<joint>_angles`` and listed in ``POINT:ANGLES``;
``VIDEOTRACK:ANGLE_AXES`` names each component (``J0.phi``; empty for the padding of joints
with fewer than three axes) so the posture columns come back exactly. The first frame is
``TRIAL:ACTUAL_START_FIELD``.
"""

from __future__ import annotations

import os

import numpy as np

from videotrack.errors import VideoTrackError
from videotrack.io._files import atomic_path, column_names, frame_times
from videotrack.io.mot import Motion
from videotrack.io.trc import Markers3D

ANGLE_SUFFIX = "_angles"  # a joint's angle point; its position may be a point of the same name


def _ezc3d():
    try:
        import ezc3d
    except ImportError:
        raise VideoTrackError("writing C3D needs the 'ezc3d' package "
                              "(pip install 'videotrack[markerless]')") from None
    return ezc3d


def _joint_groups(angle_names):
    """Joint -> its axis columns, in order (a joint is the part before the last '.')."""
    groups: dict[str, list[int]] = {}
    for i, name in enumerate(angle_names):
        groups.setdefault(name.rsplit(".", 1)[0], []).append(i)
    return groups


def write_c3d(path: str | os.PathLike, names, points, frames, rate: float, units: str = "mm",
              angle_names=(), angles=None) -> None:
    """Write 3D points (n_frames, n_markers, 3) and optionally joint angles (n_frames,
    n_axes) in degrees named ``angle_names`` (posture columns ``joint.axis``)."""
    ezc3d = _ezc3d()
    names = column_names(names, path)
    points = np.asarray(points, dtype=np.float64)
    frames, _ = frame_times(frames, rate)
    n = len(frames)
    if points.shape != (n, len(names), 3):
        raise VideoTrackError(f"points of shape {points.shape} do not match {n} frames x "
                              f"{len(names)} markers x 3", file=path)
    angle_names = column_names(angle_names, path, "angle")
    groups = {f"{joint}{ANGLE_SUFFIX}": cols
              for joint, cols in _joint_groups(angle_names).items()}
    if angle_names:
        angles = np.asarray(angles, dtype=np.float64)
        if angles.shape != (n, len(angle_names)):
            raise VideoTrackError(f"angles of shape {angles.shape} do not match {n} frames x "
                                  f"{len(angle_names)} axes", file=path)
        if any(len(cols) > 3 for cols in groups.values()):
            raise VideoTrackError("a joint with more than 3 axes cannot be a C3D angle",
                                  file=path)
        clash = set(groups) & set(names)
        if clash:
            raise VideoTrackError(f"angle label {sorted(clash)[0]!r} is the name of a marker: "
                                  "C3D labels must differ", file=path)
    labels = names + list(groups)
    data = np.zeros((4, len(labels), n))
    data[3] = 1.0
    data[:3, : len(names)] = points.transpose(2, 1, 0)
    axes = []
    for j, (_, cols) in enumerate(groups.items()):
        data[: len(cols), len(names) + j] = angles[:, cols].T
        axes += [angle_names[c] for c in cols] + [""] * (3 - len(cols))
    residuals = np.where(np.isfinite(data[:3]).all(axis=0), 0.0, -1.0)[None]
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(rate)]
    c["parameters"]["POINT"]["LABELS"]["value"] = labels
    c["data"]["points"] = data
    c["data"]["meta_points"] = {"residuals": residuals,
                                "camera_masks": np.zeros((7, len(labels), n), dtype=bool)}
    c.add_parameter("POINT", "UNITS", units)
    if groups:
        c.add_parameter("POINT", "ANGLES", list(groups))
        c.add_parameter("POINT", "ANGLE_UNITS", "deg")
        c.add_parameter("VIDEOTRACK", "ANGLE_AXES", axes)
    c.add_parameter("TRIAL", "ACTUAL_START_FIELD", [int(frames[0]) + 1 if n else 1, 0])
    with atomic_path(path) as tmp:
        c.write(str(tmp))


def read_c3d(path: str | os.PathLike) -> tuple[Markers3D, Motion | None]:
    """Read the 3D points (and, when the file has them, the joint angles) of a C3D file."""
    ezc3d = _ezc3d()
    try:
        c = ezc3d.c3d(str(path))
    except Exception as e:  # ezc3d raises RuntimeError/IOError with its own message
        raise VideoTrackError(f"not a readable C3D file ({e})", file=path) from None
    params = c["parameters"]
    labels = [s.strip() for s in params["POINT"]["LABELS"]["value"]]
    rate = float(c["header"]["points"]["frame_rate"])
    data = np.asarray(c["data"]["points"], dtype=np.float64)[:3]  # (3, n_labels, n_frames)
    residuals = np.asarray(c["data"]["meta_points"]["residuals"])[0]
    data[:, residuals < 0] = np.nan
    angle_labels = list(params["POINT"]["ANGLES"]["value"]) if "ANGLES" in params["POINT"] \
        else []
    start = c["header"]["points"]["first_frame"]
    if "TRIAL" in params and "ACTUAL_START_FIELD" in params["TRIAL"]:
        start = int(params["TRIAL"]["ACTUAL_START_FIELD"]["value"][0]) - 1
    frames = start + np.arange(data.shape[2], dtype=np.int64)
    units = params["POINT"]["UNITS"]["value"][0] if "UNITS" in params["POINT"] else ""
    is_angle = [lab in angle_labels for lab in labels]
    markers = [i for i, a in enumerate(is_angle) if not a]
    points = data[:, markers].transpose(2, 1, 0)
    out = Markers3D(tuple(labels[i] for i in markers), frames, points, rate, units)
    if not angle_labels:
        return out, None
    joints = [i for i, a in enumerate(is_angle) if a]
    comps = data[:, joints].transpose(2, 1, 0).reshape(len(frames), -1)  # joint-major x,y,z
    if "VIDEOTRACK" in params and "ANGLE_AXES" in params["VIDEOTRACK"]:
        axes = [s.strip() for s in params["VIDEOTRACK"]["ANGLE_AXES"]["value"]]
    else:
        axes = [f"{labels[j]}.{xyz}" for j in joints for xyz in "XYZ"]
    keep = [i for i, a in enumerate(axes) if a]
    return out, Motion(tuple(axes[i] for i in keep), frames / rate, comps[:, keep], True)
