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


def run(args) -> int:
    from tqdm import tqdm

    from videotrack.commands._common import note
    from videotrack.workflow.triangulate import triangulate_keypoints

    individual = args.individual
    if individual is not None and individual.lstrip("-").isdigit():
        individual = int(individual)
    bars: list = []

    def progress(done: int, total: int) -> None:
        if not bars:
            bars.append(tqdm(total=total, unit="frame", desc="triangulating",
                             file=sys.stderr, leave=False, disable=None))
        bars[0].update(done - bars[0].n)

    try:
        done = triangulate_keypoints(
            args.cameras, args.keypoints, args.output, method=args.method,
            keypoint_format=args.format, model=args.model, individual=individual,
            min_score=args.min_score, weighted=not args.unweighted, min_cams=args.min_cams,
            good_px=args.good_px, max_px=args.max_px, inlier_px=args.inlier_px,
            init=args.init, limbs=args.limbs, limb_lengths=args.limb_lengths,
            smooth=args.smooth, n_deriv=args.n_deriv, limb_weight=args.limb_weight,
            loss=args.loss, loss_px=args.loss_px, chunk=args.chunk, overlap=args.overlap,
            force=args.force, progress=progress)
    finally:
        for bar in bars:
            bar.close()
    if not done.placed:
        note("warning: no point was seen by two cameras; the output holds only NaN")
    med = f"{done.median_px:.2f}" if done.median_px is not None else "n/a"
    print(f"triangulated {done.placed} of {done.points} points ({done.body_parts} body parts "
          f"x {done.frames} frames, {done.cameras} cameras, {done.method}); reprojection "
          f"error median {med} px")
    if done.per_camera_px:
        print("per camera: " + ", ".join(f"{n} {e:.2f} px" for n, e in
                                         done.per_camera_px.items()))
    for line in done.warnings:
        note(f"warning: {line}")
    print(f"wrote {done.output}")
    return 0
