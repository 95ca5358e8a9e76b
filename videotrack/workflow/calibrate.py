"""Cameras from views of a calibration board, or converted from another tool's camera file
(``videotrack calibrate``).

:func:`calibrate_cameras` detects the board in every camera, runs the bundle adjustment and
writes the camera file (and the other outputs asked for); :func:`convert_cameras` reads
another tool's camera file instead. Both can refine the camera poses from corresponding
points of the animal and return a record of what they did.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from videotrack.errors import VideoTrackError


@dataclass(frozen=True)
class Outputs:
    """The files to write: the camera file ``out`` (VideoTrack TOML) and, when given, an
    Anipose TOML, a DLT-11 CSV (``dlt_origin``: its pixel convention), a reprojection-error
    PNG (calibration only) and a folder of OpenCV YAML files."""

    out: Path
    anipose_out: Path | None = None
    dlt_out: Path | None = None
    report_png: Path | None = None
    opencv_out: Path | None = None
    dlt_origin: str = "bottom-left"

    def kinds(self) -> dict:
        outs = {self.out: "toml"}
        for path, kind in ((self.anipose_out, "toml"), (self.dlt_out, "csv"),
                           (self.report_png, "png"), (self.opencv_out, "folder")):
            if path is not None:
                outs[path] = kind
        return outs


@dataclass(frozen=True)
class Refinement:
    """Poses refined from ``points`` corresponding points: the median reprojection error of
    the triangulated points before and after, px (after: per camera too), and how the rig
    changed (:class:`videotrack.calibration.refine.RigChange`)."""

    points: int
    before_px: float
    after_px: float
    change: object = None
    per_camera_px: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Calibrated:
    """What :func:`calibrate_cameras` did: the board, the spanning tree of shared views
    (camera, camera, views), the report's lines, the refinement (if any), the cameras written,
    the world frame and the seconds of the bundle adjustment."""

    out: Path
    board: str
    tree: tuple[tuple[str, str, int], ...]
    report: tuple[str, ...]
    refinement: Refinement | None
    cameras: int
    world_frame: str
    seconds: float


@dataclass(frozen=True)
class Converted:
    """What :func:`convert_cameras` did: ``cameras`` cameras read from ``source``."""

    out: Path
    source: Path
    cameras: int
    refinement: Refinement | None
    warnings: tuple = ()  # cameras that look wrong (kinematics.cameras.checks)


def _write(outputs: Outputs, cameras: dict, error: float | None,
           units: str | None = "mm") -> None:
    from kinematics.cameras.files import save_cameras
    from videotrack.io.camera_formats import save_anipose_toml, save_dlt_csv, save_opencv_yaml

    save_cameras(outputs.out, cameras, units=units)
    if outputs.anipose_out:
        save_anipose_toml(outputs.anipose_out, cameras, error=error)
    if outputs.dlt_out:
        save_dlt_csv(outputs.dlt_out, cameras, origin=outputs.dlt_origin)
    if outputs.opencv_out:
        outputs.opencv_out.mkdir(parents=True, exist_ok=True)
        for name, cam in cameras.items():
            save_opencv_yaml(outputs.opencv_out / f"{name}.yml", cam)


def calibrate_cameras(
    board: Path,
    cameras: Mapping[str, str],
    outputs: Outputs,
    *,
    reference: str | None = None,
    world_view: int | None = None,
    distortion: int = 5,
    intrinsics: Path | None = None,
    fix_intrinsics: bool = False,
    intrinsics_only: bool = False,
    refine_points: Path | None = None,
    free_rig: bool = False,
    restarts: int = 5,
    max_frames: int = 200,
    seed: int = 0,
    cache: bool = True,
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> Calibrated:
    """Calibrate ``cameras`` (name -> a video, image folder or glob pattern of board views, in
    order) from the board config ``board`` and write ``outputs``.

    ``reference`` (default the first camera) is the world frame, or the board in view
    ``world_view``; ``max_frames`` 0 samples all frames; ``cache``: detected corners are kept
    in ``<out>.corners.npz``. ``refine_points``: refine the poses from the animal's points
    after (``free_rig``: without the priors that hold the rig, and no tolerance).
    ``progress(done, total)`` counts the bundle adjustment's starts.
    """
    from videotrack.project.outputs import guard_outputs

    if not cameras:
        raise VideoTrackError("no cameras: give --camera NAME=PATH for each camera",
                              field="--camera")
    if len(cameras) < 2 and not intrinsics_only:
        raise VideoTrackError("one camera has no extrinsics to calibrate: give two or more, "
                              "or --intrinsics-only", field="--camera")
    if restarts < 1 or max_frames < 0:
        raise VideoTrackError("--restarts must be >= 1 and --max-frames >= 0",
                              field="--restarts")
    names = list(cameras)
    reference = reference or names[0]
    if reference not in cameras:
        raise VideoTrackError(f"no camera named {reference!r} (cameras: {', '.join(names)})",
                              field="--reference")
    corners_cache = outputs.out.with_name(outputs.out.name + ".corners.npz")
    kinds = outputs.kinds()
    if cache:
        kinds[corners_cache] = "corners"
    inputs = {board: "the board config"}
    inputs.update({Path(p): f"a source of camera {n}" for n, p in cameras.items()
                   if not any(ch in p for ch in "*?[")})
    if intrinsics:
        inputs[intrinsics] = "the intrinsics"
    if refine_points:
        inputs[refine_points] = "the points"
    guard_outputs(kinds, inputs, force=force)
    return _calibrate(board, dict(cameras), outputs, reference, corners_cache if cache else None,
                      world_view, distortion, intrinsics, fix_intrinsics, intrinsics_only,
                      (refine_points, free_rig) if refine_points else None, restarts,
                      max_frames, seed, progress)


def _calibrate(board_path, cams, outputs, reference, cache, world_view, distortion,
               intrinsics, fix_intrinsics, intrinsics_only, refine, restarts,
               max_frames, seed, progress) -> Calibrated:
    from kinematics.cameras.files import load_cameras
    from videotrack.calibration.boards import load_board
    from videotrack.calibration.bundle import Options, calibrate
    from videotrack.calibration.detect import Source, detect_all
    from videotrack.calibration.report import make_report, save_png

    board = load_board(board_path)
    sources = [Source(name, path) for name, path in cams.items()]
    corners = detect_all(board, sources, max_frames=max_frames or None,
                         synchronised=not intrinsics_only, cache=cache)
    known = {}
    if intrinsics:
        given = load_cameras(intrinsics)
        for i, name in enumerate(cams):
            if name not in given:
                raise VideoTrackError(f"no camera {name!r} in the file", file=intrinsics)
            known[i] = given[name]
    elif fix_intrinsics and intrinsics_only:
        raise VideoTrackError("--fix-intrinsics without --intrinsics has nothing to keep in "
                              "--intrinsics-only mode", field="--fix-intrinsics")
    opts = Options(reference=list(cams).index(reference), n_dist=distortion,
                   fix_intrinsics=fix_intrinsics, restarts=restarts,
                   intrinsics_only=intrinsics_only, seed=seed, known=known,
                   symmetric=board.type == "checkerboard")
    cal = calibrate(corners, board.object_points, opts, progress=progress)
    report = make_report(cal, corners, board)
    fixed = opts.reference  # the camera refinement keeps in place, whatever frame is the world
    if world_view is not None:
        from videotrack.calibration.bundle import reframe

        cal.cameras = reframe(cal, world_view)
        label = corners[0].labels[world_view]
        reference = f"the board in view {world_view} ({label})"
    names = list(cams)
    tree = tuple((names[a], names[b], n) for a, b, n in cal.tree) if cal.tree else ()
    lines = tuple(report.lines())
    refinement = None
    if refine:
        cal.cameras, refinement = _refine(*refine, cal.cameras, fixed)
    _write(outputs, {c.name: c for c in cal.cameras}, report.overall["median"])
    if outputs.report_png:
        save_png(outputs.report_png, cal, corners)
    return Calibrated(out=outputs.out, board=board.describe(), tree=tree, report=lines,
                      refinement=refinement, cameras=len(cal.cameras), world_frame=reference,
                      seconds=cal.seconds)


def _refine(path: Path, free_rig: bool, cameras: list, reference: int
            ) -> tuple[list, Refinement]:
    """Camera poses refined from the points of ``path``, the errors before and after and the
    rig's change (refused past the tolerance unless ``free_rig``)."""
    import numpy as np

    from kinematics.cameras import PinholeCamera
    from videotrack.calibration.refine import refine_extrinsics, triangulated_errors

    try:
        with np.load(path, allow_pickle=False) as z:
            if "p2d" not in z.files:
                raise VideoTrackError(f"no array 'p2d' (found: {', '.join(z.files)})",
                                      file=path)
            p2d = np.asarray(z["p2d"], dtype=np.float64)
    except (OSError, ValueError) as err:
        raise VideoTrackError(f"cannot read the points: {err}", file=path) from None
    if not all(isinstance(c, PinholeCamera) for c in cameras):
        raise VideoTrackError("refinement needs pinhole cameras", field="--refine-points")
    try:
        before = np.nanmedian(triangulated_errors(cameras, p2d))
        refined, _, change = refine_extrinsics(cameras, p2d, reference=reference,
                                               free_rig=free_rig)
    except VideoTrackError as err:
        raise err.located(file=path) from None
    after = triangulated_errors(refined, p2d)
    return refined, Refinement(points=p2d.shape[1], before_px=float(before),
                               after_px=float(np.nanmedian(after)), change=change,
                               per_camera_px={c.name: float(np.nanmedian(e)) for c, e in
                                              zip(refined, after, strict=True)})


