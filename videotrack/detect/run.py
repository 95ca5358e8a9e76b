"""Marker detection over a video: frames → views × fields → filters → regions → centroids.

:func:`iter_detect` is a generator yielding the detections of one record (a frame, or a
half-frame when de-interlacing) at a time; it never prints or writes, and closing it cancels
the run. :func:`detect_video` collects a whole run into a
:class:`~videotrack.detect.detections.Detections`. :func:`settings_from_config` builds the settings
from a project file, and :func:`detect_project` runs a project file's detection (skipped when
its detections file is up to date), as ``videotrack detect``, ``run`` and ``batch`` do.
"""

from __future__ import annotations

import contextlib
import os
import threading
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from videotrack.detect.deinterlace import Deinterlace
from videotrack.detect.detections import (
    FORMAT,
    VERSION,
    Detections,
    DetectSettings,
    build_detections,
    check_fresh,
    load_detections,
    save_detections,
)
from videotrack.detect.filters import FilterChain
from videotrack.detect.markers import MarkerSettings, RegionFinder
from videotrack.detect.video import VideoSet, as_video_set, open_videos, resolve_frames
from videotrack.detect.views import Plane, View, check_views
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.project.identity import video_hash


@dataclass(frozen=True, eq=False)
class FrameDetections:
    """Detections of one record.

    Attributes
    ----------
    record : int
        Index of the record in the run (0-based; two per frame when de-interlacing).
    video_frame : int
        Frame index in the video.
    parity : int or None
        Field parity (0 even rows, 1 odd rows), None for the whole frame.
    points : tuple of ndarray, shape (n_v, 2)
        Centroids per view, in view image coordinates.
    areas : tuple of ndarray of int64, shape (n_v,)
        Region areas per view.
    """

    record: int
    video_frame: int
    parity: int | None
    points: tuple[np.ndarray, ...]
    areas: tuple[np.ndarray, ...]


def settings_from_config(config) -> DetectSettings:
    """Detection settings of a loaded project file (views, filters, markers, fields)."""
    video = config["video"]
    deinterlace = Deinterlace(video["deinterlace"], video["field_order"], video["line_doubling"])
    filters = FilterChain.from_config(config)
    views = [
        View(v["name"], tuple(v["roi"]) or None, v["flip_x"], v["flip_y"], v["camera"] or None,
             v["video"], _view_hsv(v, i, filters, config.path))
        for i, v in enumerate(config["views"])
    ]
    if not views:  # one whole-frame view per video
        n = len(video_paths(config))
        views = [View("view" if n == 1 else f"view{i}", video=i) for i in range(n)]
    return DetectSettings(tuple(views), filters, MarkerSettings.from_config(config),
                          deinterlace)


def _view_hsv(view, i: int, filters: FilterChain, file):
    """The colour range of ``[[views]]`` entry ``i`` (None: the chain's own), checked: both
    bounds or neither, and a chain with one hsv_range step for it to replace."""
    lower, upper = view["hsv_lower"], view["hsv_upper"]
    if not lower and not upper:
        return None
    if not lower or not upper:
        missing = "hsv_upper" if lower else "hsv_lower"
        raise VideoTrackError(f"a view's colour needs both hsv_lower and hsv_upper; "
                              f"{missing} is missing", file=file, field=f"views[{i}].{missing}")
    ranges = [s for s in filters.steps if s["type"] == "hsv_range"]
    if len(ranges) != 1:
        raise VideoTrackError(f"a view's colour replaces the filter chain's hsv_range step; "
                              f"the chain has {len(ranges)}: give it exactly one",
                              file=file, field=f"views[{i}].hsv_lower")
    return tuple(lower), tuple(upper)


def video_paths(config) -> list[Path]:
    """The video file(s) or folder(s) of a project file, resolved."""
    paths = config["video"]["path"]
    return [Path(p) for p in (paths if isinstance(paths, list) else [paths])]


def default_output(config) -> Path:
    """Detections path of a project file: ``[output] detections`` or
    ``<first video>.detections.npz`` beside the config file."""
    given = config["output"]["detections"]
    if given:
        return Path(given)
    return config.folder / f"{video_paths(config)[0].stem}.detections.npz"


