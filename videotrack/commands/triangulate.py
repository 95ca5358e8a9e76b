"""``videotrack triangulate``: 2D keypoints of several cameras -> Anipose pose-3d CSV."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from kinematics.observe.triangulation import LOSSES
from videotrack.io.keypoints import FORMATS
from videotrack.project.config import TRIANGULATION_INITS, TRIANGULATION_METHODS

EXAMPLES = """\
examples:
  # SLEAP tracks of four cameras, named as in an Anipose calibration
  videotrack triangulate calibration.toml back=back.analysis.h5 mid=mid.analysis.h5 \\
      top=top.analysis.h5 side=side.analysis.h5 -o trial.pose3d.csv
  # OpenPose JSON folders of a Pose2Sim session, keypoints scored below 0.3 left out
  videotrack triangulate Calib.toml cam01_json cam02_json cam03_json cam04_json \
      --model BODY_25B --min-score 0.3 -o balancing.csv
  # DeepLabCut files in the order of the cameras of a VideoTrack camera file, RANSAC
  videotrack triangulate cameras.toml cam1DLC.h5 cam2DLC.h5 cam3DLC.h5 -o out.csv \\
      --method ransac --min-cams 2 --inlier-px 10
  # the spatiotemporal optimisation with the chain's segments as limbs of unknown length
  videotrack triangulate calibration.toml a=a.h5 b=b.h5 c=c.h5 -o out.csv --method optim \\
      --limbs hip,knee knee,ankle ankle,toe --min-score 0.5

