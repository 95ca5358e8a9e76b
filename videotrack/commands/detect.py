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
centroids in each view's image coordinates, the settings and the video's identity; when it is
up to date for the same video and settings, detect says so and does nothing. See
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
    p.add_argument("config", type=Path, help="project file (TOML)")
    p.add_argument("--frames", metavar="A:B",
                   help="frames A (included) to B (excluded), 0-based; 'A:' or ':B' also work "
                        "(default: [video] frames, else all)")
    p.add_argument("--output", "-o", type=Path, metavar="PATH",
                   help="detections file (default: [output] detections, else "
                        "<video>.detections.npz beside the project file)")
    p.add_argument("--force", action="store_true",
                   help="detect again even if the detections file is up to date")
    p.set_defaults(func=run)


def run(args) -> int:
    from tqdm import tqdm

    from videotrack.config import load_config
    from videotrack.detect import (
        default_output,
        detect_video,
        format_summary,
        settings_from_config,
        summarize,
        video_paths,
    )
    from videotrack.detections import check_fresh, load_detections, save_detections
    from videotrack.errors import VideoTrackError
    from videotrack.video import open_videos, parse_frame_range, resolve_frames

    config = load_config(args.config)
    frames_text, frames_field = ((args.frames, "--frames") if args.frames is not None
                                 else (config["video"]["frames"], "video.frames"))
    try:
        parse_frame_range(frames_text)
    except ValueError as err:
        raise VideoTrackError(str(err), field=frames_field) from None
    output = args.output if args.output is not None else default_output(config)

    try:
        settings = settings_from_config(config)
        videos = open_videos(video_paths(config), colour=settings.filters.needs_colour,
                             fps=config["video"]["fps"] or None)
    except VideoTrackError as err:
        raise err.located(file=config.path) from None
    with videos:
        try:
            frames = resolve_frames(frames_text, videos.n_frames)
        except VideoTrackError as err:
            err.field = frames_field
            if args.frames is None:  # the range comes from the config file
                err.located(file=config.path)
            raise err from None
        if output.exists() and not args.force:
            try:
                previous = load_detections(output)
            except VideoTrackError as err:  # never overwrite some other file unasked
                raise VideoTrackError(f"{err.message}; not overwritten (--force does)",
                                      file=output) from None
            try:
                check_fresh(previous, videos, settings, frames)
            except VideoTrackError as err:
                print(f"videotrack: {output} is out of date ({err.message}); detecting "
                      "again", file=sys.stderr)
            else:
                print(f"{output} is up to date (--force detects again)")
                return 0
        try:
            with tqdm(total=len(frames), unit="frame", desc="detecting", file=sys.stderr,
                      leave=False, disable=None) as bar:
                detections = detect_video(videos, settings, frames, progress=bar.update)
        except VideoTrackError as err:
            raise err.located(file=config.path) from None
    output.parent.mkdir(parents=True, exist_ok=True)
    save_detections(detections, output)

    unit = "half-frame" if detections.parities.max(initial=-1) >= 0 else "frame"
    start, stop = detections.metadata["frames"]
    print(f"markers per view per {unit} ({detections.n_records} {unit}s from frames "
          f"{start}:{stop}, {detections.frame_rate:g} per second):")
    print(format_summary(summarize(detections)))
    print(f"wrote {output} ({len(detections.points)} markers)")
    return 0
