"""The markerless route of a project: its ``[keypoints]`` files -> what the chain is fitted to.

A project whose ``[keypoints] files`` are set detects no markers: :func:`load_keypoints`
reads each camera's 2D keypoints (:func:`videotrack.io.keypoints.read_keypoints`, with the
crop and frame offsets), filters them (``[keypoints.filter]``,
:func:`videotrack.markerless.filters.apply_filters`), puts the cameras on common frames, maps
the keypoints to the chain's markers (``[keypoints.markers]``) and builds the
:class:`~kinematics.observe.observations.Observations`: the labelled 2D keypoints (route
``"2d"``), or
the 3D points triangulated from them (route ``"3d"``, :mod:`kinematics.observe.triangulation`).

The :class:`KeypointInput` it returns stands where the marker route has its detections:
records are the aligned frames, and :meth:`KeypointInput.sidecar` is what a results sidecar
records instead of the detections file (the keypoint files with their content hashes and
every ``[keypoints]`` setting), so changed files or settings make results stale.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinematics.observe.observations import Observations
from videotrack.errors import VideoTrackError

#: Frames per second of the results' time column when ``[video] fps`` is 0 (as for image
#: sequences): keypoint files have no frame rate.
DEFAULT_FPS = 25.0


def is_markerless(config) -> bool:
    """The project is fitted to keypoint files (``[keypoints] files`` is set)."""
    return bool(config["keypoints"]["files"])


def keypoint_files(config) -> list[Path]:
    return [Path(p) for p in config["keypoints"]["files"]]


def keypoint_inputs(config) -> dict[Path, str]:
    """The files the markerless route reads, by what they are (never overwritten)."""
    inputs = {Path(p): "a config file" for p in (*config.sources, config.path)}
    for k, path in enumerate(keypoint_files(config)):
        inputs[path] = f"keypoint file {k}"
    return inputs


def default_results_path(config) -> Path:
    """``[fit] results``, else ``<first keypoint file's stem>.results.csv`` in the project's
    folder."""
    given = config["fit"]["results"]
    if given:
        return Path(given)
    return config.folder / f"{keypoint_files(config)[0].stem}.results.csv"


@dataclass(frozen=True, eq=False)
class KeypointInput:
    """A project's keypoints as the fit takes them (where the marker route has detections).

    Attributes
    ----------
    observations : the labelled 2D keypoints or 3D points, one record per aligned frame
    view_names : the views (cameras) in the order of the files; none for 3D points
    video_frames : (n,) the aligned frame numbers of the keypoint files
    times : (n,) seconds
    files : the keypoint files, one per view
    settings : the ``[keypoints]`` settings that shaped the observations (less the files)
    metadata : ``{"warnings": [...]}``
    """

    observations: Observations
    view_names: tuple[str, ...]
    video_frames: np.ndarray
    times: np.ndarray
    files: tuple[Path, ...]
    settings: dict
    metadata: dict

    @property
    def n_records(self) -> int:
        return len(self.video_frames)

    @property
    def parities(self) -> np.ndarray:
        """Field parity of each record: -1 (whole frames)."""
        return np.full(self.n_records, -1, dtype=np.int64)

    def sidecar(self, base: Path | None = None) -> dict:
        """What a results sidecar records about the keypoints: the files (relative to
        ``base`` when given), their content hashes and the settings."""
        from videotrack.project.identity import relative_path
        from videotrack.results.files import file_sha256

        return {"keypoints": [str(p) if base is None else relative_path(p, base)
                              for p in self.files],
                "keypoints_sha256": [file_sha256(p) if p.is_file() else _folder_sha256(p)
                                     for p in self.files],
                "keypoints_options": self.settings}


def _folder_sha256(folder: Path) -> str:
    """Content hash of a folder of OpenPose JSON files (names and hashes of its files)."""
    import hashlib

    from videotrack.results.files import file_sha256

    h = hashlib.sha256()
    for p in sorted(folder.glob("*.json")):
        h.update(f"{p.name}\0{file_sha256(p)}\n".encode())
    return h.hexdigest()


@dataclass(frozen=True, eq=False)
class MappedKeypoints:
    """A project's 2D keypoints as read, filtered, aligned and mapped to the chain's markers
    (what both routes start from; the GUI draws them in the video views).

    Attributes
    ----------
    view_names : the views (cameras), in the order of the files
    frames : (n,) the aligned frame numbers of the keypoint files
    markers : the chain's markers that have a keypoint, in the body's order
    xy : (views, n, markers, 2) pixels; NaN where missing or scored below ``min_score``
    score : (views, n, markers); NaN where missing
    """

    view_names: tuple[str, ...]
    frames: np.ndarray
    markers: tuple[str, ...]
    xy: np.ndarray
    score: np.ndarray


def load_keypoints(config, model) -> KeypointInput:
    """The :class:`KeypointInput` of a project's ``[keypoints]`` for ``model``
    (a :class:`videotrack.workflow.model.ProjectModel`: its views and body).

    Raises
    ------
    LocatedError
        A bad keypoint file (its file, line, column), files that do not match the views,
        offsets that do not match the files, a keypoint or marker name the files or the
        chain lack.
    """
    return keypoint_input(config, model, read_mapped_keypoints(config, model))


def read_mapped_keypoints(config, model) -> MappedKeypoints:
    """The first half of :func:`load_keypoints`: each camera's file read (with its offsets),
    filtered, the cameras put on common frames, the keypoints mapped to ``model``'s markers
    and those below ``min_score`` dropped. Raises as :func:`load_keypoints`."""
    from videotrack.io.keypoints import align_cameras, marker_index, read_keypoints

    table = config["keypoints"]
    files = keypoint_files(config)
    views = model.view_names
    if len(files) != len(views):
        raise VideoTrackError(f"{len(files)} keypoint file(s) for {len(views)} camera(s) "
                              f"({', '.join(views)}): give one file per camera",
                              file=config.path, field="keypoints.files")
    crops = _per_file(table["crop_offsets"], len(files), [0.0, 0.0], config, "crop_offsets")
    shifts = _per_file(table["frame_offsets"], len(files), 0, config, "frame_offsets")
    settings = _filter_settings(config)
    individual = table["individual"]
    tracks = {}
    for view, path, crop, shift in zip(views, files, crops, shifts, strict=True):
        t = read_keypoints(path, table["format"] or None,
                           individual=int(individual) if individual.isdigit() else
                           individual or None, crop_offset=crop, frame_offset=shift,
                           model=table["model"] or None)
        tracks[view] = _filtered(t, settings)
    names, frames, xy, score = align_cameras(tracks)
    body = model.body
    index = marker_index(names, body.marker_names, table["markers"] or None,
                         source=str(config.path))
    has = np.flatnonzero(index >= 0)
    markers = [body.marker_names[m] for m in has]
    xy, score = xy[:, :, index[has]], score[:, :, index[has]]
    low = ~(score >= table["min_score"])  # NaN scores (missing) too
    xy[low], score[low] = np.nan, np.nan
    return MappedKeypoints(tuple(views), frames, tuple(markers), xy, score)


def keypoint_input(config, model, mapped: MappedKeypoints) -> KeypointInput:
    """The second half of :func:`load_keypoints`: the Observations of ``mapped`` (the 2D
    keypoints, or for route ``"3d"`` their triangulation) with frames, times and settings."""
    table = config["keypoints"]
    body = model.body
    markers = list(mapped.markers)
    xy, score = mapped.xy.copy(), mapped.score.copy()
    if table["route"] == "3d":
        obs = Observations.points_3d(_triangulate(model, xy, score, table, markers),
                                     markers, body.marker_names)
    else:
        kp = np.concatenate([xy, np.nan_to_num(score)[..., None]], axis=3)
        obs = Observations.keypoints(kp.transpose(1, 0, 2, 3), list(mapped.view_names),
                                     markers, body.marker_names)
    frames = mapped.frames
    fps = config["video"]["fps"] or DEFAULT_FPS
    options = copy.deepcopy({k: v for k, v in table.items() if k != "files"})
    return KeypointInput(obs, obs.view_names, frames, frames / fps,
                         tuple(keypoint_files(config)), options, {"warnings": []})


def fitting_model(model, data: KeypointInput):
    """The model ``data`` is fitted with: ``model``, less its cameras for 3D points (they
    were triangulated with them; the fit itself has no views)."""
    if data.observations.kind == "points3d":
        return dataclasses.replace(model, cameras={}, view_markers={})
    return model


def _per_file(values: list, n: int, none, config, key: str) -> list:
    """A per-file setting: empty (``none`` for every file), one value for all, or one per
    file."""
    if not values:
        return [none] * n
    if len(values) == 1:
        return list(values) * n
    if len(values) != n:
        raise VideoTrackError(f"{len(values)} entries for {n} keypoint files: give one per "
                              "file (or one for all)", file=config.path,
                              field=f"keypoints.{key}")
    return list(values)


def _filter_settings(config):
    from videotrack.markerless.filters import KeypointFilterSettings
    from videotrack.project.config import record_from_table

    return record_from_table(KeypointFilterSettings, config["keypoints"]["filter"],
                             file=config.path, where="keypoints.filter")


def _filtered(tracks, settings):
    from videotrack.markerless.filters import apply_filters

    return apply_filters(tracks, settings) if settings.active else tracks


def rigid_pairs(body, markers) -> tuple[list[tuple[int, int]], np.ndarray]:
    """Pairs of ``markers`` (indices into it) on the same segment of ``body``, and their
    distances: constant whatever the posture, the limb lengths the optimised triangulation
    holds (given, not estimated, since the chain knows them)."""
    where = {m.name: (id(seg), np.asarray(m.offset, float)) for _, seg, m in body.markers()}
    pairs, lengths = [], []
    for a in range(len(markers)):
        for b in range(a + 1, len(markers)):
            (sa, pa), (sb, pb) = where[markers[a]], where[markers[b]]
            if sa == sb and np.linalg.norm(pa - pb) > 0:
                pairs.append((a, b))
                lengths.append(float(np.linalg.norm(pa - pb)))
    return pairs, np.array(lengths)


def _triangulate(model, xy: np.ndarray, score: np.ndarray, table, markers) -> np.ndarray:
    """(frames, points, 4): the triangulated points with weight 1 (NaN where not placed);
    the optimised backend holds the distances of markers on one segment."""
    from kinematics.observe import triangulation

    method = getattr(triangulation, f"triangulate_{table['triangulation']}")
    extra = {}
    if table["triangulation"] == "optim":
        pairs, lengths = rigid_pairs(model.body, markers)
        if pairs:
            extra = {"limbs": pairs, "limb_lengths": lengths}
    tri = method(list(model.cameras.values()), xy, score, min_score=table["min_score"],
                 **extra)
    weight = np.where(np.isfinite(tri.xyz).all(axis=2), 1.0, np.nan)
    return np.concatenate([tri.xyz, weight[..., None]], axis=2)