The camera file is a VideoTrack camera file ([cameras.NAME] tables, see docs/cameras.md), a
project file (its [cameras] path is followed) or an Anipose/Pose2Sim calibration.toml. Each
KEYPOINTS is CAMERA=PATH or a PATH (then the files go to the cameras in file order).
Keypoints with a score below --min-score are not used; the others weight their camera's
equations by their score unless --unweighted. For crop and frame offsets and 2D filters, run
'videotrack keypoints ... -o folder/' first and triangulate the files it writes.
The output has Anipose's columns <bp>_x,_y,_z,_error,_ncams,_score, M_00..M_22, center_0..2
and fnum (the video's frame numbers); error is the mean reprojection error in px over the
cameras used, score the lowest score among them. An existing file that is not a pose-3d CSV
is not replaced (--force does); an input never is.
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "triangulate",
        help="triangulate 2D keypoints of several calibrated cameras into an Anipose "
             "pose-3d CSV",
        description=(
            "Read the 2D keypoints of each camera (DeepLabCut, SLEAP, OpenPose, Lightning Pose, "
            "Anipose pose-2d), put them on common frames and triangulate every body part: "
            "linear (confidence-weighted DLT, aniposelib's), RANSAC over camera subsets, or "
            "the spatiotemporal optimisation of Anipose (robust reprojection, smoothness, "
            "limb lengths). Writes Anipose's pose-3d CSV and prints the reprojection error."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("cameras", type=Path,
                   help="camera file (TOML), project file, or Anipose calibration.toml")
    p.add_argument("keypoints", nargs="+", metavar="KEYPOINTS",
                   help="CAMERA=PATH or PATH: a keypoint file (or OpenPose JSON folder) per "
                        "camera")
    p.add_argument("--output", "-o", type=Path, required=True, metavar="CSV",
                   help="the pose-3d CSV to write")
    p.add_argument("--method", choices=TRIANGULATION_METHODS, default="linear",
                   help="triangulation backend (default linear)")
    p.add_argument("--format", metavar="FORMAT",
                   help=f"keypoint file format (default: detected): {', '.join(FORMATS)}")
    p.add_argument("--model", metavar="NAME",
                   help="OpenPose keypoint model naming the points: BODY_25, BODY_25B, COCO")
    p.add_argument("--individual", metavar="NAME",
                   help="the animal or person to take (a name or an index; default the first)")
    p.add_argument("--min-score", type=float, default=0.0, metavar="S",
                   help="ignore keypoints scored below S (Anipose's score_threshold; "
                        "default 0)")
    p.add_argument("--unweighted", action="store_true",
                   help="do not weight by score (aniposelib's DLT and optimisation): neither "
                        "the linear equations nor the reprojection residuals")
    ran = p.add_argument_group("RANSAC (--method ransac, or --init ransac)")
    ran.add_argument("--min-cams", type=int, default=2, metavar="N",
                     help="smallest camera subset tried (default 2)")
    ran.add_argument("--good-px", type=float, default=0.5, metavar="PX",
                     help="stop at the first subset reprojecting within PX (default 0.5)")
    ran.add_argument("--max-px", type=float, default=200.0, metavar="PX",
                     help="leave a point out whose best subset reprojects worse (default 200)")
    ran.add_argument("--inlier-px", type=float, default=0.0, metavar="PX",
                     help="re-solve with every camera within PX of the best subset's point "
                          "(default 0: off)")
    opt = p.add_argument_group("optimisation (--method optim)")
    opt.add_argument("--init", choices=TRIANGULATION_INITS, default="linear",
                     help="starting points (default linear)")
    opt.add_argument("--limbs", nargs="+", default=(), metavar="A,B",
                     help="pairs of body parts whose distance stays constant")
    opt.add_argument("--limb-lengths", nargs="+", type=float, metavar="L",
                     help="their lengths in world units, one per limb (default: unknown, "
                          "estimated)")
    opt.add_argument("--smooth", type=float, default=2.0, metavar="BETA",
                     help="weight of the smoothness term, β_time (default 2, the Anipose "
                          "paper's; lower it for small, fast movements)")
    opt.add_argument("--n-deriv", type=int, default=1, metavar="N",
                     help="order of the smoothed derivative (default 1)")
    opt.add_argument("--limb-weight", type=float, default=2.0, metavar="ALPHA",
                     help="weight of the limb-length term (default 2)")
    opt.add_argument("--loss", choices=tuple(LOSSES), default="soft_l1",
                     help="robust loss of the reprojection term (default soft_l1)")
    opt.add_argument("--loss-px", type=float, default=15.0, metavar="PX",
                     help="scale of the robust loss (default 15)")
    opt.add_argument("--chunk", type=int, default=300, metavar="FRAMES",
                     help="frames optimised together (default 300)")
    opt.add_argument("--overlap", type=int, default=30, metavar="FRAMES",
                     help="frames of context on each side of a chunk (default 30)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing file of another kind at --output (never an input)")
    p.set_defaults(func=run)


def load_any_cameras(path: Path) -> dict:
    """Cameras of a VideoTrack camera file, of a project file (its ``[cameras] path``), or of
    an Anipose/Pose2Sim calibration.toml."""
    import tomllib

    from kinematics.cameras.files import import_anipose_toml, load_cameras

    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        doc = None  # load_cameras says what is wrong, with the line
    if isinstance(doc, dict) and "cameras" not in doc:
        return import_anipose_toml(path)
    if isinstance(doc, dict) and isinstance(doc["cameras"].get("path"), str):
        return load_any_cameras(path.parent / doc["cameras"]["path"])  # a project file
    return load_cameras(path)


def _assign(cameras: dict, specs: list[str]) -> dict[str, Path]:
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


def run(args) -> int:
    import numpy as np
    from tqdm import tqdm

    from kinematics.observe import triangulation as tri
    from videotrack.commands._common import note
    from videotrack.errors import VideoTrackError
    from videotrack.io.keypoints import align_cameras, read_keypoints
    from videotrack.io.pose3d import write_pose3d
    from videotrack.project.outputs import guard_outputs

    if args.method != "optim" and (args.limbs or args.limb_lengths):
        raise VideoTrackError("limbs constrain only the optimisation (--method optim)",
                              field="--limbs")
    cameras = load_any_cameras(args.cameras)
    files = _assign(cameras, args.keypoints)
    inputs = {args.cameras: "the camera file", **{p: f"the keypoints of {n}"
                                                 for n, p in files.items()}}
    guard_outputs({args.output: "pose3d"}, inputs, force=args.force, field="--output")
    individual = args.individual
    if individual is not None and individual.lstrip("-").isdigit():
        individual = int(individual)
    tracks = {n: read_keypoints(p, args.format, individual=individual, model=args.model)
              for n, p in files.items()}
    names, frames, xy, score = align_cameras(tracks)
    cams = [cameras[n] for n in files]
    common = dict(min_score=args.min_score, weighted=not args.unweighted)
    ransac = dict(min_cams=args.min_cams, good_px=args.good_px, max_px=args.max_px,
                  inlier_px=args.inlier_px)
    with tqdm(total=len(frames), unit="frame", desc="triangulating", file=sys.stderr,
              leave=False, disable=None) as bar:
        if args.method == "optim":
            result = tri.triangulate_optim(
                cams, xy, score, **common, init=args.init, limbs=_limbs(args.limbs, names),
                limb_lengths=args.limb_lengths, smooth=args.smooth, n_deriv=args.n_deriv,
                limb_weight=args.limb_weight, loss=args.loss, loss_px=args.loss_px,
                chunk=args.chunk, overlap=args.overlap,
                progress=lambda done, total: bar.update(done - bar.n),
                **(ransac if args.init == "ransac" else {}))
        else:
            parts = []
            for s in range(0, max(len(frames), 1), 500):  # blocks, for the bar
                block = slice(s, s + 500)
                if args.method == "ransac":
                    parts.append(tri.triangulate_ransac(cams, xy[:, block], score[:, block],
                                                        **common, **ransac))
                else:
                    parts.append(tri.triangulate_linear(cams, xy[:, block], score[:, block],
                                                        **common))
                bar.update(len(parts[-1].xyz))
            result = tri.Triangulation(*(np.concatenate([getattr(p, f) for p in parts],
                                                        axis=1 if f == "used" else 0)
                                         for f in ("xyz", "error", "ncams", "score", "used")))
    write_pose3d(args.output, names, result.xyz, result.error, result.ncams, result.score,
                 frames)
    placed = np.isfinite(result.xyz).all(axis=-1)
    if not placed.any():
        note("warning: no point was seen by two cameras; the output holds only NaN")
    err = result.error[placed & np.isfinite(result.error)]
    med = f"{np.median(err):.2f}" if err.size else "n/a"
    print(f"triangulated {placed.sum()} of {placed.size} points ({len(names)} body parts x "
          f"{len(frames)} frames, {len(cams)} cameras, {args.method}); reprojection error "
          f"median {med} px")
    print(f"wrote {args.output}")
    return 0