def detect_project(
    config,
    frames: str | None = None,
    force: bool = False,
    progress: Callable[[int, int], object] | None = None,
    *,
    output: str | os.PathLike | None = None,
    log: Callable[[str], object] | None = None,
    frames_field: str = "frames",
    each: Callable[[FrameDetections], object] | None = None,
) -> tuple[Detections, Path, bool]:
    """Detect the markers of a project's video(s) and save them, unless already up to date.

    Parameters
    ----------
    config : Config
        A loaded project config.
    frames : str, optional
        Frame range ``"A:B"``; default ``[video] frames`` (all when empty).
    force : bool
        Detect again although the detections file is up to date.
    progress : callable, optional
        ``progress(done, total)`` after each video frame (frames of the range).
    output : path, optional
        Detections file; default :func:`default_output`.
    log : callable, optional
        Receives a one-line note when an existing file is out of date.
    frames_field : str
        Name given to ``frames`` in errors (the CLI passes ``--frames``).
    each : callable, optional
        Called with every record's :class:`FrameDetections` as it is detected (before the
        file is written; never when the file is up to date).

    Returns
    -------
    detections : Detections
    path : Path
        The detections file.
    was_up_to_date : bool
        True when the file was made from the same video(s) with the same settings and
        covers the frames (nothing was detected).

    Raises
    ------
    VideoTrackError
        Bad video or settings, a frame range outside the video, an ``output`` that is one
        of the inputs (the video, a config file: never overwritten), or an existing file at
        ``output`` that is no detections file (not overwritten unless ``force``).
    """
    from videotrack.project.identity import relative_message, relative_path
    from videotrack.project.outputs import guard_outputs

    field = ("--output" if output is not None else
             "output.detections" if config["output"]["detections"] else None)
    output = Path(output) if output is not None else default_output(config)
    guard_outputs({output: "detections"}, detection_inputs(config), force=force, field=field)
    with _passed_on_warnings() as caught, _project_videos(
            config, frames, frames_field) as (videos, settings, frame_range):
        if not force:
            reason, previous = _stale_reason(output, videos, settings, frame_range)
            if reason is None:
                return previous, output, True
            if log is not None and previous is not None:
                log(f"{output} is out of date ({reason}); detecting again")
        total = len(frame_range)
        done = 0

        def step(n: int) -> None:
            nonlocal done
            done += n
            progress(done, total)

        try:
            detections = detect_video(videos, settings, frame_range,
                                      progress=step if progress is not None else None,
                                      each=each)
        except VideoTrackError as err:
            raise err.located(file=config.path) from None
    # what went wrong travels with the detections: later runs report it too; paths are
    # relative to the file, whose bytes then do not depend on where the project is
    base = output.absolute().parent
    for video in detections.metadata["videos"]:
        video["path"] = relative_path(video["path"], base)
    detections.metadata["warnings"] = list(dict.fromkeys(
        relative_message(str(w.message), base) for w in caught
        if issubclass(w.category, VideoTrackWarning)))
    output.parent.mkdir(parents=True, exist_ok=True)
    save_detections(detections, output)
    return detections, output, False


def detection_inputs(config) -> dict[Path, str]:
    """The files a detection reads, by what they are: config files and video(s)."""
    inputs = {Path(p): "a config file" for p in (*config.sources, config.path)}
    for k, path in enumerate(video_paths(config)):
        inputs[path] = "the video" if not k else f"video {k}"
    return inputs


@contextlib.contextmanager
def _passed_on_warnings():
    """Record the warnings of a block into the yielded list and pass them all on when it
    ends (whether it ends well or not)."""
    caught: list = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", VideoTrackWarning)
            yield caught
    finally:
        for w in list(caught):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def detections_status(config, frames: str | None = None,
                      output: str | os.PathLike | None = None
                      ) -> tuple[str | None, Detections | None]:
    """What :func:`detect_project` would find, without detecting: ``(why the detections
    must be made, e.g. "no detections yet" or other filter settings, or None when the file
    is up to date; the detections file's contents, or None when there is none)``. Opens the
    video(s) but decodes no frame."""
    output = Path(output) if output is not None else default_output(config)
    with _project_videos(config, frames, "frames") as (videos, settings, frame_range):
        return _stale_reason(output, videos, settings, frame_range)


