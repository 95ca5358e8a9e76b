"""The project model: everything the fitter needs from a project, loaded and checked once.

:func:`load_model` loads the chain (+ histogram archive), the cameras of the views and the
annealing parameters (:func:`anneal_params`: ``[anneal]`` with overrides) into a
:class:`ProjectModel`, whose :meth:`~ProjectModel.fitter` is the project's fitter and whose
:meth:`~ProjectModel.signature` is what a results file depends on.
:func:`check_detection_views` refuses detections made for other views.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from kinematics.fit import AnnealParams, Fitter
from kinematics.model import Body
from videotrack.detect.marker_colours import markers_matching
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.markerless.route import is_markerless
from videotrack.project.config import anneal_from_table
from videotrack.project.identity import relative_path
from videotrack.results.files import file_sha256


@dataclass(frozen=True)
class ProjectModel:
    """Everything the fitter needs from a project, loaded and checked."""

    body: Body
    cameras: dict  # view name -> camera, in the order of the views
    params: AnnealParams
    chain_path: Path
    cameras_path: Path
    histograms_path: Path | None
    #: view name -> the chain's markers it shows (``[[views]] model_markers``); views not
    #: named show all
    view_markers: dict = field(default_factory=dict)

    @property
    def view_names(self) -> list[str]:
        return list(self.cameras)

    def fitter(self, body: Body | None = None, params: AnnealParams | None = None) -> Fitter:
        """The fitter of this project (optionally of an edited ``body`` with the same
        markers, or with other ``params``)."""
        return Fitter(body or self.body, self.cameras, params or self.params,
                      view_markers=self.view_markers)

    def signature(self, base: str | os.PathLike | None = None) -> dict:
        """What a results file depends on, for its sidecar (replay and staleness): the
        chain, cameras and histograms files (paths relative to the folder ``base`` when
        given, and content hashes), the views and the camera each uses, axes, markers,
        seed and every annealing parameter."""
        def where(path: Path) -> str:
            return relative_path(path, base) if base is not None else str(path)

        sig = {
            "chain": where(self.chain_path), "chain_sha256": file_sha256(self.chain_path),
            "cameras": where(self.cameras_path),
            "cameras_sha256": file_sha256(self.cameras_path),
            "views": self.view_names,
            "view_cameras": {view: cam.name for view, cam in self.cameras.items()},
            "axes": self.body.axis_labels,
            "markers": len(self.body.marker_names), "seed": self.params.seed,
            **({"view_markers": self.view_markers} if self.view_markers else {}),
            "anneal": _jsonable(self.params.to_dict()),
        }
        if self.histograms_path is not None:
            sig["histograms"] = where(self.histograms_path)
            sig["histograms_sha256"] = file_sha256(self.histograms_path)
        return sig

    def inputs(self) -> dict[Path, str]:
        """The files the model was read from, by what they are (never overwritten)."""
        found = {self.chain_path: "the chain", self.cameras_path: "the camera file"}
        if self.histograms_path is not None:
            found[self.histograms_path] = "the histogram archive"
        return found


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


#: The marker cap (px) of the 2D keypoint route unless a project sets ``cap_px``: 10 px (the
#: defaults, for blobs matched to their nearest marker) misses half the frames of the
#: synthetic keypoint session, 30 px fits them (bench/bench_markerless.py).
KEYPOINT_CAP_PX = 30.0


def anneal_params(config, **overrides) -> AnnealParams:
    """:class:`AnnealParams` from the ``[anneal]`` section, with overrides (None: keep;
    ``profile`` replaces the section's profile)."""
    given = {k: v for k, v in overrides.items() if v is not None}
    table = dict(config["anneal"])
    if "profile" in given:
        table["profile"] = given.pop("profile")
    set_keys = config.keys_given.get("anneal", ())
    params = anneal_from_table(table, set_keys, file=config.path)
    keypoints = config["keypoints"]
    if (keypoints.get("files") and keypoints.get("route") == "2d" and "cap_px" not in set_keys
            and params.error.cap_px is not None):
        # labelled keypoints: a frame starting far from its posture sees every keypoint
        # beyond a blob-sized cap and the annealing loses its way (docs/benchmarks.md)
        params = replace(params, error=replace(params.error, cap_px=KEYPOINT_CAP_PX))
    if "n_end" in given and "n_l" not in given and "n_tau" not in given:
        # a shorter schedule keeps the paper's proportions (Sect. 3.2 sensitivity analysis)
        params = params.with_schedule(given.pop("n_end"))
    return replace(params, **given) if given else params


def load_model(config, **overrides) -> ProjectModel:
    """Chain (+ archive), cameras of the views and annealing parameters of a project."""
    from kinematics.cameras.files import load_cameras
    from kinematics.model.chain_xml import load_body
    from kinematics.model.histogram_xml import apply_archive, load_archive

    chain_path = config["chain"]["path"]
    if not chain_path:
        raise VideoTrackError("no chain file: set [chain] path", file=config.path,
                              field="chain.path")
    cameras_path = config["cameras"]["path"]
    if not cameras_path:
        raise VideoTrackError("no camera file: set [cameras] path", file=config.path,
                              field="cameras.path")
    body = load_body(chain_path)
    hist_path = config["chain"]["histograms"] or None
    if hist_path:
        body = apply_archive(body, load_archive(hist_path))
    all_cameras = load_cameras(cameras_path)
    views = config["views"]
    if not views and is_markerless(config):  # keypoint files: one per camera, in file order
        views = [{"name": name, "camera": name} for name in all_cameras]
    cameras, shown = {}, {}
    for i, view in enumerate(views):
        name = view["camera"] or view["name"]
        if name not in all_cameras:
            raise VideoTrackError(f"camera '{name}' is not in {cameras_path} (it has "
                                  f"{', '.join(all_cameras)})", file=config.path,
                                  field=f"views[{i}].camera")
        cameras[view["name"]] = all_cameras[name]
        patterns = view.get("model_markers") or []
        if patterns:
            shown[view["name"]] = markers_matching(patterns, body.marker_names, config.path,
                                                   f"views[{i}].model_markers")
    if not cameras:
        raise VideoTrackError("no views: add [[views]] tables", file=config.path, field="views")
    from kinematics.cameras.checks import identical_cameras

    used = {view["camera"] or view["name"] for view in views}
    for a, b in identical_cameras({n: c for n, c in all_cameras.items() if n in used}):
        warnings.warn(f"{cameras_path}: cameras {a} and {b} are identical (the same lens and "
                      "pose): one of them is wrong", VideoTrackWarning, stacklevel=2)
    if shown and len(shown) == len(cameras):  # every view lists its markers: any left out?
        nowhere = [m for m in body.marker_names if not any(m in s for s in shown.values())]
        if nowhere:
            warnings.warn(f"{config.path}: views.model_markers: no view shows "
                          f"{', '.join(nowhere)}; the fit never places them",
                          VideoTrackWarning, stacklevel=2)
    return ProjectModel(body, cameras, anneal_params(config, **overrides), Path(chain_path),
                        Path(cameras_path), Path(hist_path) if hist_path else None, shown)


def check_detection_views(model: ProjectModel, detections, detections_path: Path) -> None:
    """Refuse detections whose views are not the project's (detect again)."""
    if list(detections.view_names) != model.view_names:
        raise VideoTrackError(f"detections are for views {detections.view_names}, the project "
                              f"has {model.view_names}: detect again", file=detections_path)
    meta = getattr(detections, "metadata", None) or {}
    if "settings" in meta and "videos" in meta:  # each view against its camera's image size
        from videotrack.detect.views import View, check_camera_sizes

        check_camera_sizes([View.from_dict(v) for v in meta["settings"]["views"]],
                           [(v["width"], v["height"]) for v in meta["videos"]], model.cameras)
