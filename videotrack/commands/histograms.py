"""``videotrack histograms``: learn (Eq. 4), merge and inspect joint-angle histograms."""

from __future__ import annotations

import argparse
from pathlib import Path

EXAMPLES = """\
examples:
  # learn from two analysed videos (frames with status ok), write an archive
  videotrack histograms update chain.xml walk01.results.csv walk02.results.csv -o learned.xml
  # the same, written as a complete chain file with the learned histograms inside
  videotrack histograms update chain.xml walk*.results.csv --as-chain -o chain-learned.xml
  # combine archives of several experiments (weighted by their trial counts N)
  videotrack histograms merge labA.xml labB.xml -o combined.xml
  # look at them: a table per free axis, and bar plots
  videotrack histograms show chain-learned.xml --plot histograms.png

An output never replaces one of the command's inputs (e.g. -o chain.xml when learning from
chain.xml); an existing file of another kind is replaced only with --force.

Use a learned archive in a project with [chain] histograms = "learned.xml"; the annealing
then steps by the learned spreads s(H) and stays where the movement was seen (Sect. 2.2).
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "histograms", help="learn, merge and show joint-angle histograms",
        description="Joint-angle histograms are the constraints and priors of the fit "
                    "(paper Sect. 2.2): 360 one-degree bins per axis with a trial count N.",
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="histograms_command", metavar="ACTION", required=True)

    up = sub.add_parser("update", help="apply Eq. 4 with the angles of results files",
                        description="Update the chain's histograms (or --archive) with the "
                        "fitted angles of one or more results files, by Eq. 4 (each frame is "
                        "one trial). Locked axes are left alone.", epilog=EXAMPLES,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    up.add_argument("chain", type=Path, help="chain XML the results were fitted with")
    up.add_argument("results", type=Path, nargs="+", help="results CSV file(s)")
    up.add_argument("--archive", type=Path, help="start from this archive instead")
    up.add_argument("--all-frames", action="store_true",
                    help="also learn from frames whose fit failed (default: ok frames only)")
    up.add_argument("--as-chain", action="store_true",
                    help="write a chain file with the histograms inside, not an archive")
    up.add_argument("-o", "--output", type=Path, required=True, help="file to write")
    up.add_argument("--force", action="store_true", help=FORCE_HELP)
    up.set_defaults(func=run_update)

    mg = sub.add_parser("merge", help="combine archives weighted by their trial counts",
                        description="Merge histogram archives axis by axis: "
                        "H = sum(N_i H_i) / sum(N_i). An axis found in only some archives is "
                        "merged from those; archives of different chains are refused.")
    mg.add_argument("archives", type=Path, nargs="+", help="archive or chain XML files")
    mg.add_argument("-o", "--output", type=Path, required=True, help="archive to write")
    mg.add_argument("--force", action="store_true", help=FORCE_HELP)
    mg.set_defaults(func=run_merge)

    sh = sub.add_parser("show", help="print (and plot) the histograms of a file",
                        description="Per free axis: trial count N, mean, s(H) and the "
                        "support. Locked axes (a chain's locked axes; in an archive, "
                        "single-bin histograms never learned, N = 1) are only listed by name, "
                        "unless named with --axis.")
    sh.add_argument("file", type=Path, help="chain or archive XML")
    sh.add_argument("--axis", action="append", metavar="JOINT.AXIS",
                    help="only this axis (repeatable)")
    sh.add_argument("--plot", type=Path, metavar="PNG", help="write bar plots to this PNG")
    sh.add_argument("--force", action="store_true", help=FORCE_HELP)
    sh.set_defaults(func=run_show)


FORCE_HELP = "replace an existing output file of another kind (never one of the inputs)"


def guard_output(output: Path, inputs, kind: str, force: bool, field: str) -> None:
    """Refuse ``output`` when it is one of ``inputs``, or (unless ``force``) an existing file
    of another kind (:func:`videotrack.project.outputs.guard_outputs`)."""
    from videotrack.project.outputs import guard_outputs

    guard_outputs({output: kind}, inputs, force=force, field=field)


def _load_any(path: Path):
    """An archive from an archive file or from a chain file's histograms."""
    return _load_with_locked(path)[0]


