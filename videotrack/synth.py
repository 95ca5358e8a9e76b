"""Artificial marker videos with known ground truth (paper Sect. 3.2).

A chain is moved through an angle trajectory, its markers are projected through one or more
cameras and drawn as anti-aliased discs (:func:`videotrack.render.render_markers`), optionally
with noise, static and flickering ghost markers, occlusions and interlaced fields. Every
image drawn is recorded in a ground-truth table, so detection and fitting can be scored.
Given 3D marker trajectories (e.g. real motion capture, :func:`read_points`) are rendered
the same way without a chain (:func:`simulate_points`, :func:`write_points_project`).

The functions here are pure (arrays in, arrays out) except :func:`write_video`, which writes
lossless video atomically; the ``videotrack synth`` command ties them together.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from kinematics.fk import forward_kinematics
from kinematics.model import Body
from kinematics.packing import pack_body
from videotrack.errors import VideoTrackError
from videotrack.marker_colours import bgr, check_colours, colour_of_markers, hsv_range
from videotrack.render import render_markers

LAYOUTS = ("side-by-side", "stacked", "separate")
CODECS = {"ffv1": ("FFV1", ".avi"), "mjpg": ("MJPG", ".avi"), "png": (None, "")}


@dataclass(frozen=True)
class SynthOptions:
    """How the artificial video looks. Defaults follow the paper's test video.

    marker_diameter : disc diameter in pixels (the paper: 4 px).
    intensity, background : grey levels of markers and background.
    noise_sigma : standard deviation of Gaussian pixel noise (grey levels).
    static_ghosts, flicker_ghosts : ghost markers (reflections) per view; static ones are
        always visible, flickering ones appear in each image with ``flicker_probability``.
    occlusion_fraction : share of (marker, view, image) hidden, in runs of
        ``occlusion_length`` images (a marker hidden in one view for a few frames).
    interlaced : every video frame holds two fields (even / odd lines) taken at consecutive
        postures, as PAL video; ``top_field_first`` says which field comes first in time.
    layout : views side by side or stacked in one video, or one video per camera.
    seed : seeds noise, ghosts and occlusions (the trajectory has its own seed).
    colours : ((colour, marker patterns), ...): draw a colour video, each marker in its
        colour (:data:`videotrack.marker_colours.PALETTE`), ghosts in the colours in turn,
        and write one view per camera and colour (:mod:`videotrack.marker_colours`); empty:
        grey markers.
    """

    marker_diameter: float = 4.0
    intensity: float = 230.0
    background: float = 20.0
    noise_sigma: float = 0.0
    static_ghosts: int = 0
    flicker_ghosts: int = 0
    flicker_probability: float = 0.5
    occlusion_fraction: float = 0.0
    occlusion_length: int = 3
    interlaced: bool = False
    top_field_first: bool = True
    layout: str = "side-by-side"
    seed: int = 0
    colours: tuple[tuple[str, tuple[str, ...]], ...] = ()

    def validate(self) -> None:
        checks = [
            ("marker_diameter", 0.5 <= self.marker_diameter <= 100, "between 0.5 and 100 px"),
            ("intensity", 0 < self.intensity <= 255, "in (0, 255]"),
            ("background", 0 <= self.background < 255, "in [0, 255)"),
            ("noise_sigma", 0 <= self.noise_sigma <= 100, "between 0 and 100"),
            ("static_ghosts", 0 <= self.static_ghosts <= 1000, "between 0 and 1000"),
            ("flicker_ghosts", 0 <= self.flicker_ghosts <= 1000, "between 0 and 1000"),
            ("flicker_probability", 0 <= self.flicker_probability <= 1, "in [0, 1]"),
            ("occlusion_fraction", 0 <= self.occlusion_fraction < 1, "in [0, 1)"),
            ("occlusion_length", self.occlusion_length >= 1, "at least 1"),
            ("layout", self.layout in LAYOUTS, f"one of {', '.join(LAYOUTS)}"),
        ]
        for name, ok, what in checks:
            if not ok:
                raise VideoTrackError(f"must be {what}, got {getattr(self, name)!r}",
                                      field=name)
        check_colours(self.colours)


@dataclass(frozen=True)
class SynthScene:
    """Everything drawn, per image (a field when interlaced).

    angles_deg : (n_images, n_axes) postures.
    root_positions : (n_images, n_chains, 3).
    markers, joints : (n_images, n_markers | n_joints, 3) 3D positions.
    projections : (n_images, n_views, n_markers, 2) marker images in each camera's pixels.
    visible : (n_images, n_views, n_markers) bool, False where occluded.
    ghosts : (n_images, n_views, n_ghosts, 2), NaN where a flickering ghost is off.
    view_names : camera (view) names, in order.
    marker_colour : (n_markers,) index into ``SynthOptions.colours``, or None (grey).

    A scene of given 3D points (:func:`simulate_points`) has no posture, root or joints
    (zero columns); its ``visible`` is also False where a point is absent (NaN) or behind a
    camera.
    """

    angles_deg: np.ndarray
    root_positions: np.ndarray
    markers: np.ndarray
    joints: np.ndarray
    projections: np.ndarray
    visible: np.ndarray
    ghosts: np.ndarray
    view_names: tuple[str, ...]
    marker_colour: np.ndarray | None = None


def camera_sizes(cameras: Mapping) -> list[tuple[int, int]]:
    """(width, height) of every camera; synthetic videos need them."""
    sizes = []
    for name, cam in cameras.items():
        size = getattr(cam, "image_size", None)
        if size is None:
            raise VideoTrackError("camera needs an image size to render a video",
                                  field=f"cameras.{name}.size")
        sizes.append((int(size[0]), int(size[1])))
    return sizes


def simulate(
    body: Body,
    cameras: Mapping,
    angles_deg: np.ndarray,
    options: SynthOptions,
    root_positions: np.ndarray | None = None,
) -> SynthScene:
    """Pose the chain, project it, and decide occlusions and ghosts for every image."""
    options.validate()
    angles = np.asarray(angles_deg, dtype=float)
    if angles.ndim != 2 or angles.shape[1] != body.n_axes:
        raise VideoTrackError(f"trajectory needs shape (frames, {body.n_axes}), got "
                              f"{angles.shape}", field="angles")
    if options.interlaced and angles.shape[0] % 2:
        raise VideoTrackError("an interlaced video needs an even number of postures (two "
                              "fields per frame)", field="angles")
    n = angles.shape[0]
    roots = body.root_positions() if root_positions is None else np.asarray(root_positions)
    roots = np.ascontiguousarray(np.broadcast_to(roots, (n, len(body.chains), 3)), dtype=float)
    pose = forward_kinematics(pack_body(body), angles, roots)
    names = tuple(cameras)
    proj = np.stack([cam.project(pose.markers) for cam in cameras.values()], axis=1)
    rng = np.random.default_rng(options.seed)
    visible = _occlusions(rng, proj.shape[:3], options)
    ghosts = _ghosts(rng, n, camera_sizes(cameras), options)
    return SynthScene(angles, roots, pose.markers, pose.joints, proj, visible, ghosts, names,
                      _colours(options, body.marker_names))


def _colours(options: SynthOptions, names: Sequence[str] | None) -> np.ndarray | None:
    if not options.colours:
        return None
    if names is None:
        raise VideoTrackError("coloured markers need the markers' names", field="colours")
    return colour_of_markers(options.colours, names)


def simulate_points(points: np.ndarray, cameras: Mapping, options: SynthOptions,
                    names: Sequence[str] | None = None) -> SynthScene:
    """Project given 3D marker trajectories and decide occlusions and ghosts for every image.

    ``points`` (n_images, n_markers, 3) are in the cameras' world units; a NaN point is a
    marker absent in that image: it is not drawn and not visible (as one behind a camera).
    ``names`` (the markers' names) are needed for coloured markers.
    """
    options.validate()
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 3 or pts.shape[2] != 3 or pts.shape[0] < 1 or pts.shape[1] < 1:
        raise VideoTrackError(f"points need shape (images, markers, 3), got {pts.shape}",
                              field="points")
    n = pts.shape[0]
    if options.interlaced and n % 2:
        raise VideoTrackError("an interlaced video needs an even number of images (two "
                              "fields per frame)", field="points")
    views = tuple(cameras)
    proj = np.stack([cam.project(pts) for cam in cameras.values()], axis=1)
    rng = np.random.default_rng(options.seed)
    visible = _occlusions(rng, proj.shape[:3], options) & np.isfinite(proj).all(axis=-1)
    ghosts = _ghosts(rng, n, camera_sizes(cameras), options)
    return SynthScene(np.empty((n, 0)), np.empty((n, 0, 3)), pts, np.empty((n, 0, 3)), proj,
                      visible, ghosts, views, _colours(options, names))


def read_points(path: str | os.PathLike) -> tuple[list[str], np.ndarray]:
    """Read 3D marker trajectories from a CSV or NPZ file.

    One row (CSV) or array element (NPZ: one 1-D array per column) per image, columns
    ``NAME.x``, ``NAME.y``, ``NAME.z`` per marker in world units; an empty CSV cell or NaN is
    the marker absent in that image (it is not drawn). Other columns (``frame``) are ignored.

    Returns
    -------
    names : list of str
        Marker names, in column order.
    points : ndarray, shape (n_images, n_markers, 3)
    """
    from videotrack.tables import read_table

    path = Path(path)
    if path.suffix.lower() == ".npz":
        columns, values = _read_points_npz(path)
    else:
        columns, values = read_table(path)
    coords: dict[str, dict[str, int]] = {}
    for k, col in enumerate(columns):
        name, dot, axis = col.strip().rpartition(".")
        if dot and axis in ("x", "y", "z"):
            if not name:
                raise VideoTrackError(f"column '{col}' has no marker name", file=path, line=1)
            coords.setdefault(name, {})[axis] = k
    if not coords:
        raise VideoTrackError("no point columns (NAME.x, NAME.y, NAME.z)", file=path, line=1)
    for name, axes in coords.items():
        for axis in "xyz":
            if axis not in axes:
                raise VideoTrackError(f"marker '{name}' has no column {name}.{axis}", file=path,
                                      line=1)
    if values.shape[0] == 0:
        raise VideoTrackError("no frames in file", file=path)
    idx = np.array([[axes[a] for a in "xyz"] for axes in coords.values()])
    points = values[:, idx]
    bad = np.isinf(points)
    if bad.any():
        row, m, a = (int(v[0]) for v in np.nonzero(bad))
        name = list(coords)[m]
        raise VideoTrackError("value is not finite (leave the cell empty for an absent marker)",
                              file=path, line=row + 2 if path.suffix.lower() != ".npz" else None,
                              field=f"{name}.{'xyz'[a]}")
    return list(coords), points


def _read_points_npz(path: Path) -> tuple[list[str], np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as data:
            columns = list(data.files)
            arrays = [np.asarray(data[c]) for c in columns]
    except (OSError, ValueError, EOFError) as err:
        raise VideoTrackError(f"cannot read points: {err}", file=path) from None
    if not columns:
        raise VideoTrackError("file is empty", file=path)
    for c, a in zip(columns, arrays, strict=True):
        if a.ndim != 1 or a.dtype.kind not in "biuf":
            raise VideoTrackError(f"needs a 1-D numeric array, got {a.dtype} of shape {a.shape}",
                                  file=path, field=c)
        if len(a) != len(arrays[0]):
            raise VideoTrackError(f"has {len(a)} rows, {columns[0]} has {len(arrays[0])}",
                                  file=path, field=c)
    return columns, np.column_stack(arrays).astype(float)


def _occlusions(rng, shape, options: SynthOptions) -> np.ndarray:
    """Runs of ``occlusion_length`` hidden images, starting at a rate giving the fraction."""
    visible = np.ones(shape, dtype=bool)
    if options.occlusion_fraction <= 0:
        return visible
    start_p = options.occlusion_fraction / options.occlusion_length
    starts = rng.random(shape) < start_p
    for t in np.flatnonzero(starts.any(axis=(1, 2))):
        v, m = np.nonzero(starts[t])
        visible[t:t + options.occlusion_length, v, m] = False
    return visible


def _ghosts(rng, n, sizes, options: SynthOptions) -> np.ndarray:
    """Ghost positions per image and view; flickering ghosts are NaN while off."""
    k = options.static_ghosts + options.flicker_ghosts
    out = np.full((n, len(sizes), k, 2), np.nan)
    pad = 2.0 * options.marker_diameter
    for v, (w, h) in enumerate(sizes):
        pos = rng.uniform([pad, pad], [max(w - pad, pad + 1), max(h - pad, pad + 1)], (k, 2))
        out[:, v] = pos
        on = rng.random((n, options.flicker_ghosts)) < options.flicker_probability
        out[:, v, options.static_ghosts:][~on] = np.nan
    return out


def view_rois(sizes: Sequence[tuple[int, int]], layout: str) -> list[tuple[int, int, int, int]]:
    """(x, y, w, h) of each view in the composite frame (each at the origin if separate)."""
    rois, x, y = [], 0, 0
    for w, h in sizes:
        if layout == "separate":
            rois.append((0, 0, w, h))
        elif layout == "side-by-side":
            rois.append((x, 0, w, h))
            x += w
        else:
            rois.append((0, y, w, h))
            y += h
    return rois


def render_view_images(scene: SynthScene, sizes, options: SynthOptions, image: int,
                       rng: np.random.Generator) -> list[np.ndarray]:
    """The image of each view for one posture (markers, ghosts, noise): grey, or colour
    with coloured markers."""
    out = []
    for v, (w, h) in enumerate(sizes):
        seen = scene.visible[image, v]
        pts = scene.projections[image, v][seen]
        ghosts = scene.ghosts[image, v]
        on = np.isfinite(ghosts[:, 0])
        pts = np.concatenate([pts, ghosts[on]])
        shape, gain = (h, w), options.intensity
        if scene.marker_colour is not None:  # ghosts take the colours in turn
            palette = np.array([bgr(c, options.intensity) for c, _ in options.colours])
            which = np.concatenate([scene.marker_colour[seen],
                                    np.flatnonzero(on) % len(palette)])
            shape, gain = (h, w, 3), palette[which].reshape(-1, 3)
        out.append(render_markers(shape, pts, options.marker_diameter, gain,
                                  options.background, options.noise_sigma, rng))
    return out


def iter_frames(scene: SynthScene, sizes, options: SynthOptions) -> Iterable[list[np.ndarray]]:
    """Video frames: one list per frame with one image per output video."""
    rng = np.random.default_rng([options.seed, 1])
    rois = view_rois(sizes, options.layout)
    step = 2 if options.interlaced else 1
    for t in range(0, scene.angles_deg.shape[0], step):
        views = render_view_images(scene, sizes, options, t, rng)
        if options.interlaced:
            second = render_view_images(scene, sizes, options, t + 1, rng)
            first_rows = 0 if options.top_field_first else 1
            for a, b in zip(views, second, strict=True):
                a[1 - first_rows::2] = b[1 - first_rows::2]
        if options.layout == "separate":
            yield views
            continue
        width = max(x + w for x, _, w, _ in rois)
        height = max(y + h for _, y, _, h in rois)
        frame = np.full((height, width, *views[0].shape[2:]), round(options.background),
                        np.uint8)
        for (x, y, w, h), img in zip(rois, views, strict=True):
            frame[y:y + h, x:x + w] = img
        yield [frame]


class VideoSink:
    """Writes frames losslessly (FFV1 AVI or a PNG folder) and publishes atomically.

    Frames go to a temporary file (or folder) next to the target; :meth:`commit` moves it
    into place, and leaving the ``with`` block without commit removes it.
    """

    def __init__(self, path: str | os.PathLike, fps: float, codec: str = "ffv1") -> None:
        if codec not in CODECS:
            raise VideoTrackError(f"codec must be one of {', '.join(CODECS)}", field="codec")
        self.path, self.fps, self.codec = Path(path), float(fps), codec
        self._writer = None
        self._count = 0
        parent = self.path.parent
        parent.mkdir(parents=True, exist_ok=True)
        if codec == "png":
            self._tmp = Path(tempfile.mkdtemp(dir=parent, prefix=f".{self.path.name}."))
        else:
            fd, tmp = tempfile.mkstemp(dir=parent, prefix=f".{self.path.stem}.",
                                       suffix=self.path.suffix or ".avi")
            os.close(fd)
            self._tmp = Path(tmp)

    def write(self, frame: np.ndarray) -> None:
        if self.codec == "png":
            if not cv2.imwrite(str(self._tmp / f"frame_{self._count:06d}.png"), frame):
                raise VideoTrackError("cannot write PNG frame", file=self.path)
        else:
            if self._writer is None:
                fourcc = cv2.VideoWriter_fourcc(*CODECS[self.codec][0])
                h, w = frame.shape[:2]
                self._writer = cv2.VideoWriter(str(self._tmp), fourcc, self.fps, (w, h),
                                               isColor=frame.ndim == 3)
                if not self._writer.isOpened():
                    raise VideoTrackError(f"OpenCV cannot write {self.codec} video",
                                          file=self.path)
            self._writer.write(frame)
        self._count += 1

    def commit(self) -> Path:
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self.codec == "png" and self.path.exists():
            shutil.rmtree(self.path)
        os.replace(self._tmp, self.path)
        return self.path

    def __enter__(self) -> VideoSink:
        return self

    def __exit__(self, *exc) -> None:
        if self._writer is not None:
            self._writer.release()
        if self._tmp.exists():
            with contextlib.suppress(OSError):
                if self._tmp.is_dir():
                    shutil.rmtree(self._tmp)
                else:
                    self._tmp.unlink()


def truth_columns(body: Body, view_names: Sequence[str]) -> list[str]:
    """Column names of the ground-truth table (see :func:`truth_table`)."""
    cols = ["frame", *body.axis_labels]
    cols += [f"{c.name}.root.{a}" for c in body.chains for a in "xyz"]
    return cols + _point_columns(body.marker_names, body.joint_names, view_names)


def points_truth_columns(names: Sequence[str], view_names: Sequence[str]) -> list[str]:
    """Column names of the ground-truth table of a :func:`simulate_points` scene."""
    return ["frame", *_point_columns(names, (), view_names)]


def _point_columns(markers: Sequence[str], joints: Sequence[str], view_names) -> list[str]:
    cols = [f"{p}.{a}" for p in (*markers, *joints) for a in "xyz"]
    for v in view_names:
        for m in markers:
            cols += [f"{v}.{m}.u", f"{v}.{m}.v", f"{v}.{m}.visible"]
    return cols


def truth_table(scene: SynthScene) -> np.ndarray:
    """Ground truth as a (n_images, n_columns) array, columns from :func:`truth_columns`.

    Row ``i`` is image ``i`` as detection numbers them: a video frame, or a field (half-frame)
    in time order when interlaced. Projections are in the view's full-frame pixels.
    """
    n = scene.angles_deg.shape[0]
    proj = np.concatenate([scene.projections, scene.visible[..., None]], axis=-1)
    return np.concatenate([
        np.arange(n)[:, None],
        scene.angles_deg,
        scene.root_positions.reshape(n, -1),
        scene.markers.reshape(n, -1),
        scene.joints.reshape(n, -1),
        proj.reshape(n, -1),
    ], axis=1)


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
    from kinematics.camera_io import save_cameras
    from kinematics.fileio import atomic_write_text
    from videotrack.tables import write_table

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
