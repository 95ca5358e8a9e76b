"""``videotrack synth``: artificial marker videos with known ground truth."""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from videotrack.errors import VideoTrackError
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
    from kinematics.cameras.files import load_cameras
    from kinematics.model.chain_xml import loads_body
    from videotrack.synth.motion import read_angles_csv, smooth_random_motion
    from videotrack.synth.paper_setup import bundled_chain, locust_cameras
    from videotrack.synth.project import write_synthetic_project

    if args.points is not None:
        return _write_points(args)
    if args.chain is None:
        with bundled_chain("locust_hindleg.xml") as path:
            chain_path, chain_text = path, Path(path).read_text(encoding="utf-8")
    else:
        chain_path = args.chain
        try:
            chain_text = args.chain.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            raise VideoTrackError(f"cannot read chain: {err}", file=args.chain) from None
    body = loads_body(chain_text, source=str(chain_path))
    if args.cameras is None:
        if args.chain is not None:
            raise VideoTrackError("give --cameras for your own chain", field="--cameras")
        cameras = locust_cameras()
    else:
        cameras = load_cameras(args.cameras)
    options = _options(args)
    if args.angles is None and args.frames < 1:
        raise VideoTrackError(f"must be at least 1, got {args.frames}", field="--frames")
    _guard(args, list(cameras), chain=True)

    def trajectory(k: int = 0):
        if args.angles is not None:
            return read_angles_csv(args.angles, body)
        return smooth_random_motion(body, args.frames, args.sequences, args.keys,
                                    seed=args.motion_seed + k)

    if args.trials is not None:
        return _write_batch_project(args, body, chain_text, cameras, trajectory, options)
    angles = trajectory()
    n_frames = angles.shape[0] // (2 if args.interlaced else 1)
    with tqdm(total=n_frames, unit="frame", desc="rendering", leave=False) as bar:
        project = write_synthetic_project(args.out_dir, body, chain_text, cameras, angles,
                                          options, args.fps, args.codec,
                                          progress=lambda k: bar.update(k - bar.n))
    print(f"wrote {n_frames} frames ({project.n_images} images) of '{body.name}' through "
          f"{len(cameras)} views ({', '.join(cameras)}):")
    for path in (*project.videos, project.truth, project.cameras, project.chain,
                 project.config):
        print(f"  {path}")
    print(f"next: videotrack detect {project.config}")
    return 0


def _write_batch_project(args, body, chain_text, cameras, trajectory, options) -> int:
    from videotrack.synth.project import trial_names, write_synthetic_batch_project

    if args.trials < 1:
        raise VideoTrackError(f"must be at least 1, got {args.trials}", field="--trials")
    with tqdm(total=args.trials, unit="trial", desc="rendering", leave=False) as bar:
        folders = write_synthetic_batch_project(
            args.out_dir, trial_names(args.trials), body, chain_text, cameras, trajectory,
            options, args.fps, args.codec, progress=lambda k: bar.update(k - bar.n))
    print(f"wrote a project of {len(folders)} trials of '{body.name}' through {len(cameras)} "
          f"views ({', '.join(cameras)}): {args.out_dir / 'config.toml'}, chain.xml, "
          f"cameras.toml and {folders[0].relative_to(args.out_dir).as_posix()} ... "
          f"{folders[-1].relative_to(args.out_dir).as_posix()} (video and truth.csv each)")
    print(f"next: videotrack batch {args.out_dir}")
    return 0


def _options(args):
    from videotrack.detect.marker_colours import parse_colour
    from videotrack.synth.project import SynthOptions

    return SynthOptions(
        marker_diameter=args.diameter, intensity=args.intensity, background=args.background,
        noise_sigma=args.noise, static_ghosts=args.ghosts, flicker_ghosts=args.flicker_ghosts,
        occlusion_fraction=args.occlusions, occlusion_length=args.occlusion_length,
        interlaced=args.interlaced, top_field_first=not args.bottom_field_first,
        layout=args.layout, seed=args.seed,
        colours=tuple(parse_colour(text) for text in args.colour),
    )


def _write_points(args) -> int:
    """``--points``: render given 3D marker trajectories through the cameras."""
    from kinematics.cameras.files import load_camera_file
    from videotrack.synth.project import read_points, write_points_project

    given = [name for name, value in (("--chain", args.chain), ("--angles", args.angles),
                                      ("--trials", args.trials)) if value is not None]
    if given:
        raise VideoTrackError(f"--points draws given 3D points; it takes no {given[0]}",
                              field="--points")
    if args.cameras is None:
        raise VideoTrackError("give --cameras to draw --points through", field="--cameras")
    camera_file = load_camera_file(args.cameras)
    names, points = read_points(args.points)
    options = _options(args)
    _guard(args, list(camera_file.cameras), chain=False)
    n_frames = points.shape[0] // (2 if args.interlaced else 1)
    with tqdm(total=n_frames, unit="frame", desc="rendering", leave=False) as bar:
        project = write_points_project(args.out_dir, names, points, camera_file.cameras,
                                       options, args.fps, args.codec,
                                       progress=lambda k: bar.update(k - bar.n),
                                       units=camera_file.units)
    print(f"wrote {n_frames} frames ({project.n_images} images) of {len(names)} points "
          f"through {len(camera_file.cameras)} views ({', '.join(camera_file.cameras)}):")
    for path in (*project.videos, project.truth, project.cameras, project.config):
        print(f"  {path}")
    print(f"next: videotrack detect {project.config}")
    return 0


def _guard(args, camera_names: list[str], chain: bool) -> None:
    """Refuse to write over an input, or over an existing file of another kind unless
    --force (:func:`videotrack.project.outputs.guard_outputs`), before rendering anything."""
    from videotrack.project.outputs import guard_outputs
    from videotrack.synth.project import CODECS, trial_names

    ext = CODECS[args.codec][1]
    videos = ([f"video_{name}{ext}" for name in camera_names] if args.layout == "separate"
              else [f"video{ext}"])
    if args.codec == "png":
        videos = [n if n.endswith("_png") else f"{n}_png" for n in videos]
    video_kind = "folder" if args.codec == "png" else "video"

    def scene(folder: Path) -> dict:
        found = {folder / n: video_kind for n in videos}
        found.update({folder / "truth.csv": "csv", folder / "cameras.toml": "toml",
                      folder / "project.toml": "toml"})
        if chain:
            found[folder / "chain.xml"] = "xml"
        return found

    out = args.out_dir
    if args.trials is not None and args.trials >= 1:
        outputs = {out / "config.toml": "toml", out / "chain.xml": "xml",
                   out / "cameras.toml": "toml"}
        for name in trial_names(args.trials):
            outputs.update({**scene(out / name), out / name / "config.toml": "toml"})
    else:
        outputs = scene(out)
    inputs = {getattr(args, key): f"the --{key} file"
              for key in ("chain", "cameras", "angles", "points") if getattr(args, key)}
    guard_outputs(outputs, inputs, force=args.force)