def _load_with_locked(path: Path):
    """``(archive, locked)``: the histograms of an archive or chain file, and the keys of
    locked axes (a chain's locked axes; in an archive, single-bin histograms with N = 1, which
    is what a locked axis carries and learning never leaves)."""
    import numpy as np

    from kinematics.errors import KinematicsError
    from kinematics.model.chain_xml import load_body
    from kinematics.model.histogram_xml import archive_from_body, load_archive

    try:
        archive = load_archive(path)
    except KinematicsError as err:
        if "root element is <body>" not in err.message:
            raise
    else:
        locked = {k for k, h in archive.items()
                  if h.n_trials == 1 and np.count_nonzero(h.values) == 1}
        return archive, locked
    body = load_body(path)
    locked = {(r.chain, r.joint, r.axis.name) for r in body.axis_refs() if r.axis.locked}
    return archive_from_body(body), locked


def _angles_for(body, results_paths, all_frames: bool):
    import numpy as np

    from videotrack.errors import VideoTrackError
    from videotrack.results.files import read_results

    rows = []
    for path in results_paths:
        res = read_results(path)
        missing = [lb for lb in body.axis_labels if lb not in res.axis_labels]
        if missing:
            raise VideoTrackError(f"no column for axis {missing[0]} of the chain",
                                  file=path, line=1)
        cols = [res.axis_labels.index(lb) for lb in body.axis_labels]
        keep = np.ones(len(res), bool) if all_frames else res.ok_mask(ambiguous=False)
        rows.append(res.angles_deg[keep][:, cols])
    return np.concatenate(rows) if rows else np.empty((0, body.n_axes))


def run_update(args) -> int:
    from kinematics.model.chain_xml import load_body, save_body
    from kinematics.model.histogram_xml import (
        apply_archive,
        archive_from_body,
        load_archive,
        save_archive,
        update_archive,
    )

    inputs = {args.chain: "the chain", **{p: "a results file" for p in args.results}}
    if args.archive:
        inputs[args.archive] = "the archive"
    guard_output(args.output, inputs, "xml", args.force, "-o")
    body = load_body(args.chain)
    archive = load_archive(args.archive) if args.archive else archive_from_body(body)
    angles = _angles_for(body, args.results, args.all_frames)
    learned = update_archive(archive, body, angles)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    if args.as_chain:
        save_body(args.output, apply_archive(body, learned))
    else:
        save_archive(args.output, learned)
    kind = "chain" if args.as_chain else "archive"
    print(f"learned from {angles.shape[0]} frames of {len(args.results)} file(s); "
          f"wrote {kind} {args.output}")
    return 0


def run_merge(args) -> int:
    from kinematics.model.histogram_xml import merge_archives, save_archive

    guard_output(args.output, {p: "an input archive" for p in args.archives}, "xml",
                 args.force, "-o")
    merged = merge_archives([_load_any(p) for p in args.archives])
    args.output.parent.mkdir(parents=True, exist_ok=True)
    save_archive(args.output, merged)
    print(f"merged {len(args.archives)} archives ({len(merged)} axes); wrote {args.output}")
    return 0


def run_show(args) -> int:
    from videotrack.errors import VideoTrackError

    if args.plot:
        guard_output(args.plot, {args.file: "the histogram file"}, "png", args.force,
                     "--plot")
    archive, locked = _load_with_locked(args.file)
    items = [(f"{joint}.{axis}", h) for (_, joint, axis), h in archive.items()]
    locked_names = [f"{key[1]}.{key[2]}" for key in archive if key in locked]
    if args.axis:
        unknown = [a for a in args.axis if a not in dict(items)]
        if unknown:
            raise VideoTrackError(f"no axis {unknown[0]} (have {', '.join(n for n, _ in items)})",
                                  field="--axis")
        items = [(n, h) for n, h in items if n in args.axis]
        locked_names = []
    else:
        items = [(n, h) for n, h in items if n not in locked_names]
    print(f"{'axis':<20} {'N':>7} {'mean':>8} {'s(H)':>7}  support")
    for name, h in items:
        lo, hi = h.support_deg()
        mean = lo + (h.mean_deg() - lo) % 360.0  # within the support, e.g. 182 not -178
        print(f"{name:<20} {h.n_trials:>7} {mean:>8.1f} {h.std_deg():>7.2f}  "
              f"[{lo:g}, {hi:g}]")
    if locked_names:
        print(f"locked (not shown): {', '.join(locked_names)}")
    if args.plot:
        if not items:
            raise VideoTrackError("no histogram to plot (every axis is locked)",
                                  field="--plot")
        from videotrack.results.plots import plot_histograms

        print(f"wrote {plot_histograms(items, args.plot)}")
    return 0
