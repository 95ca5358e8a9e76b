"""``videotrack fit`` and ``videotrack run``: joint angles from detections by annealing."""

from __future__ import annotations

import argparse
from pathlib import Path

from kinematics.fit.settings import START_MODES

EXAMPLES = """\
examples:
  # fit every frame of the detections named in the project file
  videotrack fit project.toml
  # detect (if not up to date) and fit in one go, with a plot of the angles
  videotrack run project.toml --plot
  # a quick look: frames 0-99 with a 5x shorter schedule
  videotrack fit project.toml --frames 0:100 --n-end 7000
  # the paper's settings (Table 1, Eq. 5, one answer per frame), e.g. to compare
  videotrack fit project.toml --paper

the project file needs, besides [video], [[views]] and [[filters.steps]]:
  [chain]
  path = "locust_hindleg.xml"    # the kinematic chain (see docs/formats.md)
  [cameras]
  path = "cameras.toml"          # one camera per view (see docs/cameras.md)
  [anneal]                       # optional: the best measured settings are the default
  profile = "best"               # or "paper": Table 1 and Eq. 5 (reproduces Table 2)
  seed = 0

Results: a CSV per video (frame, joint.axis angles in degrees, error, error per view, runs,
iterations, status, 3D positions of markers and joints) and a .json sidecar with the seed,
every parameter and the run's warnings. An interrupted fit resumes where it stopped when run
again (and says so). The results never replace an input (chain, cameras, video, config,
detections), nor without --force an existing file of another kind.

Before fitting, the set-up is checked: views whose detections disagree in 3D, a chain that
does not fit the detections (on a sample of frames fitted first), a video without markers are
refused with the cause in one line (--accept-setup fits anyway). Each frame's status rests on
the noise model: a frame whose marker residuals are not what the views' noise allows is
'failed' (docs/concepts.md, "What a status means").

exit status: 0 done (warnings are printed, not errors); 1 an error, a refused set-up among
them; 3 the results are incomplete (the video could not be read to the end, not one frame was
fitted, or most frames failed), unless --allow-incomplete.
"""


def _add_common(p) -> None:
    p.add_argument("config", type=Path,
                   help="project file (TOML), or with --trial a project folder")
    p.add_argument("--trial", metavar="NAME",
                   help="a trial of the project folder CONFIG, e.g. session1/trial01")
    p.add_argument("--frames", metavar="A:B",
                   help="records A (included) to B (excluded) of the detections, 0-based")
    p.add_argument("--results", type=Path, metavar="PATH",
                   help="results CSV (default: [fit] results, else beside the detections)")
    p.add_argument("--plot", action="store_true", default=None,
                   help="also write <results>.png with the angle time courses")
    p.add_argument("--jobs", "-j", type=int, metavar="N",
                   help="threads for fitting (default: [fit] jobs, else all cores)")
    tune = p.add_argument_group("annealing (override [anneal])")
    tune.add_argument("--n-end", type=int, metavar="N",
                      help="iterations per run; N_l and N_tau scale with it")
    tune.add_argument("--seed", type=int, help="seed of the random streams")
    tune.add_argument("--paper", dest="profile", action="store_const", const="paper",
                      help="the paper's settings (profile 'paper': Table 1, Eq. 5, no "
                           "refinement, one answer per frame) under the [anneal] keys set")
    tune.add_argument("--refine", action="store_true", default=None,
                      help="polish each fit by Levenberg-Marquardt")
    tune.add_argument("--start", choices=START_MODES,
                      help="start posture: the histogram means, the previous frame's result, "
                           "or 'track' (a short anneal from the previous frame's result; "
                           "[anneal] start)")
    p.add_argument("--force", action="store_true",
                   help="recompute even if the outputs are up to date; replace an existing "
                        "file of another kind at an output path (never an input)")
    p.add_argument("--allow-incomplete", action="store_true",
                   help="exit 0 although the results are incomplete (the video could not be "
                        "read to the end, or no frame was fitted, or most frames failed)")
    p.add_argument("--accept-setup", action="store_true", default=None,
                   help="fit although the set-up checks find the cameras, views, chain or "
                        "video wrong; the problems stay in the results' warnings ([anneal] "
                        "accept_setup)")


