"""Artificial marker videos with known ground truth (paper Sect. 3.2).

A chain is moved through an angle trajectory, its markers are projected through one or more
cameras and drawn as anti-aliased discs (:func:`videotrack.synth.render.render_markers`), optionally
with noise, static and flickering ghost markers, occlusions and interlaced fields. Every
image drawn is recorded in a ground-truth table, so detection and fitting can be scored.
Given 3D marker trajectories (e.g. real motion capture, :func:`read_points`) are rendered
the same way without a chain (:func:`simulate_points`, :func:`write_points_project`).

:mod:`videotrack.synth.scene` poses and projects the markers (pure: arrays in, arrays out),
:mod:`videotrack.synth.video` draws the frames and writes lossless video atomically; the
functions here write a whole synthetic project (videos, ground truth, cameras, chain and a
config), which the ``videotrack synth`` command asks for.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinematics.model import Body
from videotrack.detect.marker_colours import hsv_range
from videotrack.errors import VideoTrackError
from videotrack.synth.scene import (
    LAYOUTS,  # noqa: F401  (public: the layouts of SynthOptions)
    SynthOptions,
    SynthScene,
    camera_sizes,
    points_truth_columns,
    read_points,  # noqa: F401  (public: the trajectories write_points_project takes)
    simulate,
    simulate_points,
    truth_columns,
    truth_table,
)
from videotrack.synth.video import CODECS, VideoSink, iter_frames, view_rois


@dataclass(frozen=True)
class SynthProject:
    """Paths written by :func:`write_synthetic_project` (:func:`write_points_project`:
    no chain)."""

    videos: tuple[Path, ...]
    truth: Path
    cameras: Path
    chain: Path | None
    config: Path
    n_images: int


def project_config_text(video_names: Sequence[str], cameras: Mapping, options: SynthOptions,
                        chain_name: str | None, cameras_name: str, detections_name: str) -> str:
    """A project config for the synthetic video that ``detect``, ``fit`` and ``run`` take as
    it is (TOML text); without a chain (``chain_name`` None) ``fit`` needs ``[chain] path``
    added."""
    paths = ", ".join(f'"{v}"' for v in video_names)
    lines = [
        "# Project written by 'videotrack synth': the synthetic video, its views and a",
        "# filter chain that finds the rendered markers.",
        "",
        "[video]",
        f"path = [{paths}]" if len(video_names) > 1 else f"path = {paths}",
        f'deinterlace = "{"fields" if options.interlaced else "none"}"',
        f'field_order = "{"top" if options.top_field_first else "bottom"}"',
        "",
        detection_config_text(cameras, options, len(video_names)),
        "[output]", f'detections = "{detections_name}"', "",
        *(["[chain]", f'path = "{chain_name}"', ""] if chain_name is not None else
          ["# [chain] path = \"...\": a chain XML to fit these markers with", ""]),
        "[cameras]", f'path = "{cameras_name}"', "",
        "# [anneal] keys override the best measured settings (profile = \"paper\": the",
        "# paper's Table 1 and Eq. 5); ground truth is in truth.csv",
        "",
    ]
    return "\n".join(lines)


def detection_config_text(cameras: Mapping, options: SynthOptions, n_videos: int = 1) -> str:
    """The ``[[views]]``, ``[[filters.steps]]`` and ``[markers]`` tables that find the
    markers of a synthetic video (TOML text)."""
    rois = view_rois(camera_sizes(cameras), options.layout)
    threshold = int(options.background + options.intensity / 3)
    colours = options.colours or ((None, ()),)
    lines = []
    for k, (name, (x, y, w, h)) in enumerate(zip(cameras, rois, strict=True)):
        for colour, patterns in colours:
            lines += ["[[views]]", f'name = "{name}_{colour}"' if colour else f'name = "{name}"',
                      f"roi = [{x}, {y}, {w}, {h}]", f'camera = "{name}"']
            if n_videos > 1:
                lines.append(f"video = {k}")
            if colour:
                lower, upper = hsv_range(colour, threshold)
                lines += [f"model_markers = [{', '.join(_quoted(p) for p in patterns)}]",
                          f"hsv_lower = {lower}", f"hsv_upper = {upper}"]
            lines.append("")
    min_area = max(1, int(0.25 * np.pi * (options.marker_diameter / 2) ** 2))
    if options.colours:
        lower, upper = hsv_range(options.colours[0][0], threshold)
        lines += ["# each view keeps its own colour in place of this range", "[[filters.steps]]",
                  'type = "hsv_range"', f"lower = {lower}", f"upper = {upper}", ""]
    else:
        lines += ["[[filters.steps]]", 'type = "threshold"', f"value = {threshold}", ""]
    lines += ["[markers]", f"min_area = {min_area}", ""]
    return "\n".join(lines)


def _quoted(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def write_synthetic_project(
    out_dir: str | os.PathLike,
    body: Body,
    chain_text: str,
    cameras: Mapping,
    angles_deg: np.ndarray,
    options: SynthOptions,
    fps: float = 50.0,
    codec: str = "ffv1",
    progress=None,
) -> SynthProject:
    """Render the video(s) and write ground truth, cameras, chain and a project config.

    ``progress`` is called with the number of frames written so far (for a progress bar).
    Every file is written atomically; an interrupted call leaves no partial output.
    """
    from kinematics.fileio import atomic_write_text

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scene = simulate(body, cameras, angles_deg, options)
    project = _write_scene(out, scene, truth_columns(body, scene.view_names), cameras, options,
                           fps, codec, progress, body.units, "chain.xml")
    atomic_write_text(out / "chain.xml", chain_text)
    return project


def write_points_project(
    out_dir: str | os.PathLike,
    names: Sequence[str],
    points: np.ndarray,
    cameras: Mapping,
    options: SynthOptions,
    fps: float = 50.0,
    codec: str = "ffv1",
    progress=None,
    units: str | None = None,
) -> SynthProject:
    """Render given 3D marker trajectories (:func:`simulate_points`) and write the video(s),
    ground truth (``truth.csv``: ``NAME.x/y/z`` and each view's ``VIEW.NAME.u/v/visible``),
    cameras and a project config for ``videotrack detect`` (no chain), atomically."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scene = simulate_points(points, cameras, options, names)
    if len(names) != scene.markers.shape[1]:
        raise VideoTrackError(f"{len(names)} names for {scene.markers.shape[1]} markers",
                              field="names")
    return _write_scene(out, scene, points_truth_columns(names, scene.view_names), cameras,
                        options, fps, codec, progress, units, None)


def _write_scene(out: Path, scene: SynthScene, columns, cameras, options, fps, codec, progress,
                 units, chain_name) -> SynthProject:
    """Videos, truth.csv, cameras.toml and project.toml of a scene, each atomically."""
    from kinematics.cameras.files import save_cameras
    from kinematics.fileio import atomic_write_text
    from videotrack.results.tables import write_table

    sizes = camera_sizes(cameras)
    ext = CODECS[codec][1]
    if options.layout == "separate":
        names = [f"video_{name}{ext}" for name in cameras]
    else:
        names = [f"video{ext}"]
    if codec == "png":
        names = [n if n.endswith("_png") else f"{n}_png" for n in names]
    with contextlib.ExitStack() as stack:
        sinks = [stack.enter_context(VideoSink(out / n, fps, codec)) for n in names]
        for k, frames in enumerate(iter_frames(scene, sizes, options), start=1):
            for sink, frame in zip(sinks, frames, strict=True):
                sink.write(frame)
            if progress is not None:
                progress(k)
        videos = tuple(sink.commit() for sink in sinks)
    write_table(out / "truth.csv", columns, truth_table(scene))
    save_cameras(out / "cameras.toml", cameras, units=units)
    config = out / "project.toml"
    atomic_write_text(config, project_config_text(
        names, cameras, options, chain_name, "cameras.toml", "detections.npz"))
    return SynthProject(videos, out / "truth.csv", out / "cameras.toml",
                        None if chain_name is None else out / chain_name, config,
                        scene.angles_deg.shape[0])


def write_synthetic_batch_project(
    root: str | os.PathLike,
    names: Sequence[str],
    body: Body,
    chain_text: str,
    cameras: Mapping,
    trajectory,
    options: SynthOptions,
    fps: float = 50.0,
    codec: str = "ffv1",
    anneal: Mapping | None = None,
    progress=None,
) -> list[Path]:
    """A project folder of synthetic trials for ``videotrack batch`` (docs/batch.md).

    ``root/config.toml`` holds what the trials share (views, filters, chain, cameras and the
    optional ``anneal`` keys); each trial folder (``names``, e.g. ``session1/trial01``)
    holds its video(s) and ``truth.csv``, and a config.toml naming its videos only when
    there are several (``layout="separate"``) or image folders (``codec="png"``), which
    ``[batch] videos`` would not find. ``trajectory(k)`` gives trial k's angles.
    ``progress`` is called with the number of trials written. Returns the trial folders.
    """
    import tomli_w

    from kinematics.fileio import atomic_write_text

    root = Path(root)
    folders = []
    for k, name in enumerate(names):
        folder = root / name
        project = write_synthetic_project(folder, body, chain_text, cameras, trajectory(k),
                                          options, fps, codec)
        for shared in (project.chain, project.cameras):  # once, in the project folder
            os.replace(shared, root / shared.name)
        os.unlink(project.config)
        if len(project.videos) > 1 or codec == "png":
            paths = ", ".join(f'"{v.name}"' for v in project.videos)
            atomic_write_text(folder / "config.toml", f"[video]\npath = [{paths}]\n")
        folders.append(folder)
        if progress is not None:
            progress(k + 1)
    lines = ["# A synthetic project written by 'videotrack synth --trials': what every trial",
             "# shares. Trials: SESSION/TRIAL folders, each with its video and truth.csv.", ""]
    if options.interlaced:
        lines += ["[video]", 'deinterlace = "fields"',
                  f'field_order = "{"top" if options.top_field_first else "bottom"}"', ""]
    lines += [detection_config_text(cameras, options, len(cameras)
                                    if options.layout == "separate" else 1),
              "[chain]", 'path = "chain.xml"', "", "[cameras]", 'path = "cameras.toml"', ""]
    if anneal:
        lines.append(tomli_w.dumps({"anneal": dict(anneal)}))
    atomic_write_text(root / "config.toml", "\n".join(lines))
    return folders


def trial_names(n: int, per_session: int = 10) -> list[str]:
    """``session1/trial01``, ... with ``per_session`` trials per session."""
    return [f"session{1 + k // per_session}/trial{1 + k % per_session:02d}" for k in range(n)]
