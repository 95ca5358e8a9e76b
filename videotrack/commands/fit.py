"""``videotrack fit`` and ``videotrack run``: joint angles from detections by annealing."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

EXAMPLES = """\
examples:
  # fit every frame of the detections named in the project file
  videotrack fit project.toml
  # detect (if not up to date) and fit in one go, with a plot of the angles
  videotrack run project.toml --plot
  # a quick look: frames 0-99 with a 5x shorter schedule and refinement
  videotrack fit project.toml --frames 0:100 --n-end 7000 --refine

the project file needs, besides [video], [[views]] and [[filters.steps]]:
  [chain]
  path = "locust_hindleg.xml"    # the kinematic chain (see docs/formats.md)
  [cameras]
  path = "cameras.toml"          # one camera per view (see docs/cameras.md)
  [anneal]                       # optional: Table 1 of the paper is the default
  n_end = 35000
  seed = 0

Results: a CSV per video (frame, joint.axis angles in degrees, error, error per view, runs,
iterations, status, 3D positions of markers and joints) and a .json sidecar with the seed and
every parameter. An interrupted fit resumes where it stopped when run again.
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
    tune.add_argument("--refine", action="store_true", default=None,
                      help="polish each fit by Levenberg-Marquardt")
    tune.add_argument("--start", choices=("mean", "previous"),
                      help="start posture: histogram means or the previous frame")
    p.add_argument("--force", action="store_true",
                   help="recompute even if the outputs are up to date")


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
    from videotrack.commands import detect

    det_args = argparse.Namespace(config=args.config, trial=args.trial, frames=None,
                                  output=None, force=args.force)
    code = detect.run(det_args)
    if code:
        return code
    return run_fit(args)


def run_fit(args) -> int:
    import numba
    import numpy as np
    from tqdm import tqdm

    from videotrack.detect import default_output
    from videotrack.detections import load_detections
    from videotrack.errors import VideoTrackError
    from videotrack.pipeline import (
        check_detection_views,
        default_results_path,
        fit_project,
        load_model,
        results_stale_reason,
    )
    from videotrack.project import command_config
    from videotrack.results import read_results
    from videotrack.video import parse_frame_range

    config = command_config(args.config, args.trial)
    model = load_model(config, n_end=args.n_end, seed=args.seed, refine=args.refine,
                       start=args.start)
    det_path = default_output(config)
    if not det_path.exists():
        raise VideoTrackError("no detections yet: run 'videotrack detect' first (or use "
                              "'videotrack run')", file=det_path)
    detections = load_detections(det_path)
    _check_detections_fresh(config, detections, det_path)
    check_detection_views(model, detections, det_path)
    frames = None
    if args.frames:
        try:
            start, stop = parse_frame_range(args.frames)
        except ValueError as err:
            raise VideoTrackError(str(err), field="--frames") from None
        frames = range(start, min(stop if stop is not None else detections.n_records,
                                  detections.n_records))
    jobs = args.jobs if args.jobs is not None else config["fit"]["jobs"]
    if jobs:
        numba.set_num_threads(max(1, min(jobs, numba.config.NUMBA_NUM_THREADS)))
    out = args.results or default_results_path(config, det_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not args.force and frames is None and results_stale_reason(
            model, det_path, out, detections.n_records) is None:
        print(f"{out} is up to date (--force fits again)")
        _maybe_plot(args, config, read_results(out), out, model)
        return 0
    total = detections.n_records if frames is None else len(frames)
    bad = done = 0
    t0 = time.perf_counter()
    with tqdm(total=total, unit="frame", desc="fitting", file=sys.stderr, leave=False,
              disable=None) as bar:
        def progress(r) -> None:
            nonlocal bad, done
            bad += not r.ok
            done += 1
            bar.update(1)
            bar.set_postfix_str(f"bad {100 * bad / done:.1f}%", refresh=False)

        results = fit_project(model, detections, det_path, out, frames, progress)
    seconds = time.perf_counter() - t0
    n = len(results)
    counts = {s: results.status.count(s) for s in dict.fromkeys(results.status)}
    print(f"fitted {n} frames in {seconds:.1f} s ({n / max(seconds, 1e-9):.1f} frames/s, "
          f"{numba.get_num_threads()} threads); median error "
          f"{np.nanmedian(results.error) if n else float('nan'):.2f} px")
    print("status: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    print(f"wrote {out} (+ .json sidecar)")
    _maybe_plot(args, config, results, out, model)
    return 0


def _maybe_plot(args, config, results, out, model) -> None:
    """The angle plot, when asked for on the command line or in [fit] plot."""
    if args.plot or (args.plot is None and config["fit"]["plot"]):
        from videotrack.pipeline import default_plot_path
        from videotrack.plots import plot_angles

        png = plot_angles(results, default_plot_path(out), model.body.locked_mask())
        print(f"wrote {png}")


def _check_detections_fresh(config, detections, det_path) -> None:
    """Refuse detections made from another video or with other detection settings."""
    import warnings

    from videotrack.detect import settings_from_config, video_paths
    from videotrack.detections import check_fresh
    from videotrack.errors import VideoTrackError, VideoTrackWarning
    from videotrack.video import open_videos

    paths = video_paths(config)
    if not all(p.exists() for p in paths):
        warnings.warn(f"{paths[0]}: video not found; cannot check that {det_path.name} was "
                      "made from it", VideoTrackWarning, stacklevel=2)
        return
    with open_videos(paths) as videos:
        try:
            check_fresh(detections, videos, settings_from_config(config))
        except VideoTrackError as err:
            raise VideoTrackError(f"stale detections: {err.message}; run 'videotrack detect' "
                                  "again", file=det_path) from None