def add_parser(subparsers) -> None:
    desc = ("Fit the chain to the detected markers of every frame by simulated annealing "
            "(paper Eq. 5 and 6, Table 1), re-analyse frames whose error stays above the "
            "threshold, and write joint angles, errors and 3D points.")
    fit = subparsers.add_parser("fit", help="fit the chain to existing detections",
                                description=desc, epilog=EXAMPLES,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_common(fit)
    fit.set_defaults(func=run_fit)
    run = subparsers.add_parser("run", help="detect markers and fit the chain in one go",
                                description="Run 'videotrack detect' (skipped when the "
                                "detections are up to date) and then 'videotrack fit'. " + desc,
                                epilog=EXAMPLES,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_common(run)
    run.set_defaults(func=run_run)


def run_run(args) -> int:
    return run_fit(args, detect=True)


def run_fit(args, detect: bool = False) -> int:
    """``fit`` (the detections as they are), or with ``detect`` ``run`` (detected first when
    stale)."""
    import numba
    import numpy as np

    from videotrack.commands._common import (
        incomplete_status,
        note,
        print_warnings,
        step_bars,
    )
    from videotrack.detect.video import parse_frame_range
    from videotrack.errors import VideoTrackError
    from videotrack.project.folders import command_config
    from videotrack.workflow import run_project

    config = command_config(args.config, args.trial)
    frames = None
    if args.frames:
        try:
            frames = slice(*parse_frame_range(args.frames))
        except ValueError as err:
            raise VideoTrackError(str(err), field="--frames") from None
    anneal = {"n_end": args.n_end, "seed": args.seed, "refine": args.refine,
              "start": args.start, "profile": args.profile,
              "accept_setup": args.accept_setup}
    with step_bars() as progress:
        run = run_project(config, detect=detect, force=args.force, anneal=anneal,
                          frames=frames, results=args.results, plot=args.plot,
                          threads=args.jobs, progress=progress, log=note)
    print_warnings(run)
    if detect and run.detections_path is not None:  # None: fitted to keypoint files
        from videotrack.commands.detect import print_detected

        if run.detected:
            print_detected(run.detections, run.detections_path)
        else:
            print(f"{run.detections_path} is up to date (--force detects again)")
    if run.fitted:
        results, seconds, n = run.results, run.fit_seconds, run.n_frames
        counts = {s: results.status.count(s) for s in dict.fromkeys(results.status)}
        if run.resumed:
            print(f"resumed an interrupted fit: {run.resumed} of {n} frames kept from its "
                  "checkpoint")
        finite = results.error[np.isfinite(results.error)]
        print(f"fitted {n} frames in {seconds:.1f} s ({n / max(seconds, 1e-9):.1f} frames/s, "
              f"{numba.get_num_threads()} threads); median error "
              f"{np.median(finite) if finite.size else float('nan'):.2f} "
              f"{error_unit(results, run.model)}")
        print("status: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
        _print_views(results)
        print(f"wrote {run.results_path} (+ .json sidecar)")
    else:
        print(f"{run.results_path} is up to date (--force fits again)")
    if run.plot_path is not None:
        print(f"wrote {run.plot_path}")
    return incomplete_status(run, args.allow_incomplete)


def _print_views(results) -> None:
    """Each view's median error over the frames to trust, and a warning for a view whose
    errors stand out (its camera's calibration may be wrong)."""
    import numpy as np

    from kinematics.cameras.checks import camera_warnings
    from videotrack.commands._common import note

    per_view = results.error_per_view[results.ok_mask()]
    if len(results.view_names) < 2 or not len(per_view):
        return
    medians = {}
    for v, name in enumerate(results.view_names):
        finite = per_view[:, v][np.isfinite(per_view[:, v])]
        medians[name] = float(np.median(finite)) if finite.size else float("nan")
    print("median error per view: " + ", ".join(f"{n} {e:.2f} px" for n, e in medians.items()))
    for line in camera_warnings([], medians):
        note(f"warning: {line.replace('camera ', 'view ', 1)}")


def error_unit(results, model) -> str:
    """The unit of E in ``results``: px for a fit to 2D points; for 3D points (no views) the
    camera file's length unit ("length units" where the file does not say)."""
    if results.view_names:
        return "px"
    units = None
    if model is not None:
        from kinematics.cameras.files import load_camera_file
        from kinematics.errors import KinematicsError

        try:
            units = load_camera_file(model.cameras_path).units
        except (KinematicsError, OSError):  # an imported format: no units key
            units = None
    return units if units and units != "px" else "length units (the camera file's)"