@contextlib.contextmanager
def _project_videos(config, frames: str | None, frames_field: str):
    """Open a project's videos: ``(videos, settings, frame range)``, errors located."""
    from_config = frames is None
    try:
        settings = settings_from_config(config)
        videos = open_videos(video_paths(config), colour=settings.filters.needs_colour,
                             fps=config["video"]["fps"] or None)
    except VideoTrackError as err:
        raise err.located(file=config.path) from None
    with videos:
        try:
            frame_range = resolve_frames(config["video"]["frames"] if from_config else frames,
                                         videos.n_frames)
        except VideoTrackError as err:
            err.field = "video.frames" if from_config else frames_field
            if from_config:
                err.located(file=config.path)
            raise err from None
        yield videos, settings, frame_range


def _stale_reason(output: Path, videos, settings, frame_range) -> tuple[str | None, object]:
    """(why the detections at ``output`` are stale or None, the loaded detections or None)."""
    if not output.exists():
        return "no detections yet", None
    try:
        previous = load_detections(output)
    except VideoTrackError as err:  # never overwrite some other file unasked
        raise VideoTrackError(f"{err.message}; not overwritten (--force does)",
                              file=output) from None
    try:
        check_fresh(previous, videos, settings, frame_range)
    except VideoTrackError as err:
        return err.message, previous
    return None, previous


def iter_detect(source, settings: DetectSettings, frames=None) -> Iterator[FrameDetections]:
    """Detect markers record by record.

    Parameters
    ----------
    source : VideoSource or VideoSet
        The video(s); colour frames are needed when the filter chain picks colours.
    settings : DetectSettings
    frames : range, (start, stop), "A:B" or None
        Video frames to process (None: all).

    Yields
    ------
    FrameDetections
        One per frame, or per half-frame in time order when de-interlacing.

    Raises
    ------
    VideoTrackError
        ROI outside the frame, unknown view in a mask step, grey video for a colour filter,
        a frame range outside the video, or the first frame of the range cannot be decoded.
    """
    videos = as_video_set(source)
    detect = FrameDetector(videos, settings)
    frame_range = resolve_frames(frames, videos.n_frames)
    record = 0
    with opencv_one_thread():
        for index, frame_set in videos.frames(frame_range.start, frame_range.stop, reuse=True):
            for parity, points, areas in detect(frame_set):
                yield FrameDetections(record, index, parity, points, areas)
                record += 1


_opencv_lock = threading.Lock()
_opencv_users = [0, 0]  # detections running, OpenCV's thread count before the first


@contextlib.contextmanager
def opencv_one_thread():
    """OpenCV's own thread pool at one thread inside the block. A video's frames are
    detected one after the other, and a frame's filters gain no wall time from OpenCV's
    threads: its idle workers spun 0.65 ms of CPU per 720x576 frame, half a core, which the
    fit running alongside needs (docs/benchmarks.md "End to end"). The setting is the
    process's: the first detection to start sets it, the last to end restores it."""
    with _opencv_lock:
        if _opencv_users[0] == 0:
            _opencv_users[1] = cv2.getNumThreads()
            cv2.setNumThreads(1)
        _opencv_users[0] += 1
    try:
        yield
    finally:
        with _opencv_lock:
            _opencv_users[0] -= 1
            if _opencv_users[0] == 0:
                cv2.setNumThreads(_opencv_users[1])


