"""``videotrack demo``: the paper's accuracy test end to end, scored against ground truth."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from videotrack.synth.paper_setup import PAPER_FRAMES

EXAMPLES = f"""\
examples:
  # the whole method in a few seconds: render, detect, fit, score (files in ./videotrack-demo)
  videotrack demo
  # elsewhere, and draw fitted against true angles
  videotrack demo --out mydemo --plot
  # leave no files behind
  videotrack demo --temp
  # a quicker look: 100 frames with a 5x shorter annealing schedule
  videotrack demo --frames 100 --n-end 7000

What it does (the paper's Sect. 3.2): renders a synthetic video of a locust hind leg moving
through {PAPER_FRAMES} frames of 10 random movement sequences, seen from the side and from
above with 4-px markers at the joints ('videotrack synth'), detects the markers ('detect'),
fits the chain by simulated annealing with the paper's Table 1 parameters ('fit'), and scores
the joint angles against the ground truth ('eval'), beside the paper's Table 2. The first
run after installing compiles the numba kernels (about half a minute); later runs start
at once. The output folder is a complete project: open it with 'videotrack gui
DIR/project.toml', or fit it again with 'videotrack run DIR/project.toml'.
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "demo",
        help="run the paper's accuracy test: synthetic video, detection, fit, errors",
        description=(
            "Generate the paper's locust test video with ground truth, detect and fit it, "
            "and print the joint-angle errors beside the paper's Table 2 and the throughput."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument("--out", type=Path, metavar="DIR", default=Path("videotrack-demo"),
                       help="write the project here (default: ./videotrack-demo)")
    where.add_argument("--temp", action="store_true",
                       help="work in a temporary folder and delete it afterwards")
    p.add_argument("--frames", type=int, default=PAPER_FRAMES,
                   help=f"frames of the video (default: {PAPER_FRAMES}, as the paper)")
    p.add_argument("--n-end", type=int, metavar="N",
                   help="annealing iterations per run (default: 35000, Table 1); N_l and "
                        "N_tau scale with it")
    p.add_argument("--seed", type=int, default=0, help="seed of the fit (default 0)")
    p.add_argument("--plot", nargs="?", const="", metavar="PNG",
                   help="draw fitted and true angles (default file: DIR/angles.png, or "
                        "demo_angles.png here with --temp)")
    p.set_defaults(func=run)


def run(args) -> int:
    import contextlib
    import tempfile
    import time

    import numba
    import numpy as np
    from tqdm import tqdm

    from videotrack.commands._common import print_warnings, step_bars
    from videotrack.errors import VideoTrackError
    from videotrack.project.config import load_config
    from videotrack.results.evaluate import evaluate, truth_angles
    from videotrack.results.tables import read_table, text_table
    from videotrack.synth.paper_setup import (
        PAPER_DETECTION_FPS,
        PAPER_FIT_FPS,
        PAPER_VIEW_ERROR_PX,
        TABLE2_BOTH_VIEWS,
        TABLE2_SYMBOLS,
        write_paper_project,
    )
    from videotrack.workflow import run_project

    if args.frames < 1:
        raise VideoTrackError(f"must be at least 1, got {args.frames}", field="--frames")

    def bar(desc: str, total: int | None = None):
        return tqdm(total=total, desc=desc, unit="frame", file=sys.stderr, leave=False,
                    disable=None)

    with contextlib.ExitStack() as stack:
        out = Path(stack.enter_context(tempfile.TemporaryDirectory(
            prefix="videotrack-demo-"))) if args.temp else args.out
        print(f"VideoTrack demo: the paper's accuracy test (Sect. 3.2), a locust hind leg "
              f"seen from the side and from above, {args.frames} frames")
        t0 = time.perf_counter()
        with bar("rendering", args.frames) as b:
            project = write_paper_project(out, args.frames,
                                          progress=lambda k: b.update(k - b.n))
        t_render = time.perf_counter() - t0
        print(f"  rendered the video and its ground truth in {t_render:.1f} s")

        with step_bars() as progress:
            run = run_project(load_config(project.config), force=True, plot=False,
                              anneal={"n_end": args.n_end, "seed": args.seed},
                              progress=progress)
        print_warnings(run)
        t_detect, t_fit = run.detect_seconds, run.fit_seconds
        print(f"  detected {len(run.detections.points)} markers in {t_detect:.1f} s "
              f"({args.frames / t_detect:.0f} frames/s; the paper: {PAPER_DETECTION_FPS:g})")
        results, model, n = run.results, run.model, run.n_frames
        runs = {s: results.status.count(s) for s in ("reanalysed", "failed")}
        print(f"  fitted {n} frames in {t_fit:.1f} s ({n / t_fit:.0f} frames/s on "
              f"{numba.get_num_threads()} threads, N_end {model.params.n_end}; the paper: "
              f"{PAPER_FIT_FPS:g}), {runs['reanalysed']} re-analysed, {runs['failed']} failed")
        e = results.error[np.isfinite(results.error)]
        print(f"  view error E: {e.mean():.2f} ± {e.std():.2f} px (the paper: "
              f"{PAPER_VIEW_ERROR_PX[0]:g} ± {PAPER_VIEW_ERROR_PX[1]:g} px)")

        columns, truth = read_table(project.truth)
        sums = [k for k in TABLE2_BOTH_VIEWS if "+" in k]
        ev = evaluate(results, columns, truth, sums)
        print("\nJoint-angle errors against the ground truth, degrees (the paper's Table 2, "
              "both views):")
        keys = list(TABLE2_BOTH_VIEWS)
        rows = [("RMSE, this run", *(f"{ev.row(k).rmse:.2f}" for k in keys)),
                ("RMSE, the paper", *(f"{TABLE2_BOTH_VIEWS[k]:.1f}" for k in keys)),
                ("median |error|", *(f"{ev.row(k).median:.2f}" for k in keys))]
        print(text_table(("", *(TABLE2_SYMBOLS[k] for k in keys)), rows))
        print(f"\n{n} frames analysed in {t_detect + t_fit:.1f} s: "
              f"{n / (t_detect + t_fit):.0f} frames/s end to end (the paper: "
              f"{1 / (1 / PAPER_DETECTION_FPS + 1 / PAPER_FIT_FPS):.2f} frames/s)")

        if args.plot is not None:
            from videotrack.results.plots import plot_angles

            png = Path(args.plot) if args.plot else (
                Path("demo_angles.png") if args.temp else out / "angles.png")
            plot_angles(results, png, model.body.locked_mask(),
                        truth=truth_angles(results, columns, truth))
            print(f"wrote {png}")
        if not args.temp:
            print(f"\nresults: {out / 'detections.results.csv'} (joint angles, errors, 3D "
                  f"points per frame)\nproject: {out / 'project.toml'} (video.avi, "
                  "truth.csv, detections.npz beside it); next:\n"
                  f"  videotrack gui {out / 'project.toml'}\n"
                  f"  videotrack eval {out / 'detections.results.csv'} {out / 'truth.csv'} "
                  "--sum J0.alpha+J1.beta")
    return 0
