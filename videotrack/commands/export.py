"""``videotrack export``: a results file's 3D points and joint angles in the formats the next
tools read (OpenSim, biomechanics tools, movement, NWB)."""

from __future__ import annotations

import argparse
from pathlib import Path

EXAMPLES = """\
examples:
  # OpenSim: markers and joints (.trc) and joint angles (.mot)
  videotrack export detections.results.csv walk.trc walk.mot
  # C3D and NWB (ndx-pose; the movement package loads it), a chain measured in pixels
  videotrack export detections.results.csv walk.c3d walk.nwb --units px

The writer is chosen by each output's suffix: .trc (3D points), .mot (joint angles), .c3d
(both), .nwb (both). Rows whose fit failed are written as missing unless --all-frames. An
output never replaces an input, nor without --force an existing file of another kind. See
docs/markerless.md, "Exporting results".
"""

#: Output suffix -> the kind :func:`videotrack.project.outputs.guard_outputs` checks it against.
KIND = {".trc": "trc", ".mot": "mot", ".c3d": "c3d", ".nwb": "h5"}


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "export", help="write results as TRC, .mot, C3D or NWB",
        description="Write the 3D markers and joints and the joint angles of a results file "
                    "(from 'videotrack fit') for OpenSim (.trc, .mot), biomechanics tools "
                    "(.c3d) or NWB / movement (.nwb).",
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("results", type=Path, help="results CSV of 'videotrack fit'")
    p.add_argument("outputs", type=Path, nargs="+",
                   help="files to write; the suffix chooses the format")
    p.add_argument("--units", default="mm",
                   help="length unit of the chain and the 3D points (default mm)")
    p.add_argument("--all-frames", action="store_true",
                   help="also write the rows whose fit failed (default: missing)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing file of another kind (never an input)")
    p.set_defaults(func=run)


def run(args) -> int:
    from videotrack.errors import VideoTrackError
    from videotrack.io.export import EXPORTS, export_results
    from videotrack.project.outputs import guard_outputs
    from videotrack.results.files import read_results, sidecar_path

    for out in args.outputs:
        if out.suffix.lower() not in EXPORTS:
            raise VideoTrackError(f"unknown export type {out.suffix or '(none)'!r} (one of "
                                  f"{', '.join(EXPORTS)})", file=out)
    guard_outputs({out: KIND[out.suffix.lower()] for out in args.outputs},
                  {args.results: "the results file",
                   sidecar_path(args.results): "the results sidecar"}, force=args.force)
    results = read_results(args.results)
    for out in args.outputs:
        export_results(results, out, units=args.units, only_ok=not args.all_frames)
        print(f"wrote {out} ({EXPORTS[out.suffix.lower()]}, {len(results)} frames)")
    return 0