class FrameDetector:
    """Detection of one frame at a time, with the filters prepared once for every plane.

    What :func:`iter_detect` runs per frame; also for detecting single frames (e.g. the
    frame a GUI shows). Construction checks the views against the video(s) and computes
    background medians.

    Parameters
    ----------
    videos : VideoSet or VideoSource
    settings : DetectSettings
    """

    def __init__(self, videos, settings: DetectSettings) -> None:
        videos = as_video_set(videos)
        if settings.filters.needs_colour and not all(s.colour for s in videos.sources):
            raise VideoTrackError("the filter chain picks colours, but the video was opened "
                                  "in grey (open it with colour=True)", field="filters.steps")
        self.views = check_views(settings.views, [(s.width, s.height) for s in videos.sources])
        settings.filters.check_views([v.name for v in self.views])
        deint = settings.deinterlace
        self.planes = [[Plane(v, p, deint) for v in self.views] for p in deint.parities]
        sampler = _Sampler(videos)
        self.filters = [[settings.filters.compile(pl, sampler.for_video(pl.view.video))
                         for pl in row] for row in self.planes]
        self.find = RegionFinder(settings.markers)

    def __call__(self, frame_set) -> list[tuple[int | None, tuple, tuple]]:
        """Detect in one frame per video (a tuple, as :meth:`VideoSet.read` gives).

        Returns
        -------
        list of (parity, points, areas)
            One entry per field in time order (one entry without de-interlacing); points
            and areas are tuples with one array per view, points in view coordinates.
        """
        out = []
        for row, filters in zip(self.planes, self.filters, strict=True):
            points, areas = [], []
            for plane, chain in zip(row, filters, strict=True):
                mask, weights = chain.run(plane.extract(frame_set[plane.view.video]))
                regions = self.find(mask, weights)
                points.append(plane.to_view(regions.xy))
                areas.append(regions.area)
            out.append((row[0].parity, tuple(points), tuple(areas)))
        return out


class _Sampler:
    """Frames sampled evenly over a whole video (for background medians), read once."""

    def __init__(self, videos: VideoSet) -> None:
        self.videos = videos
        self.cache: dict[tuple[int, int], list[np.ndarray]] = {}

    def for_video(self, video: int) -> Callable[[int], list[np.ndarray]]:
        return lambda n: self.sample(video, n)

    def sample(self, video: int, n: int) -> list[np.ndarray]:
        if (video, n) not in self.cache:
            source = self.videos.sources[video]
            while True:
                count = self.videos.n_frames
                indices = np.unique(np.rint(np.linspace(0, count - 1, n)).astype(int))
                try:
                    self.cache[video, n] = [source.read(int(i)) for i in indices]
                    break
                except VideoTrackError:
                    if self.videos.n_frames == count:  # not a newly found break: give up
                        raise
        return self.cache[video, n]


def detect_video(source, settings: DetectSettings, frames=None,
                 progress: Callable[[int], object] | None = None,
                 each: Callable[[FrameDetections], object] | None = None) -> Detections:
    """Detect markers in every record of a frame range and collect them.

    Parameters
    ----------
    source : VideoSource or VideoSet
    settings : DetectSettings
    frames : range, (start, stop), "A:B" or None
    progress : callable, optional
        Called with 1 after each video frame (e.g. ``tqdm.update``).
    each : callable, optional
        Called with each record's :class:`FrameDetections` as it is detected (e.g. to fit
        records while later ones are still being detected).

    Returns
    -------
    Detections
        Not yet saved (``save_detections``). A view without any marker in the whole run is
        reported by a :class:`~videotrack.detect.video.VideoTrackWarning`; its records are empty.
    """
    videos = as_video_set(source)
    frame_range = resolve_frames(frames, videos.n_frames)
    # hashed before decoding: a file changed meanwhile is recognised as changed next time
    identity = [{**ident, "sha256": video_hash(s.path)}
                for ident, s in zip(videos.identity(), videos.sources, strict=True)]
    per_record, video_frames, parities = [], [], []
    last = None
    with _naming_broken_images(videos):
        for det in iter_detect(videos, settings, frame_range):
            per_record.append(list(zip(det.points, det.areas, strict=True)))
            video_frames.append(det.video_frame)
            parities.append(-1 if det.parity is None else det.parity)
            if each is not None:
                each(det)
            if progress is not None and det.video_frame != last:
                progress(1)
            last = det.video_frame
    broken = [s.broken_at for s in videos.sources if s.broken_at is not None]
    metadata = {
        "format": FORMAT,
        "version": VERSION,
        "settings": settings.to_dict(),
        "settings_hash": settings.hash(),
        "videos": identity,
        "view_names": [v.name for v in settings.views],
        "frame_rate": settings.deinterlace.frame_rate(videos.fps),
        "frames": [frame_range.start, frame_range.start if last is None else last + 1],
        "broken_at": min(broken) if broken else None,
        "broken": [_broken_entry(s) for s in videos.sources if s.broken_at is not None],
        "warnings": [],
    }
    detections = build_detections(per_record, video_frames, parities, metadata)
    counts = detections.counts()
    for v, name in enumerate(detections.view_names):
        if len(counts) and not counts[:, v].any():
            warnings.warn(
                f"view {name!r}: no markers in any of the {len(counts)} records; check its ROI "
                "and the filter chain", VideoTrackWarning, stacklevel=2)
    return detections


