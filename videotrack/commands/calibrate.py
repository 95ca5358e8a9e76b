"""``videotrack calibrate``: cameras from videos or images of a calibration board."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from videotrack.calibration.formats import FORMATS as CAMERA_FORMATS
from videotrack.io.camera_formats import ORIGINS as DLT_ORIGINS

EXAMPLES = """\
examples:
  # four synchronised videos of a ChArUco board -> the project's camera file (mm)
  videotrack calibrate board.toml --camera back=back/board.mp4 --camera mid=mid/board.mp4 \\
      --camera side=side/board.mov --camera top=top/board.mp4 -o cameras.toml
  # image folders or glob patterns (quoted) of a checkerboard; also for Anipose and a PNG
  videotrack calibrate checker.toml --camera left='stereo/left*.jpg' \\
      --camera right='stereo/right*.jpg' -o cameras.toml --anipose-out calibration.toml \\
      --report-png calibration.png
  # lens intrinsics only, from separate photos per camera (no shared views needed)
  videotrack calibrate checker.toml --camera cam01='intrinsics/cam01_*.jpg' \\
      --camera cam02='intrinsics/cam02_*.jpg' --intrinsics-only -o intrinsics.toml
  # extrinsics only, keeping known intrinsics; the world frame from camera 'top'
  videotrack calibrate board.toml --camera ... --intrinsics intrinsics.toml \\
      --fix-intrinsics --reference top -o cameras.toml
  # refine the camera poses of a calibration from corresponding points of the animal
  videotrack calibrate --import calibration.toml --refine-points points.npz -o cameras.toml
  # convert another tool's calibration (Qualisys .qca, Anipose, OpenCV YAML, DLT CSV)
  videotrack calibrate --import Calib.qca.txt -o cameras.toml --dlt-out dlt.csv

The board config is a TOML file with a [board] table (Anipose board files work too):

  [board]
  type = "charuco"          # or "checkerboard"
  squares = [8, 11]         # squares along x and y (not inner corners)
  square_mm = 24.0
  marker_mm = 18.75         # charuco only
  dictionary = "4X4_1000"   # charuco only

