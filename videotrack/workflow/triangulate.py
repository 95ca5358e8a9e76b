"""2D keypoints of several cameras -> an Anipose pose-3d CSV (``videotrack triangulate``).

:func:`triangulate_keypoints` reads the cameras and each camera's keypoints, triangulates
every body part and writes the CSV; it returns a :class:`Triangulated` saying what it did.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from kinematics.cameras.checks import camera_warnings


@dataclass(frozen=True)
class Triangulated:
    """What :func:`triangulate_keypoints` wrote.

    ``placed`` of ``points`` (body parts x frames) were triangulated; ``median_px`` is the
    median reprojection error of those with one (None: none has), ``per_camera_px`` each
    camera's over the keypoints it gave; ``warnings``: cameras that look wrong
    (:func:`kinematics.cameras.checks.camera_warnings`).
    """

    output: Path
    placed: int
    points: int
    body_parts: int
    frames: int
    cameras: int
    method: str
    median_px: float | None
    per_camera_px: dict = field(default_factory=dict)
    warnings: tuple = ()


def load_any_cameras(path: Path) -> dict:
    """Cameras of a VideoTrack camera file, of a project file (its ``[cameras] path``), or of
    an Anipose/Pose2Sim calibration.toml."""
    import tomllib

    from kinematics.cameras.files import import_anipose_toml, load_cameras
    from kinematics.fileio import parse_toml

    try:
        doc = parse_toml(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        doc = None  # load_cameras says what is wrong, with the line
    if isinstance(doc, dict) and "cameras" not in doc:
        return import_anipose_toml(path)
    if isinstance(doc, dict) and isinstance(doc["cameras"].get("path"), str):
        return load_any_cameras(path.parent / doc["cameras"]["path"])  # a project file
    return load_cameras(path)


def assign_keypoints(cameras: dict, specs: Sequence[str]) -> dict[str, Path]:
    """Camera name -> keypoint path from CAMERA=PATH or PATH arguments."""
    from videotrack.errors import VideoTrackError

    names = list(cameras)
    out: dict[str, Path] = {}
    plain = []
    for spec in specs:
        name, sep, rest = spec.partition("=")
        if sep and name in cameras:
            if name in out:
                raise VideoTrackError(f"camera {name!r} is given two keypoint files",
                                      field="KEYPOINTS")
            out[name] = Path(rest)
        elif sep and not Path(spec).exists():
            raise VideoTrackError(f"no camera {name!r} in the camera file (it has "
                                  f"{', '.join(names)})", field="KEYPOINTS")
        else:
            plain.append(Path(spec))
    if plain and out:
        raise VideoTrackError("name the camera of every keypoint file (CAMERA=PATH) or of "
                              "none", field="KEYPOINTS")
    if plain:
        if len(plain) > len(names):
            raise VideoTrackError(f"{len(plain)} keypoint files for {len(names)} cameras",
                                  field="KEYPOINTS")
        out = dict(zip(names, plain, strict=False))
    if len(out) < 2:
        raise VideoTrackError("triangulation needs the keypoints of at least two cameras",
                              field="KEYPOINTS")
    return {n: out[n] for n in names if n in out}


def _limbs(specs, names: tuple[str, ...]):
    from videotrack.errors import VideoTrackError

    pairs = []
    for spec in specs:
        parts = spec.split(",")
        if len(parts) != 2 or any(p not in names for p in parts):
            raise VideoTrackError(f"expected two body parts A,B of {', '.join(names)}; got "
                                  f"{spec!r}", field="--limbs")
        pairs.append((names.index(parts[0]), names.index(parts[1])))
    return pairs


def triangulate_keypoints(
    cameras_path: Path,
    keypoints: Sequence[str],
    output: Path,
    *,
    method: str = "linear",
    keypoint_format: str | None = None,
    model: str | None = None,
    individual: str | int | None = None,
    min_score: float = 0.0,
    weighted: bool = True,
    min_cams: int = 2,
    good_px: float = 0.5,
    max_px: float = 200.0,
    inlier_px: float = 0.0,
    init: str = "linear",
    limbs: Sequence[str] = (),
    limb_lengths: Sequence[float] | None = None,
    smooth: float = 2.0,
    n_deriv: int = 1,
    limb_weight: float = 2.0,
    loss: str = "soft_l1",
    loss_px: float = 15.0,
    chunk: int = 300,
    overlap: int = 30,
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> Triangulated:
    """Triangulate the keypoints of ``keypoints`` (CAMERA=PATH or PATH, see
    :func:`assign_keypoints`) through the cameras of ``cameras_path``
    (:func:`load_any_cameras`) and write them to the pose-3d CSV ``output``.

    ``limbs`` are "A,B" pairs of body parts (``method="optim"`` only); ``progress(done,
    total)`` is called with the frames triangulated so far.
    """
    import numpy as np

    from kinematics.observe import triangulation as tri
    from videotrack.errors import VideoTrackError
    from videotrack.io.keypoints import align_cameras, read_keypoints
    from videotrack.io.pose3d import write_pose3d
    from videotrack.project.outputs import guard_outputs

    if method != "optim" and (limbs or limb_lengths):
        raise VideoTrackError("limbs constrain only the optimisation (--method optim)",
                              field="--limbs")
    cameras = load_any_cameras(cameras_path)
    files = assign_keypoints(cameras, keypoints)
    inputs = {cameras_path: "the camera file", **{p: f"the keypoints of {n}"
                                                 for n, p in files.items()}}
    guard_outputs({output: "pose3d"}, inputs, force=force, field="--output")
    tracks = {n: read_keypoints(p, keypoint_format, individual=individual, model=model)
              for n, p in files.items()}
    names, frames, xy, score = align_cameras(tracks)
    cams = [cameras[n] for n in files]
    common = dict(min_score=min_score, weighted=weighted)
    ransac = dict(min_cams=min_cams, good_px=good_px, max_px=max_px, inlier_px=inlier_px)
    report = progress or (lambda done, total: None)
    if method == "optim":
        result = tri.triangulate_optim(
            cams, xy, score, **common, init=init, limbs=_limbs(limbs, names),
            limb_lengths=limb_lengths, smooth=smooth, n_deriv=n_deriv,
            limb_weight=limb_weight, loss=loss, loss_px=loss_px, chunk=chunk,
            overlap=overlap, progress=lambda done, total: report(done, len(frames)),
            **(ransac if init == "ransac" else {}))
    else:
        parts = []
        done = 0
        for s in range(0, max(len(frames), 1), 500):  # blocks, for the progress
            block = slice(s, s + 500)
            if method == "ransac":
                parts.append(tri.triangulate_ransac(cams, xy[:, block], score[:, block],
                                                    **common, **ransac))
            else:
                parts.append(tri.triangulate_linear(cams, xy[:, block], score[:, block],
                                                    **common))
            done += len(parts[-1].xyz)
            report(done, len(frames))
        result = tri.Triangulation(*(np.concatenate([getattr(p, f) for p in parts],
                                                    axis=1 if f == "used" else 0)
                                     for f in ("xyz", "error", "ncams", "score", "used")))
    write_pose3d(output, names, result.xyz, result.error, result.ncams, result.score, frames)
    placed = np.isfinite(result.xyz).all(axis=-1)
    err = result.error[placed & np.isfinite(result.error)]
    per_camera = _per_camera_px(list(files), cams, xy, result)
    return Triangulated(output=output, placed=int(placed.sum()), points=int(placed.size),
                        body_parts=len(names), frames=len(frames), cameras=len(cams),
                        method=method, median_px=float(np.median(err)) if err.size else None,
                        per_camera_px=per_camera,
                        warnings=tuple(camera_warnings(dict(zip(files, cams, strict=True)),
                                                       per_camera)))


def _per_camera_px(names, cams, xy, result) -> dict[str, float]:
    """Each camera's median reprojection error (px) over the keypoints a point was solved
    from (NaN: none)."""
    import numpy as np

    out = {}
    for c, (name, cam) in enumerate(zip(names, cams, strict=True)):
        use = result.used[c] & np.isfinite(result.xyz).all(axis=-1)
        if not use.any():
            out[name] = float("nan")
            continue
        d = np.linalg.norm(cam.project(result.xyz[use]) - xy[c][use], axis=-1)
        d = d[np.isfinite(d)]
        out[name] = float(np.median(d)) if d.size else float("nan")
    return out