def _broken_image(source) -> Path | None:
    """The image of an image folder at which decoding stopped (None for a video file)."""
    if not source.is_sequence or source.broken_at is None:
        return None
    from videotrack.project.identity import image_files

    files = image_files(source.path)
    return files[source.broken_at] if source.broken_at < len(files) else None


def _broken_entry(source) -> dict:
    """What the detections file records about a video that could not be read to its end."""
    image = _broken_image(source)
    return {"video": source.path.name, "frame": int(source.broken_at),
            "announced": int(source.container_frames),
            "file": None if image is None else image.name}


def incomplete_reason(detections: Detections) -> str:
    """Why ``detections`` do not cover their video(s) to the end, or ``""``: a video that
    could not be decoded past a frame (truncated or damaged), an unreadable image."""
    meta = detections.metadata
    parts = []
    for b in meta.get("broken") or []:
        where = (f"image {b['video']}/{b['file']} (frame {b['frame']}) cannot be read"
                 if b.get("file") else
                 f"{b['video']} cannot be decoded from frame {b['frame']} on")
        parts.append(f"{where}: frames {b['frame']}..{b['announced'] - 1} of "
                     f"{b['announced']} are missing")
    if not parts and meta.get("broken_at") is not None:  # files of an earlier version
        parts.append(f"the video(s) could not be decoded from frame {meta['broken_at']} on")
    return "; ".join(parts)


@contextlib.contextmanager
def _naming_broken_images(videos: VideoSet):
    """While detecting: a break in an image folder is reported naming the image (where the
    video reader's warning names the folder and the frame number only)."""
    caught: list = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", VideoTrackWarning)
            yield
    finally:
        named = {}
        for source in videos.sources:
            image = _broken_image(source)
            if image is not None:
                named[f"{source.path}: decoding stopped at frame {source.broken_at}"] = (
                    image, source)
        for w in caught:
            text = str(w.message)
            prefix = next((p for p in named if text.startswith(p)), None)
            if prefix is not None and named[prefix][0].name in text:
                del named[prefix]  # the reader named the image itself
            elif prefix is not None:
                continue  # replaced by the warning below
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        for image, source in named.values():
            n = source.container_frames
            warnings.warn(f"{image}: cannot read this image (frame {source.broken_at} of the "
                          f"{n} images in its folder; damaged or truncated): frames "
                          f"{source.broken_at}..{n - 1} are left out", VideoTrackWarning,
                          stacklevel=4)


@dataclass(frozen=True)
class ViewSummary:
    """Markers per record of one view: min / median / max and records without any."""

    view: str
    records: int
    min: int
    median: float
    max: int
    empty: int


def summarize(detections: Detections) -> list[ViewSummary]:
    """One :class:`ViewSummary` per view."""
    counts = detections.counts()
    rows = []
    for v, name in enumerate(detections.view_names):
        c = counts[:, v] if len(counts) else np.zeros(1, np.int64)
        rows.append(ViewSummary(name, len(counts), int(c.min()), float(np.median(c)),
                                int(c.max()), int((c == 0).sum()) if len(counts) else 0))
    return rows


def format_summary(rows: list[ViewSummary]) -> str:
    """A plain-text table of :func:`summarize`."""
    from videotrack.results.tables import text_table

    head = ("view", "records", "min", "median", "max", "empty")
    body = [(r.view, str(r.records), str(r.min), f"{r.median:g}", str(r.max), str(r.empty))
            for r in rows]
    return text_table(head, body)
