"""``videotrack keypoints``: import 2D keypoints (DeepLabCut, SLEAP, OpenPose, Lightning Pose,
Anipose), filter them, summarise them and write them in one format."""

from __future__ import annotations

import argparse
from pathlib import Path

from videotrack.io.keypoints import FORMATS

EXAMPLES = """\
examples:
  # what is in a SLEAP file and a DeepLabCut file (one camera each)
  videotrack keypoints back.slp side_DLC_resnet50.h5
  # drop low scores, Viterbi filter, median filter; write one DeepLabCut CSV per camera
  videotrack keypoints cam1.h5 cam2.h5 --score-threshold 0.3 --viterbi --median 7 -o filtered/
  # all cameras, aligned on their frames, into one archive (numpy.load reads it)
  videotrack keypoints cam1.h5 cam2.h5 --names left,right -o session.keypoints.npz
  # OpenPose JSON folders of the BODY_25B model, the most confident person
  videotrack keypoints cam01_json cam02_json --model BODY_25B --individual confident
  # a camera tracked on a crop at (320, 40) starting at video frame 100
  videotrack keypoints side.csv --crop-offset 320,40 --frame-offset 100

Options given once apply to every file; --crop-offset, --frame-offset and --individual may
instead be given once per file, in the files' order. -o is a folder (one DeepLabCut .csv per
camera, named after the camera; add --h5 for .h5), a .csv/.h5 file (one camera) or a .npz
(all cameras). See docs/markerless.md.
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "keypoints", help="import, filter and summarise 2D keypoint files",
        description="Read the 2D keypoints of one file per camera (format detected: "
                    "DeepLabCut .h5/.csv, SLEAP .slp/.h5, OpenPose JSON folders, Lightning "
                    "Pose .csv, Anipose pose-2d .h5), filter them (Anipose's score threshold, "
                    "Viterbi and median filters), print per camera the frames, keypoints and "
                    "share of missing points before and after filtering, and write them.",
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("files", type=Path, nargs="+", help="keypoint file or folder per camera")
    p.add_argument("--names", metavar="A,B,...",
                   help="camera names, in the files' order (default: the file names)")
    p.add_argument("--format", choices=FORMATS, help="the files' format (default: detect)")
    p.add_argument("--individual", action="append", metavar="ID",
                   help="animal/track/person to follow: name or index (default: the first; "
                        "OpenPose: 'largest' bounding box, or 'confident')")
    p.add_argument("--model", metavar="NAME",
                   help="OpenPose keypoint model naming the points: BODY_25, BODY_25B, COCO")
    p.add_argument("--crop-offset", action="append", metavar="X,Y",
                   help="pixels added to the keypoints (tracked on a crop of the video)")
    p.add_argument("--frame-offset", action="append", type=int, metavar="N",
                   help="added to the frame numbers (tracked video started at frame N)")
    f = p.add_argument_group("filters (each off unless given)")
    f.add_argument("--score-threshold", type=float, default=0.0, metavar="S",
                   help="drop points scored below S (0..1)")
    f.add_argument("--viterbi", action="store_true",
                   help="Viterbi filter: most likely path through each keypoint's candidates")
    f.add_argument("--n-back", type=int, default=4, metavar="N",
                   help="Viterbi: candidates from this many frames (default 4)")
    f.add_argument("--sigma", type=float, default=30.0, metavar="PX",
                   help="Viterbi: spread of a step between frames in px (default 30)")
    f.add_argument("--no-candidates", action="store_true",
                   help="Viterbi: ignore other animals'/people's detections")
    f.add_argument("--median", type=int, default=0, metavar="N",
                   help="median filter window in frames (odd)")
    f.add_argument("--offset-threshold", type=float, default=25.0, metavar="PX",
                   help="median filter: drop points this far from the filtered trajectory "
                        "(|dx|+|dy|, default 25)")
    p.add_argument("-o", "--output", type=Path, metavar="PATH",
                   help="folder, .csv/.h5 (one camera) or .npz (all cameras) to write")
    p.add_argument("--h5", action="store_true", help="into a folder: DeepLabCut .h5 files")
    p.add_argument("--force", action="store_true",
                   help="replace an existing file of another kind at --output (never an input)")
    p.set_defaults(func=run)


def _per_file(values, n: int, option: str, default):
    from videotrack.errors import VideoTrackError

    if not values:
        return [default] * n
    if len(values) == 1:
        return values * n
    if len(values) != n:
        raise VideoTrackError(f"given {len(values)} times for {n} files: give it once or "
                              "once per file", field=option)
    return list(values)


def _offset(text: str):
    from videotrack.errors import VideoTrackError

    try:
        x, y = (float(v) for v in str(text).split(","))
    except ValueError:
        raise VideoTrackError(f"expected X,Y in pixels, got {text!r}",
                              field="--crop-offset") from None
    return x, y


def camera_names(files, names: str | None) -> list[str]:
    """Camera names: given, else the file names without suffixes (made unique)."""
    from videotrack.errors import VideoTrackError

    if names:
        out = [n.strip() for n in names.split(",")]
        if len(out) != len(files) or len(set(out)) != len(out) or not all(out):
            raise VideoTrackError(f"need {len(files)} distinct names, got {names!r}",
                                  field="--names")
        return out
    out = [Path(f).name.split(".")[0] or Path(f).name for f in files]
    if len(set(out)) != len(out):
        out = [f"{n}{i + 1}" for i, n in enumerate(out)]
    return out


def _outputs(args, cams) -> dict:
    """Output path per camera (or one .npz for all) and its kind."""
    from videotrack.errors import VideoTrackError

    out = args.output
    suffix = out.suffix.lower()
    if suffix == ".npz":
        return {out: "npz"}
    if suffix in (".csv", ".h5"):
        if len(cams) != 1:
            raise VideoTrackError(f"one {suffix} holds one camera, given {len(cams)} files: "
                                  "write to a folder or a .npz", field="--output")
        return {out: "csv" if suffix == ".csv" else "h5"}
    ext = ".h5" if args.h5 else ".csv"
    return {out / f"{cam}{ext}": ext[1:] for cam in cams}


def run(args) -> int:
    from videotrack.errors import VideoTrackError
    from videotrack.io import dlc
    from videotrack.io.keypoints import read_keypoints, write_npz
    from videotrack.markerless.filters import KeypointFilterSettings, apply_filters
    from videotrack.project.outputs import guard_outputs

    files = args.files
    cams = camera_names(files, args.names)
    crops = [_offset(c) if c is not None else (0.0, 0.0)
             for c in _per_file(args.crop_offset, len(files), "--crop-offset", None)]
    frame_offsets = _per_file(args.frame_offset, len(files), "--frame-offset", 0)
    individuals = _per_file(args.individual, len(files), "--individual", None)
    try:
        settings = KeypointFilterSettings(
            score_threshold=args.score_threshold, median=args.median,
            offset_threshold=args.offset_threshold, viterbi=args.viterbi,
            n_back=args.n_back, sigma=args.sigma, candidates=not args.no_candidates)
    except VideoTrackError as err:
        raise VideoTrackError(err.message, field="--" + str(err.field).replace("_", "-")) \
            from None
    if not 0 <= args.score_threshold <= 1:
        raise VideoTrackError("must be in 0..1", field="--score-threshold")
    outputs = {}
    if args.output is not None:
        outputs = _outputs(args, cams)
        guard_outputs(outputs, {f: "a keypoint file" for f in files}, force=args.force,
                      field="--output")
    raw, filtered = {}, {}
    for cam, path, crop, off, ind in zip(cams, files, crops, frame_offsets, individuals,
                                         strict=True):
        raw[cam] = read_keypoints(path, args.format, individual=ind, crop_offset=crop,
                                  frame_offset=off, model=args.model)
        filtered[cam] = apply_filters(raw[cam], settings)
    print(format_summary(raw, filtered if settings.active else None))
    if outputs:
        if len(outputs) == 1 and next(iter(outputs.values())) == "npz":
            write_npz(args.output, filtered)
        else:
            if args.output.suffix.lower() not in (".csv", ".h5"):
                args.output.mkdir(parents=True, exist_ok=True)
            for (path, _), cam in zip(outputs.items(), cams, strict=True):
                dlc.write(path, filtered[cam])
        for path in outputs:
            print(f"wrote {path}")
    return 0


def format_summary(raw, filtered=None) -> str:
    """Per camera: frames (first-last), keypoints, individual, % missing before and after
    filtering, and % of points the Viterbi filter moved to another candidate."""
    head = ["camera", "frames", "first-last", "keypoints", "individual", "missing"]
    if filtered is not None:
        head += ["filtered", "moved"]
    rows = [head]
    for cam, t in raw.items():
        span = f"{t.frames[0]}-{t.frames[-1]}" if t.n_frames else "-"
        row = [cam, str(t.n_frames), span, str(len(t.names)), t.individual or "-",
               f"{100 * t.missing.mean():.1f}%" if t.missing.size else "-"]
        if filtered is not None:
            f = filtered[cam]
            both = ~t.missing & ~f.missing
            moved = both & (f.xy != t.xy).any(axis=2)
            row += [f"{100 * f.missing.mean():.1f}%", f"{100 * moved.mean():.1f}%"] \
                if f.missing.size else ["-", "-"]
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
                     for r in rows)
