"""NWB files with the ``ndx-pose`` extension, the layout ``movement`` loads
(``movement.io.load_poses.from_nwb_file``) and DANDI accepts.

The processing module ``behavior`` holds a ``PoseEstimation`` named ``PoseEstimation`` with one
``PoseEstimationSeries`` per marker (2D or 3D points, NaN when missing, with a confidence) and
the ``Skeleton`` it refers to; joint angles in degrees are one ``TimeSeries`` per posture
column in a ``BehavioralTimeSeries`` named ``JointAngles``, and their standard deviations
(where the results have them) the same way in ``JointAngleSD``.
"""

from __future__ import annotations

import datetime
import os

import numpy as np

from videotrack.errors import VideoTrackError
from videotrack.io._files import atomic_path, column_names, frame_times
from videotrack.io.mot import Motion
from videotrack.io.trc import Markers3D

MODULE, POSES, ANGLES, ANGLE_SD = "behavior", "PoseEstimation", "JointAngles", "JointAngleSD"


def _modules():
    try:
        import ndx_pose
        import pynwb
    except ImportError:
        raise VideoTrackError("NWB needs the 'pynwb' and 'ndx-pose' packages "
                              "(pip install 'videotrack[markerless]')") from None
    return pynwb, ndx_pose


def _timing(frames, rate):
    """rate and starting_time for evenly numbered frames, else timestamps."""
    frames, times = frame_times(frames, rate)
    if len(frames) > 1 and np.any(np.diff(frames) != 1):
        return {"timestamps": times}
    return {"rate": float(rate), "starting_time": float(times[0]) if len(times) else 0.0}


def write_nwb(path: str | os.PathLike, names, points, frames, rate: float,
              units: str = "mm", confidence=None, angle_names=(), angles=None,
              angle_sd=None, edges=None, subject: str = "animal", software: str = "VideoTrack",
              description: str = "kinematic chain fitted by VideoTrack") -> None:
    """Write points (n_frames, n_markers, 2 or 3) in ``units`` (with an optional confidence
    (n_frames, n_markers)) and optionally joint angles (n_frames, n_axes) in degrees, with
    their standard deviations ``angle_sd`` (the same shape) if given.

    ``edges`` are pairs of marker indices (the chain's segments) for the skeleton;
    ``subject`` becomes the NWB identifier, which movement uses as the individual's name.
    """
    pynwb, ndx_pose = _modules()
    from pynwb.behavior import BehavioralTimeSeries

    names = column_names(names, path)
    points = np.asarray(points, dtype=np.float64)
    n = len(np.asarray(frames))
    if points.ndim != 3 or points.shape[:2] != (n, len(names)) or points.shape[2] not in (2, 3):
        raise VideoTrackError(f"points of shape {points.shape} do not match {n} frames x "
                              f"{len(names)} markers x 2 or 3", file=path)
    conf = (np.where(np.isfinite(points).all(axis=2), 1.0, np.nan) if confidence is None
            else np.asarray(confidence, dtype=np.float64))
    if conf.shape != (n, len(names)):
        raise VideoTrackError(f"confidence of shape {conf.shape}, expected {(n, len(names))}",
                              file=path)
    timing = _timing(frames, rate)
    edges = np.zeros((0, 2), np.uint8) if edges is None else np.asarray(edges, np.uint8)
    nwb = pynwb.NWBFile(session_description=description, identifier=str(subject),
                        session_start_time=datetime.datetime.now(datetime.UTC))
    skeleton = ndx_pose.Skeleton(name="skeleton", nodes=names, edges=edges)
    series = [ndx_pose.PoseEstimationSeries(
        name=name, description=f"position of {name}", data=points[:, i], unit=units,
        reference_frame="the chain's world frame", confidence=conf[:, i],
        confidence_definition="weight of the point (1 when not given)", **timing)
        for i, name in enumerate(names)]
    poses = ndx_pose.PoseEstimation(name=POSES, pose_estimation_series=series,
                                    description=description, source_software=software,
                                    skeleton=skeleton)
    module = nwb.create_processing_module(name=MODULE, description="pose and joint angles")
    module.add(ndx_pose.Skeletons(skeletons=[skeleton]))
    module.add(poses)
    angle_names = column_names(angle_names, path, "angle")
    if angle_names:
        angles = np.asarray(angles, dtype=np.float64)
        if angles.shape != (n, len(angle_names)):
            raise VideoTrackError(f"angles of shape {angles.shape} do not match {n} frames x "
                                  f"{len(angle_names)} axes", file=path)
        tables = [(ANGLES, angles, "joint angle")]
        if angle_sd is not None:
            angle_sd = np.asarray(angle_sd, dtype=np.float64)
            if angle_sd.shape != angles.shape:
                raise VideoTrackError(f"angle sd of shape {angle_sd.shape} do not match the "
                                      f"angles' {angles.shape}", file=path)
            tables.append((ANGLE_SD, angle_sd, "standard deviation of joint angle"))
        for table, values, what in tables:
            group = BehavioralTimeSeries(name=table)
            for i, a in enumerate(angle_names):
                group.add_timeseries(pynwb.TimeSeries(
                    name=a, data=values[:, i], unit="degrees", description=f"{what} {a}",
                    comments=f"column {i}", **timing))  # NWB sorts by name; this keeps order
            module.add(group)
    with atomic_path(path) as tmp, pynwb.NWBHDF5IO(str(tmp), mode="w") as io:
        io.write(nwb)


def read_nwb(path: str | os.PathLike) -> tuple[Markers3D, np.ndarray, Motion | None]:
    """The points, their confidence and the joint angles (if any) of a file written by
    :func:`write_nwb` (or any NWB file with an ndx-pose ``PoseEstimation``)."""
    pynwb, _ = _modules()
    try:
        with pynwb.NWBHDF5IO(str(path), mode="r") as io:
            nwb = io.read()
            module = nwb.processing[MODULE]
            poses = module[POSES]
            order = list(poses.skeleton.nodes[:]) if poses.skeleton is not None else []
            series = sorted(poses.pose_estimation_series.values(),
                            key=lambda s: order.index(s.name) if s.name in order else 0)
            names = tuple(s.name for s in series)
            points = np.stack([np.asarray(s.data[:]) for s in series], axis=1)
            conf = np.stack([np.asarray(s.confidence[:]) for s in series], axis=1)
            first = series[0]
            times = (np.asarray(first.timestamps[:]) if first.timestamps is not None
                     else first.starting_time + np.arange(len(points)) / first.rate)
            rate = first.rate or float(np.median(1 / np.diff(times)))
            motion = None
            if ANGLES in module.data_interfaces:
                ts = sorted(module[ANGLES].time_series.values(), key=_column)
                motion = Motion(tuple(t.name for t in ts), times,
                                np.stack([np.asarray(t.data[:]) for t in ts], axis=1), True)
            units = first.unit
    except (OSError, KeyError, ValueError, IndexError) as e:
        raise VideoTrackError(f"not an NWB file with an ndx-pose PoseEstimation ({e})",
                              file=path) from None
    frames = np.rint(times * rate).astype(np.int64)
    return Markers3D(names, frames, points, rate, units), conf, motion


def _column(series) -> int:
    """The column index :func:`write_nwb` kept in a joint angle's comments."""
    text = str(series.comments or "")
    return int(text.split()[-1]) if text.startswith("column ") else 0
