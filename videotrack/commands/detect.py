"""``videotrack detect``: marker centroids of every (half-)frame and view, saved for the fitter."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

EXAMPLES = """\
examples:
  # every frame of the video(s) named in the project file
  videotrack detect project.toml
  # try the filter settings on the first 100 frames, into a scratch file
  videotrack detect project.toml --frames 0:100 --output trial.detections.npz
  # detect again although the detections file is up to date
  videotrack detect project.toml --force
  # one trial of a project folder (see 'videotrack batch'), e.g. to tune the filters
  videotrack detect myproject --trial session1/trial01

a minimal project file (paths relative to it):
  [video]
  path = "walk01.avi"            # or a folder of images, or a list: one video per camera
  deinterlace = "fields"         # two half-frames per frame; "none" for whole frames
  field_order = "bottom"         # PAL DV; "top" when even rows come first

  [[views]]                      # one table per view: a rectangle of the frame
  name = "side"
  roi = [0, 0, 360, 576]         # x, y, width, height
  [[views]]
  name = "top"
  roi = [360, 0, 360, 576]
  flip_x = true                  # seen in a mirror

  [[filters.steps]]              # filters run in order and must end with a mask
  type = "threshold"
  value = 120

  [markers]
  min_area = 3
  max_area = 200

The detections file (default: <video>.detections.npz beside the project file) holds the
centroids in each view's image coordinates, the settings, the video's identity (with the
SHA-256 of its content) and the warnings of the detection; when it is up to date for the same
video and settings, detect says so, repeats those warnings and does nothing. It never
replaces the video or a config file, nor without --force a file of another kind. See
docs/detection.md for every filter, the coordinate convention and the file format.
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "detect",
        help="find the 2D marker centroids in every frame and view of a video",
        description=(
            "Cut each frame into its views, split it into half-frames if interlaced, run the "
            "filter chain (threshold, Otsu, erosion, colour, background subtraction, masks ...) "
            "and measure the intensity-weighted sub-pixel centroid of every marker region "
            "(paper Fig. 1). Prints markers per view per frame (min/median/max) and writes "
            "one detections file per video."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("config", type=Path,
                   help="project file (TOML), or with --trial a project folder")
    p.add_argument("--trial", metavar="NAME",
                   help="a trial of the project folder CONFIG, e.g. session1/trial01 (its "
                        "config.toml files merged as 'videotrack batch' does)")
    p.add_argument("--frames", metavar="A:B",
                   help="frames A (included) to B (excluded), 0-based; 'A:' or ':B' also work "
                        "(default: [video] frames, else all)")
    p.add_argument("--output", "-o", type=Path, metavar="PATH",
                   help="detections file (default: [output] detections, else "
                        "<video>.detections.npz beside the project file)")
    p.add_argument("--force", action="store_true",
                   help="detect again even if the detections file is up to date; replace "
                        "an existing file of another kind at --output (never an input)")
    p.set_defaults(func=run)


def run(args) -> int:
    import warnings

    from tqdm import tqdm

    from videotrack.commands._common import note
    from videotrack.detect.run import detect_project, incomplete_reason
    from videotrack.detect.video import parse_frame_range
    from videotrack.errors import VideoTrackError, VideoTrackWarning
    from videotrack.project.folders import command_config
    from videotrack.project.identity import relative_message

    config = command_config(args.config, args.trial)
    if args.frames is not None:
        try:
            parse_frame_range(args.frames)
        except ValueError as err:
            raise VideoTrackError(str(err), field="--frames") from None
    with tqdm(unit="frame", desc="detecting", file=sys.stderr, leave=False,
              disable=None) as bar, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", VideoTrackWarning)

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        detections, output, up_to_date = detect_project(
            config, args.frames, args.force, progress, output=args.output,
            log=lambda line: print(f"videotrack: {line}", file=sys.stderr),
            frames_field="--frames")
    # this run's warnings, and those the detections file keeps from when it was made
    base = output.absolute().parent
    found = [relative_message(str(w.message), base) for w in caught
             if issubclass(w.category, VideoTrackWarning)]
    for w in caught:
        if not issubclass(w.category, VideoTrackWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    for message in dict.fromkeys([*found, *detections.metadata.get("warnings", [])]):
        note(f"warning: {message}")
    if incomplete_reason(detections):
        note(f"incomplete: {incomplete_reason(detections)}")
    if up_to_date:
        print(f"{output} is up to date (--force detects again)")
        return 0
    print_detected(detections, output)
    return 0


def print_detected(detections, output) -> None:
    """What ``detect`` prints after detecting: markers per view per frame, the file written."""
    from videotrack.detect.run import format_summary, summarize

    unit = "half-frame" if detections.parities.max(initial=-1) >= 0 else "frame"
    start, stop = detections.metadata["frames"]
    print(f"markers per view per {unit} ({detections.n_records} {unit}s from frames "
          f"{start}:{stop}, {detections.frame_rate:g} per second):")
    print(format_summary(summarize(detections)))
    print(f"wrote {output} ({len(detections.points)} markers)")