def convert_cameras(
    source: Path,
    outputs: Outputs,
    *,
    fmt: str | None = None,
    dlt_size: tuple[int, int] | None = None,
    refine_points: Path | None = None,
    free_rig: bool = False,
    force: bool = False,
) -> Converted:
    """Read the cameras of another tool's file ``source`` (``fmt``: its format, default from
    the name and content; ``dlt_size``: the image size of DLT cameras), refine their poses
    from ``refine_points`` if given, and write ``outputs``."""
    from videotrack.calibration.formats import guess_format, read_cameras
    from videotrack.project.outputs import guard_outputs

    inputs = {source: "the imported camera file"}
    if refine_points:
        inputs[refine_points] = "the points"
    guard_outputs(outputs.kinds(), inputs, force=force)
    fmt = fmt or guess_format(source)
    cameras = read_cameras(source, fmt, dlt_size=dlt_size, dlt_origin=outputs.dlt_origin)
    from kinematics.cameras.checks import camera_warnings

    found = tuple(camera_warnings(cameras))
    refinement = None
    if refine_points:
        refined, refinement = _refine(refine_points, free_rig, list(cameras.values()), 0)
        cameras = {c.name: c for c in refined}
    _write(outputs, cameras, None, units="mm" if fmt == "qca" else None)  # others: unknown
    return Converted(out=outputs.out, source=source, cameras=len(cameras),
                     refinement=refinement, warnings=found)
