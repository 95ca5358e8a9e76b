"""``videotrack eval``: errors of fitted results against ground truth."""

from __future__ import annotations

import argparse
from pathlib import Path

EXAMPLES = """\
examples:
  # a synthetic project: fit it, then score the fit against the truth synth wrote
  videotrack eval demo/detections.results.csv demo/truth.csv
  # the paper's alpha+beta as a derived axis, 2-degree threshold, and a CSV of it all
  videotrack eval results.csv truth.csv --sum J0.alpha+J1.beta --threshold 2 --csv errors.csv

The truth is a CSV with a 'frame' column (record index, as in the results) and columns named
like the results' (joint.axis in degrees, marker.x/y/z and joint.x/y/z): the truth.csv of
'videotrack synth', or any table you build the same way. Angle errors are wrapped (359 vs 1
degree is 2 degrees); locked axes are left out; frames without a fit (no detections) are
counted, not scored. 3D errors are Euclidean distances in the chain's units.
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "eval",
        help="score fitted results against ground truth (angle and 3D errors)",
        description=(
            "Compare a results file with a ground-truth table frame by frame: per axis the "
            "RMSE, the median absolute error, the largest error and the share of frames off "
            "by more than a threshold; per marker and joint centre the 3D position error."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("results", type=Path, help="results CSV (videotrack fit/run/batch)")
    p.add_argument("truth", type=Path, help="ground-truth CSV (e.g. truth.csv of synth)")
    p.add_argument("--sum", action="append", default=[], metavar="EXPR",
                   help="a derived axis, e.g. J0.alpha+J1.beta (repeatable; + and -)")
    p.add_argument("--threshold", type=float, default=5.0, metavar="DEG",
                   help="a frame is off when an axis errs by more than this (default 5)")
    p.add_argument("--csv", type=Path, metavar="OUT",
                   help="also write the scores as CSV")
    p.add_argument("--force", action="store_true",
                   help="let --csv replace an existing file that is not a CSV (never an input)")
    p.set_defaults(func=run)


def run(args) -> int:
    from videotrack.errors import VideoTrackError
    from videotrack.results.evaluate import evaluate_files, format_evaluation, write_evaluation

    if not args.threshold >= 0:
        raise VideoTrackError(f"must be a number >= 0, got {args.threshold}",
                              field="--threshold")
    if args.csv is not None:  # never over an input; over another kind of file with --force
        from videotrack.project.outputs import guard_outputs

        guard_outputs({args.csv: "csv"}, {args.results: "the results", args.truth: "the truth"},
                      force=args.force, field="--csv")
    ev = evaluate_files(args.results, args.truth, args.sum, args.threshold)
    print(format_evaluation(ev))
    if args.csv is not None:
        print(f"wrote {write_evaluation(ev, args.csv)}")
    return 0