or, for an ArUco grid (OpenCV's GridBoard):

  [board]
  type = "aruco"
  markers = [5, 7]          # markers along x and y
  marker_mm = 30.0
  separation_mm = 6.0       # gap between neighbouring markers
  dictionary = "4X4_50"

Frame i of every camera must be the same instant (synchronised videos, or image lists that
sort in the same order). Up to --max-frames frames are sampled evenly from each. Detected
corners are cached in OUT.corners.npz, so a second run (another --restarts ...) starts at
once. The world frame is the reference camera's (x right, y down, z forward), in mm.

The report gives per camera the views with the board, the views used, the reprojection error
(median, 95th percentile) and outliers, how much of the image the board covered; the square
size (the marker side of an ArUco grid) measured by triangulating the corners (a check of the
whole calibration); and the spread of camera centres and focal lengths over the --restarts
starts.
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "calibrate",
        help="calibrate cameras from views of a checkerboard, ChArUco board or ArUco grid",
        description=(
            "Detect the board in every camera, estimate each camera's lens (intrinsics) and "
            "the cameras' poses (extrinsics) by joint bundle adjustment with outlier "
            "rejection and several starts, and write the camera file with a report of its "
            "quality and repeatability. Also converts other tools' camera files."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("board", type=Path, nargs="?",
                   help="board config TOML ([board] table, or an Anipose board file)")
    p.add_argument("--camera", action="append", default=[], metavar="NAME=PATH",
                   help="a camera and its board views: a video, an image folder or a quoted "
                        "glob pattern of images (repeat per camera, in order)")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="camera file to write (VideoTrack TOML, units mm)")
    outs = p.add_argument_group("other outputs")
    outs.add_argument("--anipose-out", type=Path, metavar="TOML",
                      help="also write an Anipose calibration.toml")
    outs.add_argument("--opencv-out", type=Path, metavar="DIR",
                      help="also write one OpenCV YAML file per camera into DIR")
    outs.add_argument("--dlt-out", type=Path, metavar="CSV",
                      help="also write DLT-11 coefficients (DLTdv/easyWand CSV; lens "
                           "distortion cannot be represented and is left out)")
    outs.add_argument("--report-png", type=Path, metavar="PNG",
                      help="plot of the reprojection errors per camera")
    how = p.add_argument_group("how to calibrate")
    how.add_argument("--reference", metavar="NAME",
                     help="camera whose frame is the world frame (default: the first)")
    how.add_argument("--world-view", type=int, metavar="N",
                     help="the board in view N (0-based among the sampled frames) is the "
                          "world frame instead: origin at its first corner, z into the board")
    how.add_argument("--distortion", type=int, choices=(0, 4, 5), default=5,
                     help="distortion coefficients: 0, 4 (k1 k2 p1 p2) or 5 (+ k3; default)")
    how.add_argument("--intrinsics", type=Path, metavar="FILE",
                     help="camera file with known intrinsics (cameras matched by name) to "
                          "start from")
    how.add_argument("--fix-intrinsics", action="store_true",
                     help="keep the intrinsics (from --intrinsics, else from each camera's "
                          "own views) and adjust only the poses")
    how.add_argument("--intrinsics-only", action="store_true",
                     help="calibrate each camera's lens alone; all cameras at the origin")
    how.add_argument("--refine-points", type=Path, metavar="NPZ",
                     help="then refine the camera poses from corresponding points of the "
                          "animal: an .npz with 'p2d' (cameras, points, 2) px, NaN where "
                          "unseen, cameras in --camera order (aniposelib's points.npz); also "
                          "after --import")
    how.add_argument("--restarts", type=int, default=5, metavar="N",
                     help="bundle adjustments from different starts; the best is kept and "
                          "the spread is reported (default 5)")
    how.add_argument("--max-frames", type=int, default=200, metavar="N",
                     help="frames sampled evenly per camera (default 200; 0: all)")
    how.add_argument("--seed", type=int, default=0, help="seed of sampling and restarts")
    how.add_argument("--no-cache", action="store_true", help="detect again, write no cache")
    conv = p.add_argument_group("conversion")
    conv.add_argument("--import", dest="import_file", type=Path, metavar="FILE",
                      help="read cameras from FILE instead of calibrating: VideoTrack or "
                           "Anipose TOML, OpenCV YAML, DLT CSV, Qualisys .qca")
    conv.add_argument("--format", choices=CAMERA_FORMATS,
                      help="format of --import (default: from the name and content)")
    conv.add_argument("--dlt-size", metavar="WxH",
                      help="image size of DLT cameras (needed: DLTdv counts v from the bottom)")
    conv.add_argument("--dlt-origin", choices=DLT_ORIGINS,
                      default="bottom-left",
                      help="pixel convention of DLT coefficients: bottom-left (DLTdv, "
                           "easyWand, Argus; default) or top-left (OpenCV)")
    p.add_argument("--force", action="store_true",
                   help="replace existing files of another kind (never an input)")
    p.set_defaults(func=run)


def _cameras(specs: list[str]) -> dict[str, str]:
    from videotrack.errors import VideoTrackError

    out: dict[str, str] = {}
    for spec in specs:
        name, sep, path = spec.partition("=")
        if not sep or not name.strip() or not path:
            raise VideoTrackError(f"expected NAME=PATH, got {spec!r}", field="--camera")
        if name in out:
            raise VideoTrackError(f"camera {name!r} given twice", field="--camera")
        out[name] = path
    return out


def _size(text: str | None):
    from videotrack.errors import VideoTrackError

    if text is None:
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or int(m[1]) < 1 or int(m[2]) < 1:
        raise VideoTrackError(f"expected WIDTHxHEIGHT such as 1280x1024, got {text!r}",
                              field="--dlt-size")
    return int(m[1]), int(m[2])


def _outputs(args) -> dict:
    outs = {args.out: "toml"}
    for path, kind in ((args.anipose_out, "toml"), (args.dlt_out, "csv"),
                       (args.report_png, "png"), (args.opencv_out, "folder")):
        if path is not None:
            outs[path] = kind
    return outs


def _write(args, cameras: dict, error: float | None, units: str | None = "mm") -> None:
    from kinematics.cameras.files import save_cameras
    from videotrack.io.camera_formats import save_anipose_toml, save_dlt_csv, save_opencv_yaml

    save_cameras(args.out, cameras, units=units)
    if args.anipose_out:
        save_anipose_toml(args.anipose_out, cameras, error=error)
    if args.dlt_out:
        save_dlt_csv(args.dlt_out, cameras, origin=args.dlt_origin)
    if args.opencv_out:
        args.opencv_out.mkdir(parents=True, exist_ok=True)
        for name, cam in cameras.items():
            save_opencv_yaml(args.opencv_out / f"{name}.yml", cam)


def run(args) -> int:
    from videotrack.errors import VideoTrackError
    from videotrack.project.outputs import guard_outputs

    if args.import_file is not None:
        return _convert(args)
    if args.board is None:
        raise VideoTrackError("give a board config (or --import FILE to convert)",
                              field="board")
    cams = _cameras(args.camera)
    if not cams:
        raise VideoTrackError("no cameras: give --camera NAME=PATH for each camera",
                              field="--camera")
    if len(cams) < 2 and not args.intrinsics_only:
        raise VideoTrackError("one camera has no extrinsics to calibrate: give two or more, "
                              "or --intrinsics-only", field="--camera")
    if args.restarts < 1 or args.max_frames < 0:
        raise VideoTrackError("--restarts must be >= 1 and --max-frames >= 0",
                              field="--restarts")
    names = list(cams)
    reference = args.reference or names[0]
    if reference not in cams:
        raise VideoTrackError(f"no camera named {reference!r} (cameras: {', '.join(names)})",
                              field="--reference")
    cache = args.out.with_name(args.out.name + ".corners.npz")
    outputs = _outputs(args)
    if not args.no_cache:
        outputs[cache] = "corners"
    inputs = {args.board: "the board config"}
    inputs.update({Path(p): f"a source of camera {n}" for n, p in cams.items()
                   if not any(ch in p for ch in "*?[")})
    if args.intrinsics:
        inputs[args.intrinsics] = "the intrinsics"
    if args.refine_points:
        inputs[args.refine_points] = "the points"
    guard_outputs(outputs, inputs, force=args.force)
    return _calibrate(args, cams, reference, cache)


def _calibrate(args, cams: dict, reference: str, cache: Path) -> int:
    import sys

    from tqdm import tqdm

    from kinematics.cameras.files import load_cameras
    from videotrack.calibration.boards import load_board
    from videotrack.calibration.bundle import Options, calibrate
    from videotrack.calibration.detect import Source, detect_all
    from videotrack.calibration.report import make_report, save_png
    from videotrack.errors import VideoTrackError

    board = load_board(args.board)
    sources = [Source(name, path) for name, path in cams.items()]
    corners = detect_all(board, sources, max_frames=args.max_frames or None,
                         synchronised=not args.intrinsics_only,
                         cache=None if args.no_cache else cache)
    known = {}
    if args.intrinsics:
        given = load_cameras(args.intrinsics)
        for i, name in enumerate(cams):
            if name not in given:
                raise VideoTrackError(f"no camera {name!r} in the file", file=args.intrinsics)
            known[i] = given[name]
    elif args.fix_intrinsics and args.intrinsics_only:
        raise VideoTrackError("--fix-intrinsics without --intrinsics has nothing to keep in "
                              "--intrinsics-only mode", field="--fix-intrinsics")
    opts = Options(reference=list(cams).index(reference), n_dist=args.distortion,
                   fix_intrinsics=args.fix_intrinsics, restarts=args.restarts,
                   intrinsics_only=args.intrinsics_only, seed=args.seed, known=known,
                   symmetric=board.type == "checkerboard")
    with tqdm(total=args.restarts, desc="bundle adjustment", unit="start", leave=False,
              file=sys.stderr, disable=None) as bar:
        cal = calibrate(corners, board.object_points, opts,
                        progress=lambda done, total: bar.update(done - bar.n))
    report = make_report(cal, corners, board)
    if args.world_view is not None:
        from videotrack.calibration.bundle import reframe

        cal.cameras = reframe(cal, args.world_view)
        label = corners[0].labels[args.world_view]
        reference = f"the board in view {args.world_view} ({label})"
    print(f"board: {board.describe()}")
    if cal.tree:
        names = list(cams)
        print("spanning tree: " + ", ".join(f"{names[a]}-{names[b]} ({n} shared views)"
                                            for a, b, n in cal.tree))
    for line in report.lines():
        print(line)
    if args.refine_points:
        cal.cameras = _refine(args, cal.cameras, list(cams).index(reference))
    _write(args, {c.name: c for c in cal.cameras}, report.overall["median"])
    if args.report_png:
        save_png(args.report_png, cal, corners)
    print(f"wrote {args.out} ({len(cal.cameras)} cameras, world frame: {reference}, mm) in "
          f"{cal.seconds:.1f} s")
    return 0


def _refine(args, cameras: list, reference: int) -> list:
    """Camera poses refined from the points of --refine-points; prints before and after."""
    import numpy as np

    from kinematics.cameras import PinholeCamera
    from videotrack.calibration.refine import refine_extrinsics, triangulated_errors
    from videotrack.errors import VideoTrackError

    path = args.refine_points
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
        refined, _ = refine_extrinsics(cameras, p2d, reference=reference)
    except VideoTrackError as err:
        raise err.located(file=path) from None
    print(f"refined from {p2d.shape[1]} points: reprojection median {before:.3f} px before, "
          f"{np.nanmedian(triangulated_errors(refined, p2d)):.3f} px after (triangulated)")
    return refined


def _convert(args) -> int:
    from videotrack.calibration.formats import read_cameras
    from videotrack.errors import VideoTrackError
    from videotrack.project.outputs import guard_outputs

    if args.board is not None or args.camera:
        raise VideoTrackError("--import converts a camera file: give no board or --camera",
                              field="--import")
    inputs = {args.import_file: "the imported camera file"}
    if args.refine_points:
        inputs[args.refine_points] = "the points"
    guard_outputs(_outputs(args), inputs, force=args.force)
    from videotrack.calibration.formats import guess_format

    fmt = args.format or guess_format(args.import_file)
    cameras = read_cameras(args.import_file, fmt, dlt_size=_size(args.dlt_size),
                           dlt_origin=args.dlt_origin)
    if args.refine_points:
        refined = _refine(args, list(cameras.values()), 0)
        cameras = {c.name: c for c in refined}
    _write(args, cameras, None, units="mm" if fmt == "qca" else None)  # others: unknown
    print(f"wrote {args.out} ({len(cameras)} cameras from {args.import_file})")
    return 0
