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
                          "after --import. Priors hold each camera near its place (the rig "
                          "keeps its size); a change of a baseline by more than 1 %% or a "
                          "turn of more than 5° is refused")
    how.add_argument("--free-rig", action="store_true",
                     help="with --refine-points: no priors and no tolerance, for a rig that "
                          "really moved (the change is listed)")
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


def _outputs(args):
    from videotrack.workflow.calibrate import Outputs

    return Outputs(out=args.out, anipose_out=args.anipose_out, dlt_out=args.dlt_out,
                   report_png=args.report_png, opencv_out=args.opencv_out,
                   dlt_origin=args.dlt_origin)


def _print_refinement(refinement) -> None:
    if refinement is not None:
        print(f"refined from {refinement.points} points: reprojection median "
              f"{refinement.before_px:.3f} px before, {refinement.after_px:.3f} px after "
              f"(triangulated); per camera: " + ", ".join(
                  f"{n} {e:.2f} px" for n, e in refinement.per_camera_px.items()))
        print("the rig's change (lengths in the camera file's unit):")
        for line in refinement.change.lines():
            print(line)


def run(args) -> int:
    import sys

    from tqdm import tqdm

    from videotrack.errors import VideoTrackError
    from videotrack.workflow.calibrate import calibrate_cameras

    if args.import_file is not None:
        return _convert(args)
    if args.board is None:
        raise VideoTrackError("give a board config (or --import FILE to convert)",
                              field="board")
    cams = _cameras(args.camera)
    bars: list = []

    def progress(n: int, total: int) -> None:
        if not bars:
            bars.append(tqdm(total=args.restarts, desc="bundle adjustment", unit="start",
                             leave=False, file=sys.stderr, disable=None))
        bars[0].update(n - bars[0].n)
        if n >= total:
            bars[0].close()

    try:
        done = calibrate_cameras(
            args.board, cams, _outputs(args), reference=args.reference,
            world_view=args.world_view, distortion=args.distortion,
            intrinsics=args.intrinsics, fix_intrinsics=args.fix_intrinsics,
            intrinsics_only=args.intrinsics_only, refine_points=args.refine_points,
            free_rig=args.free_rig,
            restarts=args.restarts, max_frames=args.max_frames, seed=args.seed,
            cache=not args.no_cache, force=args.force, progress=progress)
    finally:
        for bar in bars:
            bar.close()
    print(f"board: {done.board}")
    if done.tree:
        print("spanning tree: " + ", ".join(f"{a}-{b} ({n} shared views)"
                                            for a, b, n in done.tree))
    for line in done.report:
        print(line)
    _print_refinement(done.refinement)
    print(f"wrote {done.out} ({done.cameras} cameras, world frame: {done.world_frame}, mm) in "
          f"{done.seconds:.1f} s")
    return 0


def _convert(args) -> int:
    from videotrack.errors import VideoTrackError
    from videotrack.workflow.calibrate import convert_cameras

    if args.board is not None or args.camera:
        raise VideoTrackError("--import converts a camera file: give no board or --camera",
                              field="--import")
    done = convert_cameras(args.import_file, _outputs(args), fmt=args.format,
                           dlt_size=_size(args.dlt_size), refine_points=args.refine_points,
                           free_rig=args.free_rig,
                           force=args.force)
    from videotrack.commands._common import note

    for line in done.warnings:
        note(f"warning: {line}")
    _print_refinement(done.refinement)
    print(f"wrote {done.out} ({done.cameras} cameras from {done.source})")
    return 0
