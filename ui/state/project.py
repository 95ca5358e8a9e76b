"""Opening a project: its config, video, views, chain and cameras, detections and results;
applying an edited config and closing (a part of :class:`ui.state.Session`)."""

from __future__ import annotations

import copy
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from kinematics.errors import LocatedError
from ui import adapters
from ui.state import backend
from videotrack.detect import edits as detection_edits
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.project.config import read_toml


class ProjectMixin:
    """Loading a project and its files; editing and applying its config."""

    # -- project ------------------------------------------------------------------------
    @property
    def config_path(self) -> Path | None:
        return None if self.config is None else self.config.path

    @property
    def keypoint_project(self) -> bool:
        """The project is fitted to keypoint files (``[keypoints] files``), not markers."""
        return self.config is not None and backend.is_markerless(self.config)

    @property
    def editable(self) -> bool:
        """Whether the settings come from one project file the session can edit and save (a
        trial's config is merged from the project's config.toml files, shared by trials)."""
        return self.config is not None and self.trial is None

    def open_project(self, path, trial: str | None = None) -> bool:
        """Open a project file: video, views, chain and cameras, detections and results.

        With ``trial``, ``path`` is a project folder and the trial's merged config is opened
        (its settings are edited in its ``config.toml`` files, not here). What cannot be
        loaded is reported on :attr:`error` (e.g. a missing chain file) and the rest stays
        usable. Returns False when the project itself could not be opened.
        """
        if self.busy:
            self.error.emit("wait for the running task to finish (or cancel it) first")
            return False
        path = Path(path).absolute()
        try:
            config = backend.load_project_config(path, trial)
            raw = {} if trial is not None else read_toml(path)
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        self._close_videos()
        self._clear()
        self.raw_config, self.trial = raw, trial
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", VideoTrackWarning)
            problems = self._install(config, keep_body=False)
            self._load_data()
        self.status.emit(f"opened {path.name}: {self.n_frames} frames, views "
                         f"{', '.join(self.view_names)}"
                         + (f"; {self.notice}" if self.notice else ""))
        self.projectChanged.emit()
        self.dirtyChanged.emit(False)
        self.undoChanged.emit()
        self.frameChanged.emit(self.frame)
        for msg in problems:
            self.error.emit(msg)
        self._report_warnings(caught)
        return True

    def _report_warnings(self, caught) -> None:
        """VideoTrack's warnings (a truncated video, a view without markers) go to the
        status bar: they are worth seeing but need no answer."""
        for w in caught:
            if issubclass(w.category, VideoTrackWarning):
                self.status.emit(f"warning: {w.message}")

    def _install(self, config, keep_body: bool) -> list[str]:
        """Build video, views and model (and a keypoint project's keypoints) from a
        validated config; returns the problems met."""
        self.config = config
        self._frames.clear()
        if backend.is_markerless(config):  # the views are the cameras: model first
            problems = self._install_model(config, keep_body)
            return problems + self._install_keypoints(config)
        from videotrack.detect.run import settings_from_config

        problems = []
        try:
            self.settings = settings_from_config(config)
            self._open_video(config, self.settings.views)
        except LocatedError as err:
            problems.append(str(err.located(file=config.path)))
        return problems + self._install_model(config, keep_body)

    def _open_video(self, config, views) -> None:
        """Open the project's video(s) (kept when open) and resolve ``views`` on them."""
        from videotrack.detect.run import video_paths
        from videotrack.detect.video import open_videos
        from videotrack.detect.views import check_views

        if self.videos is None:
            self.videos = open_videos(video_paths(config), colour=True,
                                      fps=config["video"]["fps"] or None)
        self.views = check_views(views, [(s.width, s.height) for s in self.videos.sources])

    def _install_keypoints(self, config) -> list[str]:
        """A keypoint project's keypoints, and its views: one per camera (or its
        ``[[views]]``), cut from ``[video] path`` when given, else drawn on a blank canvas
        sized from the calibration (or the keypoints' extent)."""
        from videotrack.detect.run import settings_from_config
        from videotrack.detect.views import View

        self.settings = self.mapped = self.keypoints = self.canvas = None
        self.notice = ""
        if self.model is None:  # no cameras: no views, nothing to fit
            self.views = ()
            return []
        problems = []
        try:
            self.mapped = backend.read_mapped_keypoints(config, self.model)
            self.keypoints = backend.keypoint_input(config, self.model, self.mapped)
        except LocatedError as err:
            problems.append(str(err))
        views = tuple(View(name, video=k) for k, name in enumerate(self.model.view_names))
        why = "no video ([video] path)"
        try:
            if config["views"]:  # the cameras' names and videos as the views give them
                views = settings_from_config(config).views
            self.views = views
            if config["video"]["path"]:
                self._open_video(config, views)
                return problems
        except LocatedError as err:
            self._close_videos()
            self.videos, self.views = None, views
            why = f"video not shown ({err.message})"
        sizes = [adapters.canvas_size(
            getattr(cam, "image_size", None),
            None if self.mapped is None else self.mapped.xy[k])
            for k, cam in enumerate(self.cameras)]
        self.canvas = [np.full((h, w), adapters.CANVAS_GREY, np.uint8) for w, h in sizes]
        self.notice = f"{why}: keypoints drawn on a blank canvas"
        return problems

    def _install_model(self, config, keep_body: bool) -> list[str]:
        """Chain, cameras and parameters; the chain with its edits is kept with
        ``keep_body`` when its axes are the same."""
        problems = []
        old_body = self.body
        try:
            self.model = backend.load_model(config)
            self.params = self.model.params
            self.body = old_body if keep_body and old_body is not None and (
                old_body.axis_labels == self.model.body.axis_labels) else self.model.body
        except LocatedError as err:
            problems.append(str(err))
            self.model = None
        return problems

    def _load_data(self) -> None:
        """Detections and results named by the project (when they exist)."""
        from videotrack.detect.detections import load_detections

        self.detections_path, self.results_path = backend.output_paths(self.config)
        if self.detections_path is not None and self.detections_path.exists():
            try:
                det = load_detections(self.detections_path)
                if self.model is not None:
                    backend.check_detection_views(self.model, det, self.detections_path)
                self.detections = det
            except LocatedError as err:
                self.error.emit(str(err))
        try:  # a keypoint project's edits are hidden marks only
            self.detection_edits = detection_edits.load_edits(
                detection_edits.edits_path(self.results_path), self.view_names)
        except LocatedError as err:
            self.error.emit(str(err))
        if self.results_path.exists() and self.body is not None:
            try:
                self.results = backend.read_project_results(self.results_path, self.body,
                                                            self.error_views)
                self.results = backend.attach_candidates(self.results, self.results_path)
                used = [r.threshold for r in self.results.values() if np.isfinite(r.threshold)]
                self.measured_threshold = used[0] if used else None
                self.measured_noise = backend.recorded_noise(self.results_path)
            except LocatedError as err:
                self.error.emit(str(err))

    def parse_raw(self, raw: dict):
        """Validate an edited project table as if it were the project file; returns the
        :class:`~videotrack.project.config.Config` or raises :class:`VideoTrackError`."""
        import tomli_w

        from videotrack.project.config import parse_config

        return parse_config(tomli_w.dumps(raw), self.config.path)

    def apply_config(self, raw: dict) -> bool:
        """Validate and apply an edited project config (views, filters, chain, annealing).

        The chain is reloaded when its file changed, kept with its edits otherwise; results
        whose axes do not fit the new chain are dropped. Marks the config unsaved.
        """
        from videotrack.detect.run import settings_from_config
        from videotrack.detect.views import check_views

        if not self.editable:
            self.error.emit("this trial's settings come from several config.toml files; "
                            "edit them there")
            return False
        try:
            config = self.parse_raw(raw)
            if self.videos is not None:  # views must fit the frames before anything changes
                check_views(settings_from_config(config).views,
                            [(v.width, v.height) for v in self.videos.sources])
        except LocatedError as err:
            self.error.emit(str(err.located(file=self.config.path)))
            return False
        chain_changed = (config["chain"] != self.config["chain"]
                         or config["cameras"] != self.config["cameras"])
        self.raw_config = copy.deepcopy(raw)
        # the threshold set in the window stays unless the edit changed the project's one
        kept = self.params
        filed = self.model.params.reanalysis_threshold if self.model is not None else None
        problems = self._install(config, keep_body=not chain_changed)
        if (kept is not None and self.model is not None
                and self.model.params.reanalysis_threshold == filed):
            self.params = replace(self.params,
                                  reanalysis_threshold=kept.reanalysis_threshold)
        if chain_changed:
            # edits of the old chain are gone with it, and so is undoing them
            self._dirty.discard("chain")
            self._undo.clear()
            self._redo.clear()
            self.undoChanged.emit()
        if self.body is not None and self.results:
            n_axes = self.body.n_axes
            if any(np.size(r.angles_deg) != n_axes for r in self.results.values()):
                self.results, self.pins = {}, {}
                problems.append("the results were made with another chain and were dropped")
            elif chain_changed:
                self.stale = set(self.results)  # kept, but of the previous chain
        self._mark("config")
        self._check_detections()
        self.projectChanged.emit()
        self.frameChanged.emit(self.frame)
        for msg in problems:
            self.error.emit(msg)
        return not problems

    def _check_detections(self) -> None:
        from videotrack.detect.detections import check_fresh

        if self.detections is None or self.settings is None:
            return
        try:
            check_fresh(self.detections, self.videos, self.settings)
        except VideoTrackError as err:
            self.status.emit(f"{err.message} (Detect markers runs them again)")

    def set_params(self, params: backend.AnnealParams) -> None:
        """Annealing parameters of the next fits (the project's ``[anneal]`` by default); a
        changed ``reanalysis_threshold`` is a bar the user set (:attr:`threshold`)."""
        if self.params is not None and (params.reanalysis_threshold
                                        != self.params.reanalysis_threshold):
            self.bar_typed = True
        self.params = params

    def _close_videos(self) -> None:
        if self.videos is not None:
            self.videos.close()

    def close(self) -> None:
        """Cancel running work and release the video; nothing new starts until a project
        is opened again (:attr:`closed`)."""
        self.cancel(wait=True)
        self.wait_released()
        self._close_videos()
        self.closed = True

