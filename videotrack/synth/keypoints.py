"""A synthetic markerless session with known truth: a chain moved through smooth random
postures (:func:`videotrack.synth.motion.smooth_random_motion`), its markers projected through
calibrated pinhole cameras around it, with pixel noise and a share of keypoints missing or
swapped with another keypoint, written as one DeepLabCut CSV per camera
(:func:`videotrack.io.dlc.write`), a camera file and a project file.

It serves the markerless tests, ``bench/bench_markerless.py`` and the examples of
docs/markerless.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: A free-root rat hind leg (docs/fitting.md): pelvis with both hips and the tail, femur.
RAT_LEG = """<body name="rat-leg" units="mm" format="1"><chain name="leg">
  <root mode="free" marker="hipL"/>
  <joint name="pelvis">
    <axis rot="y" name="yaw" min="-40" max="40"/>
    <axis rot="x" name="pitch" min="-30" max="30"/>
    <axis rot="z" name="roll" min="-30" max="30"/>
    <segment name="pelvis" length="0">
      <marker name="hipL" offset="0 0 -8"/><marker name="hipR" offset="0 0 8"/>
      <marker name="tail" offset="-20 4 0"/>
      <joint name="hip">
        <axis rot="y" name="yaw" min="-40" max="40"/>
        <axis rot="x" name="roll" min="-40" max="40"/>
        <axis rot="z" name="pitch" min="-110" max="-10"/>
        <segment name="femur" length="20"><marker name="knee"/>
          <joint name="stifle">
            <axis rot="y" name="yaw" locked="0"/>
            <axis rot="x" name="roll" locked="0"/>
            <axis rot="z" name="flex" min="20" max="130"/>
            <segment name="tibia" length="24"><marker name="ankle"/></segment>
          </joint>
        </segment>
      </joint>
    </segment>
  </joint></chain></body>"""


@dataclass(frozen=True)
class Session:
    """What :func:`write_session` wrote and the truth behind it."""

    project: Path
    chain: Path
    cameras: Path
    files: tuple[Path, ...]
    body: object
    camera_list: tuple
    angles_deg: np.ndarray  # (frames, axes)
    roots: np.ndarray  # (frames, chains, 3)
    markers: np.ndarray  # (frames, markers, 3)
    joints: np.ndarray  # (frames, joints, 3)
    keypoints: np.ndarray  # (cameras, frames, markers, 2) as written (NaN = missing)


def pinhole_ring(n: int = 4, distance: float = 350.0) -> list:
    """``n`` pinhole cameras (1280 x 1024, f = 1400 px) on a ring around the origin, tilted
    down 0.35 rad, looking at it."""
    from kinematics.cameras import PinholeCamera

    k = [[1400.0, 0, 639.5], [0, 1400.0, 511.5], [0, 0, 1]]
    cams = []
    for i in range(n):
        yaw = -0.9 + 1.8 * i / max(n - 1, 1)
        cams.append(PinholeCamera(f"cam{i}", k, rvec=[0.35, yaw, 0], t=[0, 0, distance],
                                  size=(1280, 1024)))
    return cams


def write_session(folder, n_frames: int = 40, n_cameras: int = 4, noise_px: float = 2.0,
                  bad_share: float = 0.1, seed: int = 0, project_text: str = "",
                  distance: float = 350.0) -> Session:
    """Write a session into ``folder``: ``rat.xml``, ``cameras.toml``, ``cam<i>DLC.csv``
    (one per camera; half of the ``bad_share`` keypoints missing, half swapped with another
    keypoint of the same camera and frame, the swapped ones scored 0.6) and ``project.toml``
    (chain, cameras, ``[keypoints] files``, then ``project_text``). The cameras are
    :func:`pinhole_ring` at ``distance`` mm (at 350 mm the 20 mm femur is about 80 px long)."""
    from kinematics.cameras.files import save_cameras
    from kinematics.model.chain_xml import loads_body
    from kinematics.model.fk import forward_kinematics
    from videotrack.io import dlc
    from videotrack.io.keypoints import make_tracks
    from videotrack.synth.motion import smooth_random_motion

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    chain = folder / "rat.xml"
    chain.write_text(RAT_LEG, encoding="utf-8")
    body = loads_body(RAT_LEG)
    angles = smooth_random_motion(body, n_frames, seed=seed)
    t = np.arange(n_frames)
    roots = np.stack([1.5 * t - 0.75 * n_frames, 3 * np.sin(t / 6), 4 * np.cos(t / 9)],
                     axis=1)[:, None]
    pose = forward_kinematics(body, angles, roots)
    cams = pinhole_ring(n_cameras, distance)
    cameras = folder / "cameras.toml"
    save_cameras(cameras, cams, units="mm")
    names = list(body.marker_names)
    m = len(names)
    keypoints = np.empty((n_cameras, n_frames, m, 2))
    files = []
    for c, cam in enumerate(cams):
        xy = cam.project(pose.markers) + rng.normal(0, noise_px, (n_frames, m, 2))
        score = rng.uniform(0.8, 1.0, (n_frames, m))
        bad = rng.random((n_frames, m)) < bad_share
        swap = bad & (rng.random((n_frames, m)) < 0.5)
        for f, k in zip(*np.nonzero(swap), strict=True):
            other = (k + 1 + rng.integers(m - 1)) % m
            xy[f, [k, other]] = xy[f, [other, k]]
            score[f, [k, other]] = 0.6
        xy[bad & ~swap] = np.nan
        keypoints[c] = xy
        path = folder / f"{cam.name}DLC.csv"
        dlc.write(path, make_tracks(names, xy, score, t, path), scorer="DLC_synthetic")
        files.append(path)
    project = folder / "project.toml"
    listed = ", ".join(f'"{p.name}"' for p in files)
    project.write_text(f'[chain]\npath = "rat.xml"\n[cameras]\npath = "cameras.toml"\n'
                       f"[keypoints]\nfiles = [{listed}]\n{project_text}", encoding="utf-8")
    return Session(project, chain, cameras, tuple(files), body, tuple(cams), angles, roots,
                   pose.markers, pose.joints, keypoints)
