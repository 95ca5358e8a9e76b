"""``videotrack synth``: artificial marker videos with known ground truth."""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from videotrack.synth.project import LAYOUTS

EXAMPLES = """\
examples:
  # the paper's test video: locust hind leg, side + top view, 668 frames in 10 sequences
  videotrack synth out/locust
  # the same with noise, two static and two flickering ghosts and 2 % occlusions
  videotrack synth out/hard --noise 2 --ghosts 2 --flicker-ghosts 2 --occlusions 0.02
  # your chain and cameras, a trajectory from a CSV file (one column per axis, degrees)
  videotrack synth out/mine --chain leg.xml --cameras cameras.toml --angles angles.csv
  # a project folder of 12 short trials for 'videotrack batch'
  videotrack synth out/project --trials 12 --frames 100
  # given 3D marker trajectories (e.g. motion capture), no chain: one video per camera
  videotrack synth out/mocap --points points.csv --cameras cameras.toml --layout separate

Output folder: video.avi (or one video per camera with --layout separate), truth.csv
(angles, 3D points and 2D projections of every image), cameras.toml, chain.xml and
project.toml, a project config that 'videotrack detect' runs as it is. With --points there
is no chain and truth.csv holds the given points and their projections.

--points: a CSV (or NPZ, one 1-D array per column) with one row per image and columns
NAME.x, NAME.y, NAME.z per marker in the cameras' world units; an empty cell (NaN) is a
marker absent in that image, not drawn; other columns (frame) are ignored.

synth never writes over its own inputs (--chain, --cameras, --angles, --points) and, without
--force, never over an existing file of another kind (a video.avi that is no video, ...).
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "synth",
        help="render artificial marker videos with ground truth",
        description=(
            "Move a chain through a trajectory, project its markers through the cameras and "
            "draw them as anti-aliased discs, as the paper did to measure accuracy "
            "(Sect. 3.2). Without --chain/--cameras it makes the paper's locust test video; "
            "with --points it draws given 3D marker trajectories instead of a chain."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("out_dir", type=Path, help="output folder (created if needed)")
    src = p.add_argument_group("what moves")
    src.add_argument("--chain", type=Path, help="chain XML (default: bundled locust hind leg)")
    src.add_argument("--cameras", type=Path,
                     help="camera TOML file; every camera needs a size (default: the paper's "
                          "side and top views, 360x288 px each)")
    src.add_argument("--angles", type=Path,
                     help="trajectory CSV, one column per axis named joint.axis, degrees")
    src.add_argument("--points", type=Path,
                     help="3D marker trajectories to draw instead of a chain: CSV or NPZ, "
                          "columns NAME.x, NAME.y, NAME.z (empty/NaN: marker absent); needs "
                          "--cameras")
    src.add_argument("--frames", type=int, default=668,
                     help="images of generated smooth random motion (default: 668)")
    src.add_argument("--sequences", type=int, default=10,
                     help="independent concatenated movement sequences (default: 10)")
    src.add_argument("--keys", type=int, default=4,
                     help="key postures per sequence; more is faster motion (default: 4)")
    src.add_argument("--motion-seed", type=int, default=0, help="seed of the trajectory")
    src.add_argument("--trials", type=int, metavar="N",
                     help="write a project folder of N trials for 'videotrack batch' instead "
                          "(SESSION/TRIAL folders, ten per session, trial k moving with "
                          "motion seed + k; see docs/batch.md)")
    look = p.add_argument_group("how it looks")
    look.add_argument("--diameter", type=float, default=4.0, help="marker diameter, px (4)")
    look.add_argument("--intensity", type=float, default=230.0, help="marker grey level (230)")
    look.add_argument("--background", type=float, default=20.0, help="background grey (20)")
    look.add_argument("--noise", type=float, default=0.0, help="pixel noise sigma, grey levels")
    look.add_argument("--ghosts", type=int, default=0, help="static ghost markers per view")
    look.add_argument("--flicker-ghosts", type=int, default=0,
                      help="flickering ghost markers per view (on half of the images)")
    look.add_argument("--occlusions", type=float, default=0.0,
                      help="fraction of marker images hidden, e.g. 0.02")
    look.add_argument("--occlusion-length", type=int, default=3,
                      help="images an occlusion lasts (3)")
    look.add_argument("--interlaced", action="store_true",
                      help="two fields per frame at consecutive postures (PAL-style)")
    look.add_argument("--bottom-field-first", action="store_true",
                      help="with --interlaced: odd rows were exposed first")
    look.add_argument("--layout", choices=LAYOUTS,
                      default="side-by-side", help="views in one video, or one per camera")
    look.add_argument("--codec", choices=("ffv1", "png"), default="ffv1",
                      help="lossless FFV1 AVI or a PNG folder")
    look.add_argument("--fps", type=float, default=50.0, help="frame rate written (50)")
    look.add_argument("--seed", type=int, default=0, help="seed of noise, ghosts, occlusions")
    look.add_argument("--colour", action="append", default=[], metavar="COLOUR=MARKERS",
                      help="draw these markers (names or patterns, comma-separated) in a "
                           "colour (red, yellow, green, cyan, blue, magenta); repeat for each "
                           "colour, every marker needs one. The project gets one view per "
                           "camera and colour, matched to that colour's markers only. "
                           "E.g. --colour red=L* --colour green=R*")
    p.add_argument("--force", action="store_true",
                   help="replace existing files of another kind at the output paths (never "
                        "an input)")
    p.set_defaults(func=run)


def run(args) -> int:
    from videotrack.synth.project import SynthOptions
    from videotrack.workflow.synthesize import synthesize

    options = SynthOptions(
        marker_diameter=args.diameter, intensity=args.intensity, background=args.background,
        noise_sigma=args.noise, static_ghosts=args.ghosts, flicker_ghosts=args.flicker_ghosts,
        occlusion_fraction=args.occlusions, occlusion_length=args.occlusion_length,
        interlaced=args.interlaced, top_field_first=not args.bottom_field_first,
        layout=args.layout, seed=args.seed,
    )
    bars: list = []

    def progress(done: int, total: int) -> None:
        if not bars:
            bars.append(tqdm(total=total, unit="frame" if args.trials is None else "trial",
                             desc="rendering", leave=False))
        bars[0].update(done - bars[0].n)

    try:
        done = synthesize(
            args.out_dir, options, chain=args.chain, cameras=args.cameras, angles=args.angles,
            points=args.points, trials=args.trials, frames=args.frames,
            sequences=args.sequences, keys=args.keys, motion_seed=args.motion_seed,
            colours=args.colour, fps=args.fps, codec=args.codec, force=args.force,
            progress=progress)
    finally:
        for bar in bars:
            bar.close()
    views = f"{len(done.cameras)} views ({', '.join(done.cameras)})"
    if done.trials:
        first, last = (folder.relative_to(done.out_dir).as_posix()
                       for folder in (done.trials[0], done.trials[-1]))
        print(f"wrote a project of {len(done.trials)} trials of '{done.body}' through {views}: "
              f"{done.config}, chain.xml, cameras.toml and {first} ... {last} (video and "
              f"truth.csv each)")
        print(f"next: videotrack batch {done.out_dir}")
        return 0
    what = f"'{done.body}'" if done.points is None else f"{done.points} points"
    print(f"wrote {done.frames} frames ({done.images} images) of {what} through {views}:")
    for path in done.files:
        print(f"  {path}")
    print(f"next: videotrack detect {done.config}")
    return 0
