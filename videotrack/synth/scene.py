"""What a synthetic video shows (paper Sect. 3.2): a chain posed through an angle trajectory,
or given 3D marker trajectories (:func:`read_points`), projected through the cameras, with
occlusions and ghost markers decided for every image (:func:`simulate`,
:func:`simulate_points`), and the ground-truth table of it all (:func:`truth_table`).

The functions here are pure (arrays in, arrays out); :mod:`videotrack.synth.video` draws the
frames and :mod:`videotrack.synth.project` writes the project.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinematics.model import Body
from kinematics.model.fk import forward_kinematics
from kinematics.model.packing import pack_body
from videotrack.detect.marker_colours import check_colours, colour_of_markers
from videotrack.errors import VideoTrackError

LAYOUTS = ("side-by-side", "stacked", "separate")


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
        colour (:data:`videotrack.detect.marker_colours.PALETTE`), ghosts in the colours in turn,
        and write one view per camera and colour (:mod:`videotrack.detect.marker_colours`); empty:
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
    from videotrack.results.tables import read_table

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
