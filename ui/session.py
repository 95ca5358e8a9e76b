"""The GUI's one state object: project, video, views, cameras, chain, detections, results.

Widgets call :class:`Session` methods and redraw when its signals fire; they keep no state
of their own that the session also has. Long work (fitting, detection, a correction's
re-fit) runs in a worker thread (:mod:`ui.workers`) and its results are applied here, in
the GUI thread. Every change of results or chain is an undoable :class:`Edit`.
"""

from __future__ import annotations

import copy
import warnings
from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from PySide6.QtCore import QObject, Signal

from kinematics.errors import LocatedError
from kinematics.model import Body
from kinematics.observations import Observations
from ui import adapters, backend
from ui.workers import FitWorker, TaskWorker, error_text
from videotrack import detection_edits
from videotrack.config import read_toml
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.markerless import DEFAULT_FPS

#: Video frames kept decoded for scrubbing back and forth.
FRAME_CACHE = 48

#: A fit of some frames also fits this many frames before and after each (not kept), so that
#: the path through time chooses with the movement around them (Session._with_context). One
#: was enough where three frames alone chose a mirror posture (docs/gui.md, "A scripted
#: correction session"); two keep F6 at 5 frames' cost.
FIT_CONTEXT = 2

#: Re-fitting forward/backward stops where a frame's error exceeds JUMP_FACTOR times the
#: median error of the frames carried so far plus JUMP_PX: the carried posture no longer
#: fits there (a loose bar alone let it overwrite right frames with wrong ones).
JUMP_FACTOR = 3.0
JUMP_PX = 2.0

#: Re-fitting forward/backward takes the carried posture refined in place instead of the
#: anneal's result when the two differ by more than this (degrees, all axes): the anneal
#: went to another branch (a mirror posture with a lower E). Below it they are the same
#: posture, and the anneal's is taken (refining alone drifted over 40 frames).
BRANCH_DEG = 20.0
#: ... and only when the refined posture's E is at most this times the anneal's: a mirror
#: posture that flickering ghosts favour is a few per cent lower; a refinement stuck far
#: from the data (2-5 times the anneal's E, seen on a keypoint project) is no branch.
BRANCH_E_RATIO = 1.25

#: An alternative posture chosen with A carries to a neighbour (Session._carry_choice) only
#: when the neighbour kept a candidate nearer the chosen posture than this share of its own
#: posture's distance: clearly the same branch, not a candidate close to both.
CARRY_RATIO = 0.5


def carried_or_annealed(annealed: backend.FrameResult, carried: backend.FrameResult,
                        previous_deg) -> backend.FrameResult:
    """Of a frame re-fitted from its neighbour's posture ``previous_deg``: the anneal's
    result, unless it left the neighbour's branch (more than :data:`BRANCH_DEG` from the
    neighbour's posture refined in place, ``carried``, which is nearer the neighbour) for
    an E not much lower (:data:`BRANCH_E_RATIO`): then the refined posture, with the
    anneal's kept as its alternative candidate."""
    d = adapters.angle_distance
    if (carried.error <= BRANCH_E_RATIO * annealed.error
            and d(annealed.angles_deg, carried.angles_deg) > BRANCH_DEG
            and d(carried.angles_deg, previous_deg) < d(annealed.angles_deg, previous_deg)):
        # the anneal's posture stays the frame's alternative (A swaps to it)
        return replace(carried, candidates=(*carried.candidates[:1],
                                            *annealed.candidates[:1]))
    return annealed


@dataclass
class Edit:
    """One undoable change: results of some frames, their pinned axes, and/or the chain.

    Each entry maps to ``(before, after)``; None stands for "absent".
    """

    label: str
    results: dict[int, tuple] = field(default_factory=dict)
    pins: dict[int, tuple] = field(default_factory=dict)
    body: tuple[Body, Body] | None = None
    stale: tuple[frozenset, frozenset] | None = None  # Session.stale before and after
    detection_edits: tuple[dict, dict] | None = None  # Session.detection_edits

    def record_result(self, frame: int, before, after) -> None:
        old = self.results.get(frame, (before, None))[0]
        self.results[frame] = (old, after)

    def record_pins(self, frame: int, before, after) -> None:
        old = self.pins.get(frame, (before, None))[0]
        self.pins[frame] = (old, after)

    def __bool__(self) -> bool:
        return bool(self.results or self.pins or self.body or self.detection_edits)


def pinned_result(fitter, body: Body, dets, frame: int, angles, roots,
                  pins: Mapping[int, float], refit: bool) -> backend.FrameResult:
    """The ``corrected`` result of a frame set by hand (thread-safe: no session state).

    ``dets`` is the frame's fitting input (:func:`ui.backend.frame_input`). ``pins``
    (posture index -> degrees, clipped to the ranges) are held while the other free axes
    are fitted from ``angles`` (:meth:`kinematics.anneal.Fitter.with_pins`); without
    ``refit``, or with nothing left free, the posture is taken as it is and only E is
    computed. A frame without observations keeps the user's posture.
    """
    angles = adapters.clamp_to_range(body, angles)
    lo, hi = body.ranges_deg().T
    for k, v in pins.items():
        angles[k] = float(np.clip(v, lo[k], hi[k]))
    seed = fitter.params.seed
    result = None
    if refit and any(k not in pins for k in adapters.free_axes(body)):
        result = fitter.with_pins(pins).fit_frame(dets, frame, start_deg=angles,
                                                  root_positions=roots)
    if result is None or result.status == "no-detections":
        if backend.has_observations(dets):
            error, per_view = backend.posture_error(fitter, angles, dets, roots)
        else:
            error, per_view = np.nan, np.full(fitter.n_views, np.nan)
        result = backend.manual_result(frame, angles, roots, error, per_view, seed)
    return backend.with_status(result, backend.CORRECTED)


class Session(QObject):
    """State of one open project and every operation on it.

    Signals
    -------
    projectChanged()
        A project was opened or its configuration applied: everything may have changed.
    frameChanged(int)
        The current record (frame or half-frame) changed.
    bodyChanged()
        The chain drawn changed (committed, or previewed by the chain editor).
    postureChanged()
        The posture drawn for the current frame changed without a new result (previews).
    resultsChanged(list)
        Results of these frames changed.
    detectionsChanged()
        New detections.
    busyChanged(bool)
        A background task started or ended.
    progress(int, int, float)
        Frames done, frames in all, frames per second of the running task.
    status(str)
        What the session is doing, for the status bar.
    error(str)
        A one-line error message for a dialog.
    dirtyChanged(bool)
        Unsaved changes appeared or were saved.
    undoChanged()
        The undo or redo stack changed.
    """

    projectChanged = Signal()
    frameChanged = Signal(int)
    bodyChanged = Signal()
    postureChanged = Signal()
    resultsChanged = Signal(object)
    detectionsChanged = Signal()
    busyChanged = Signal(bool)
    progress = Signal(int, int, float)
    status = Signal(str)
    error = Signal(str)
    dirtyChanged = Signal(bool)
    undoChanged = Signal()

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self._clear()

    def _clear(self) -> None:
        self.closed = False
        self.config = None
        self.trial: str | None = None
        self.raw_config: dict = {}
        self.videos = None
        self.settings = None
        self.views: tuple = ()
        self.model: backend.ProjectModel | None = None
        self.body: Body | None = None
        self.params: backend.AnnealParams | None = None
        self.detections = None
        #: A keypoint project's input (instead of detections): the 2D keypoints as mapped to
        #: the chain's markers (drawn) and what the fit takes (:class:`KeypointInput`).
        self.mapped: backend.MappedKeypoints | None = None
        self.keypoints: backend.KeypointInput | None = None
        #: Blank view images of a keypoint project without its video, and why.
        self.canvas: list[np.ndarray] | None = None
        self.notice = ""
        self.detections_path: Path | None = None
        self.results_path: Path | None = None
        self.results: dict[int, backend.FrameResult] = {}
        #: The re-analysis threshold the last fit measured on the video (threshold_mode
        #: 'auto'), shown as the bar until the user types one (:meth:`set_bar`).
        self.measured_threshold: float | None = None
        self._measuring = False  # the running task is a fit of the whole video
        #: frame -> the result the latest A set there (itself or carried): A again on one of
        #: them cycles that stretch as one
        self._swapped: dict[int, backend.FrameResult] = {}
        self.bar_typed = False
        self.pins: dict[int, dict[int, float]] = {}
        #: The user's edits of the detections, ``{(record, view): ViewEdit}``.
        self.detection_edits: dict = {}
        # (detections, edits, chain, edited detections, what the fit takes of them)
        self._edited = (None, None, None, None, None)
        #: (detections, model, body, settings, match, why): 'auto' decided on the whole video
        self._matched = (None, None, None, None, None, "")
        self._means: tuple = (None, None, None)  # (body, mean posture, locked mask)
        #: Frames whose results (error, status) were computed with an earlier chain.
        self.stale: set[int] = set()
        self.frame = 0
        self.preview_body: Body | None = None
        self.preview_angles: np.ndarray | None = None
        self._undo: list[Edit] = []
        self._redo: list[Edit] = []
        self._dirty: set[str] = set()
        self._frames: OrderedDict[int, tuple] = OrderedDict()
        self._task = None
        self._edit: Edit | None = None
        self._released: list = getattr(self, "_released", [])  # fits let go, still running

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
        from videotrack.detect import settings_from_config

        problems = []
        try:
            self.settings = settings_from_config(config)
            self._open_video(config, self.settings.views)
        except LocatedError as err:
            problems.append(str(err.located(file=config.path)))
        return problems + self._install_model(config, keep_body)

    def _open_video(self, config, views) -> None:
        """Open the project's video(s) (kept when open) and resolve ``views`` on them."""
        from videotrack.detect import video_paths
        from videotrack.video import open_videos
        from videotrack.views import check_views

        if self.videos is None:
            self.videos = open_videos(video_paths(config), colour=True,
                                      fps=config["video"]["fps"] or None)
        self.views = check_views(views, [(s.width, s.height) for s in self.videos.sources])

    def _install_keypoints(self, config) -> list[str]:
        """A keypoint project's keypoints, and its views: one per camera (or its
        ``[[views]]``), cut from ``[video] path`` when given, else drawn on a blank canvas
        sized from the calibration (or the keypoints' extent)."""
        from videotrack.detect import settings_from_config
        from videotrack.views import View

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
        from videotrack.detections import load_detections

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
            except LocatedError as err:
                self.error.emit(str(err))

    def parse_raw(self, raw: dict):
        """Validate an edited project table as if it were the project file; returns the
        :class:`~videotrack.config.Config` or raises :class:`VideoTrackError`."""
        import tomli_w

        from videotrack.config import parse_config

        return parse_config(tomli_w.dumps(raw), self.config.path)

    def apply_config(self, raw: dict) -> bool:
        """Validate and apply an edited project config (views, filters, chain, annealing).

        The chain is reloaded when its file changed, kept with its edits otherwise; results
        whose axes do not fit the new chain are dropped. Marks the config unsaved.
        """
        from videotrack.detect import settings_from_config
        from videotrack.views import check_views

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
        from videotrack.detections import check_fresh

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

    # -- what there is ------------------------------------------------------------------
    @property
    def view_names(self) -> list[str]:
        return [v.name for v in self.views]

    @property
    def cameras(self) -> list:
        """The camera of each view, in view order (empty without a model)."""
        return [] if self.model is None else list(self.model.cameras.values())

    @property
    def error_views(self) -> list[str]:
        """The views of the fit's error columns: the views, or none when the fit is to
        triangulated 3D points (a keypoint project of route "3d")."""
        if self.keypoints is not None:
            return list(self.keypoints.view_names)
        return self.view_names

    @property
    def n_frames(self) -> int:
        """Records of the project: those of the detections (or keypoints), else the
        video's frames."""
        if self.keypoints is not None:
            return self.keypoints.n_records
        if self.detections is not None:
            return self.detections.n_records
        return 0 if self.videos is None else self.videos.n_frames

    @property
    def threshold(self) -> float:
        """The bar (pixels): frames above it are highlighted and need attention. It is the
        threshold the last fit used — with ``threshold_mode = "auto"`` the one it measured on
        the video — until the user sets one (:meth:`set_bar`)."""
        if self.params is None:
            return float("inf")
        if (self.params.threshold_mode == "auto" and not self.bar_typed
                and self.measured_threshold is not None):
            return self.measured_threshold
        return self.params.reanalysis_threshold

    def set_bar(self, value: float) -> None:
        """The user's bar: it replaces the fit's threshold in the window from now on."""
        self.set_params(replace(self.params, reanalysis_threshold=float(value)))
        self.bar_typed = True

    @property
    def display_body(self) -> Body | None:
        """The chain drawn: the chain editor's preview, else the session's chain."""
        return self.preview_body if self.preview_body is not None else self.body

    @property
    def fps(self) -> float:
        if self.keypoints is not None:
            return float(self.config["video"]["fps"] or DEFAULT_FPS)
        if self.detections is not None:
            return self.detections.frame_rate
        return 25.0 if self.videos is None else self.videos.fps

    def _records(self):
        """What numbers the records: the keypoints, the detections or None."""
        return self.keypoints if self.keypoints is not None else self.detections

    def video_frame(self, record: int) -> int:
        """Video frame of a record (records are half-frames when de-interlacing; a keypoint
        project's records are the frames its files have in common)."""
        records = self._records()
        if records is not None and 0 <= record < records.n_records:
            return int(records.video_frames[record])
        return int(record)

    def time_of(self, record: int) -> float:
        """Seconds of a record, as the results file writes them."""
        records = self._records()
        if records is not None and 0 <= record < records.n_records:
            return float(records.times[record])
        return record / self.fps if self.fps else 0.0

    # -- current frame ------------------------------------------------------------------
    def set_frame(self, frame: int) -> None:
        """Make ``frame`` (clipped to the records) the current one."""
        frame = int(np.clip(frame, 0, max(self.n_frames - 1, 0)))
        if frame != self.frame:
            self.frame = frame
            self.preview_angles = None
            self.frameChanged.emit(frame)

    def step(self, delta: int) -> None:
        self.set_frame(self.frame + delta)

    def view_images(self, record: int | None = None) -> list[np.ndarray]:
        """The image of each view of a record (ROI cut and mirrored as set), BGR or grey;
        a keypoint project without video gets its blank canvases."""
        if self.canvas is not None:
            return self.canvas
        if self.videos is None or not self.views:
            return []
        index = self.video_frame(self.frame if record is None else record)
        frames = self._frames.get(index)
        if frames is None:
            try:
                frames = self.videos.read(index)
            except VideoTrackError as err:
                self.status.emit(str(err))
                return []
            self._frames[index] = frames
            while len(self._frames) > FRAME_CACHE:
                self._frames.popitem(last=False)
        self._frames.move_to_end(index)
        return [v.cut(frames[v.video]) for v in self.views]

    def full_frames(self, record: int | None = None) -> tuple:
        """Whole video frames of a record, one per video (for drawing ROIs)."""
        self.view_images(record)
        index = self.video_frame(self.frame if record is None else record)
        return self._frames.get(index, ())

    @property
    def fit_detections(self):
        """What the fit and E use: the detections file with the user's edits, or a keypoint
        project's :class:`~kinematics.observations.Observations`; Observations with the
        marks where markers are marked hidden in a view (None: nothing to fit)."""
        return self._edited_now()[1]

    def _edited_now(self) -> tuple:
        """(the detections with the user's edits, what the fit takes of them), cached."""
        source = self.keypoints.observations if self.keypoints is not None else self.detections
        key = (source, self.detection_edits, self.body)  # marks name the chain's markers
        if any(a is not b for a, b in zip(self._edited[:3], key, strict=True)):
            edited = obs = None
            if self.keypoints is not None:
                obs = source
                marks = self._hidden_marks(obs.n_frames)
                if marks is not None and obs.kind == "keypoints":
                    obs = obs.with_hidden(marks)
            elif source is not None:
                edited = obs = detection_edits.edited_detections(source, self.detection_edits)
                marks = self._hidden_marks(source.n_records)
                if marks is not None:
                    obs = Observations.unlabelled(edited.points, edited.offsets,
                                                  self.view_names).with_hidden(marks)
            self._edited = (*key, edited, obs)
        return self._edited[3:]

    def _hidden_marks(self, n_records: int) -> np.ndarray | None:
        """(records, views, markers) of the chain's markers hidden in a view, or None."""
        if self.body is None:
            return None
        return detection_edits.hidden_marks(self.detection_edits, n_records, len(self.views),
                                            self.body.marker_names)

    def hidden_in_frame(self, record: int | None = None) -> np.ndarray:
        """(n_views, n_markers) of the drawn chain's markers hidden in each view of a record
        (the GUI's H)."""
        record = self.frame if record is None else record
        body = self.display_body
        names = () if body is None else body.marker_names
        out = np.zeros((len(self.views), len(names)), bool)
        observed = self.keypoints.observations if self.keypoints is not None else None
        if observed is not None and observed.kind == "points3d":
            return out  # fitted to 3D points: a mark in a view means nothing there
        marks = self._marks_of(self.detection_edits, record, names)
        out = out if marks is None else marks
        shown = {} if self.model is None else self._fit_model().view_markers
        if shown and len(names) and len(self.views) == len(self.model.view_names):
            # a view of one colour of markers: the others are not matched there either
            out = out | backend.unseen_markers(
                {v: [m for m in ms if m in names] for v, ms in shown.items()},
                self.model.view_names, names)
        return out

    def frame_detections(self, record: int | None = None) -> list[np.ndarray]:
        """Detected centroids of a record, one (n, 2) array per view (none in a keypoint
        project: see :meth:`frame_keypoints`)."""
        record = self.frame if record is None else record
        edited = None if self.keypoints is not None else self._edited_now()[0]
        return adapters.frame_detections(edited, record, len(self.views))

    def frame_input(self, record: int | None = None):
        """What the fitter takes for one record (:func:`ui.backend.frame_input`)."""
        record = self.frame if record is None else record
        return backend.frame_input(self.fit_detections, record, len(self.views))

    def frame_keypoints(self, record: int | None = None) -> list[np.ndarray] | None:
        """A keypoint project's 2D keypoints of a record, one (n_markers, 3) array (x, y,
        score; NaN where missing) per view in the chain's marker order; None otherwise."""
        if self.mapped is None or self.display_body is None:
            return None
        record = self.frame if record is None else record
        return adapters.frame_keypoints(self.mapped, record,
                                        self.display_body.marker_names)

    def posture(self, record: int | None = None) -> tuple[np.ndarray, np.ndarray, str]:
        """``(angles_deg, roots, source)`` drawn for a record; source is ``preview``,
        ``fit`` (any result, corrected included) or ``start`` (the histogram means)."""
        record = self.frame if record is None else record
        body = self.display_body
        result = self.results.get(record)
        roots = (np.asarray(result.root_positions) if result is not None
                 else body.root_positions())
        mean, locked = self._mean_posture(body)
        if record == self.frame and self.preview_angles is not None:
            angles, source = self.preview_angles, "preview"
        elif result is not None and np.all(np.isfinite(result.angles_deg)):
            angles, source = np.asarray(result.angles_deg, float), "fit"
        else:
            return mean.copy(), roots, "start"
        # locked axes at the drawn chain's values (the chain editor may have moved a lock)
        return np.where(locked, mean, angles), roots, source

    def _mean_posture(self, body: Body) -> tuple[np.ndarray, np.ndarray]:
        """The histogram means and locked mask of a body, kept while the body is the same
        object (bodies are immutable; the means cost milliseconds, asked on every step)."""
        if self._means[0] is not body:
            self._means = (body, body.mean_posture_deg(), body.locked_mask())
        return self._means[1], self._means[2]

    def geometry(self, record: int | None = None) -> adapters.PostureGeometry | None:
        """3D points and skeleton of the drawn posture (None without a chain)."""
        if self.display_body is None:
            return None
        angles, roots, _ = self.posture(record)
        return adapters.posture_geometry(self.display_body, angles, roots)

    def overlays(self, record: int | None = None) -> list[adapters.ViewOverlay]:
        """Projected markers and skeleton of the drawn posture, one per view."""
        geometry = self.geometry(record)
        if geometry is None or not self.cameras:
            return []
        return adapters.project_geometry(geometry, self.cameras)

    def alternative_overlays(self, record: int | None = None) -> list[adapters.ViewOverlay]:
        """Projected other posture of an ``ambiguous`` frame, the one A swaps to, one per
        view; empty where the frame is not ambiguous, has no other candidate, or a preview
        is drawn."""
        record = self.frame if record is None else record
        result = self.results.get(record)
        if (result is None or result.status != "ambiguous" or len(result.candidates) < 2
                or self.display_body is None or not self.cameras
                or (record == self.frame and self.preview_angles is not None)):
            return []
        other = result.candidates[1]
        angles = np.asarray(other.angles_deg, float)
        if not np.all(np.isfinite(angles)):
            return []
        mean, locked = self._mean_posture(self.display_body)
        angles = np.where(locked, mean, angles)  # as posture() draws it once chosen
        geometry = adapters.posture_geometry(self.display_body, angles,
                                             np.asarray(other.root_positions))
        return adapters.project_geometry(geometry, self.cameras)

    # -- previews (chain editor, sliders) -----------------------------------------------
    def set_preview_body(self, body: Body | None) -> None:
        """Draw ``body`` instead of the session's chain (None: stop previewing)."""
        self.preview_body = body
        self.bodyChanged.emit()

    def set_preview_angles(self, angles_deg) -> None:
        """Draw this posture in the current frame until the frame changes (None: stop)."""
        self.preview_angles = None if angles_deg is None else np.asarray(angles_deg, float)
        self.postureChanged.emit()

    # -- edits, undo, dirty -------------------------------------------------------------
    @property
    def dirty(self) -> bool:
        return bool(self._dirty)

    @property
    def unsaved(self) -> list[str]:
        """What has unsaved changes: ``config``, ``chain``, ``detection edits`` and/or
        ``results``."""
        return sorted(self._dirty)

    def _mark(self, *parts: str) -> None:
        was = self.dirty
        self._dirty.update(parts)
        if not was:
            self.dirtyChanged.emit(True)

    def _apply(self, edit: Edit, which: int) -> None:
        """Set the state of ``edit``: ``which`` 0 for before (undo), 1 for after (redo)."""
        if edit.stale is not None:
            self.stale = set(edit.stale[which])
        for frame, pair in edit.results.items():
            if pair[which] is None:
                self.results.pop(frame, None)
            else:
                self.results[frame] = pair[which]
        for frame, pair in edit.pins.items():
            if pair[which]:
                self.pins[frame] = dict(pair[which])
            else:
                self.pins.pop(frame, None)
        if edit.results:
            self._mark("results")
            self.resultsChanged.emit(sorted(edit.results))
        if edit.body is not None:
            self.body = edit.body[which]
            self._mark("chain")
            self.bodyChanged.emit()
        if edit.detection_edits is not None:
            self.detection_edits = edit.detection_edits[which]
            self._mark("detection edits")
            self.frameChanged.emit(self.frame)  # redraw the detections

    def _freshen(self, edit: Edit, frames) -> None:
        """These frames' results are now of the current chain (recorded in ``edit``)."""
        before = frozenset(self.stale) if edit.stale is None else edit.stale[0]
        self.stale.difference_update(frames)
        edit.stale = (before, frozenset(self.stale))

    def _push(self, edit: Edit) -> None:
        if edit:
            self._undo.append(edit)
            self._redo.clear()
            self.undoChanged.emit()

    @property
    def can_undo(self) -> bool:
        return bool(self._undo) and not self.busy

    @property
    def can_redo(self) -> bool:
        return bool(self._redo) and not self.busy

    @property
    def undo_label(self) -> str:
        return self._undo[-1].label if self._undo else ""

    @property
    def redo_label(self) -> str:
        return self._redo[-1].label if self._redo else ""

    def undo(self) -> None:
        if not self.can_undo:
            return
        edit = self._undo.pop()
        self._apply(edit, 0)
        self._redo.append(edit)
        self.status.emit(f"undid: {edit.label}")
        self.undoChanged.emit()

    def redo(self) -> None:
        if not self.can_redo:
            return
        edit = self._redo.pop()
        self._apply(edit, 1)
        self._undo.append(edit)
        self.status.emit(f"redid: {edit.label}")
        self.undoChanged.emit()

    def commit_body(self, body: Body, label: str = "edit chain",
                    geometry: bool = True) -> bool:
        """Make ``body`` the session's chain (undoable); it is validated first.

        ``geometry`` False for a change that leaves the projection alone (histograms);
        otherwise every result becomes :attr:`stale` until its frame is fitted again.
        """
        from kinematics.model import validate_body

        try:
            validate_body(body)
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        self.preview_body = None
        before = frozenset(self.stale)
        edit = Edit(label, body=(self.body, body),
                    stale=(before, before | set(self.results) if geometry else before))
        self._apply(edit, 1)
        self._push(edit)
        if geometry and self.stale:
            self.status.emit(f"chain changed: the errors of {len(self.stale)} frames are of "
                             "the previous chain until they are fitted again")
        return True

    def set_results(self, results: Iterable, label: str) -> None:
        """Store results (e.g. of a fit) as one undoable edit; their pins are released."""
        edit = Edit(label)
        for r in results:
            edit.record_result(r.frame, self.results.get(r.frame), r)
            if r.frame in self.pins and r.status != backend.CORRECTED:
                edit.record_pins(r.frame, self.pins[r.frame], None)
        self._freshen(edit, list(edit.results))
        self._apply(edit, 1)
        self._push(edit)

    # -- background tasks ---------------------------------------------------------------
    @property
    def busy(self) -> bool:
        return self._task is not None

    def _start(self, worker, what: str) -> None:
        if self.closed:  # e.g. a correction timer firing after the window closed
            worker.deleteLater()
            return
        self._task = worker
        self._measuring = False  # fit() says when its task measures the threshold
        worker.finished.connect(lambda: self._task_finished(worker))
        self.busyChanged.emit(True)
        self.undoChanged.emit()
        self.status.emit(what)
        worker.start()

    def _task_finished(self, worker) -> None:
        worker.deleteLater()
        if worker in self._released:
            self._released.remove(worker)
            return  # let go at a cancel: the session has moved on
        self._task = None
        self.busyChanged.emit(False)
        self.undoChanged.emit()

    def cancel(self, wait: bool = False) -> None:
        """Stop the running task. A fit is let go at once where threads allow it
        (:meth:`_let_go`); other tasks stop at their next check (a frame)."""
        task = self._task
        if task is None:
            return
        task.cancel()
        self.status.emit("cancelling …")
        if wait:
            task.wait()
        elif isinstance(task, FitWorker) and backend.concurrent_fits():
            self._let_go(task)

    def _let_go(self, worker: FitWorker) -> None:
        """End a cancelled fit now, keeping the results that arrived (one undo step).

        The fitter can only be stopped where it hands results over, which with candidates
        is every 32 frames along the path through time; rather than wait for that, the
        window moves on and the worker finishes the frames in hand in the background, its
        results discarded. Only where numba runs parallel kernels of two threads at once
        (:func:`ui.backend.concurrent_fits`), since a new fit may start meanwhile.
        """
        worker.released = True
        self._released.append(worker)
        self._task = None
        self._fit_done(worker)
        self.busyChanged.emit(False)
        self.undoChanged.emit()

    def wait(self, timeout_ms: int = 60000) -> bool:
        """Block until the running task ends (tests and closing); True when it ended."""
        task = self._task
        return True if task is None else task.wait(timeout_ms)

    def wait_released(self) -> None:
        """Block until fits let go at a cancel have finished (closing)."""
        for worker in list(self._released):
            worker.wait()

    def run_task(self, fn: Callable, on_done: Callable[[object], None], what: str) -> bool:
        """Run ``fn(worker)`` in a thread and ``on_done(result)`` in the GUI thread."""
        if self.busy:
            self.error.emit("another task is running; wait for it or cancel it")
            return False
        worker = TaskWorker(fn)
        worker.done.connect(lambda result: None if worker.cancelled else on_done(result))
        worker.failed.connect(self._failed)
        worker.progressed.connect(self.progress)
        self._start(worker, what)
        return True

    def _failed(self, message: str) -> None:
        self.status.emit("failed")
        self.error.emit(message)

    # -- fitting ------------------------------------------------------------------------
    def _fit_model(self):
        """The project model the fit uses: a keypoint project of route "3d" is fitted to
        its triangulated points without cameras (:func:`videotrack.markerless.fitting_model`);
        the views keep the cameras to draw."""
        if self.keypoints is None:
            return self.model
        return backend.fitting_model(self.model, self.keypoints)

    def _fitter(self, body: Body | None = None, whole_video: bool = False):
        """The fitter of the session's chain, cameras and settings. Only a fit of the whole
        video measures the threshold on it (``threshold_mode = "auto"``); any other (some
        frames, a re-fit, a correction) decides statuses by the bar the window shows: a
        threshold measured on a few frames would be noise, and it would move the bar."""
        if self.model is None or self.body is None:
            raise VideoTrackError("no chain and cameras: set them under Project ▸ Settings",
                                  file=self.config_path)
        params = self.params
        if not whole_video and params.threshold_mode == "auto":
            params = replace(params, threshold_mode="absolute",
                             reanalysis_threshold=self.threshold)
        fitter = replace(self._fit_model(), params=params).fitter(body or self.body)
        observed = self.fit_detections
        if observed is None or not fitter.match_measured:
            return fitter
        # decided on the whole video, so that a re-fit or a correction of one frame is matched
        # as the fit of every frame was ('auto' would decide on that one frame); once per
        # video, chain and settings (it triangulates a sample of frames)
        key = (observed, self.model, body or self.body, self.params)
        if any(a is not b for a, b in zip(self._matched[:4], key, strict=True)):
            self._matched = (*key, *fitter.match_why(observed))
        return replace(self._fit_model(), params=replace(params, match=self._matched[4])
                       ).fitter(body or self.body)

    def _match_note(self) -> str:
        """Where 'auto' matched the markers of this video and why (for the status line of a
        fit), or "" where the settings or the views decide."""
        if self._matched[0] is not self.fit_detections or self._matched[3] is not self.params:
            return ""
        how = "in 3D" if self._matched[4] == "3d" else "per view"
        return f"; markers matched {how}: {self._matched[5]}"

    def _fitter_or_report(self, whole_video: bool = False):
        """The fitter for the next task, or None after reporting on :attr:`error` why there
        is none (one line)."""
        try:
            return self._fitter(whole_video=whole_video)
        except LocatedError as err:
            self.error.emit(str(err))
            return None

    def _missing_input(self) -> str | None:
        """Why there is nothing to fit, or None."""
        if self.fit_detections is not None:
            return None
        if self.keypoint_project:
            return "no keypoints: the project's [keypoints] files could not be read"
        return "no detections: run Detect markers first"

    def fit(self, frames: Iterable[int] | None = None, label: str = "fit") -> bool:
        """Fit frames in the background (default: every frame not corrected by hand).

        Results replace those frames' results as they arrive; the whole run is one undo
        step. Returns False when it could not start.
        """
        if self.busy:
            self.error.emit("another task is running; wait for it or cancel it")
            return False
        missing = self._missing_input()
        if missing:
            self.error.emit(missing)
            return False
        some = frames is not None  # not Fit all: these frames get neighbours as context
        if frames is None:
            frames = [f for f in range(self.n_frames)
                      if self.results.get(f) is None or self.results[f].status
                      != backend.CORRECTED]
        frames = sorted({int(f) for f in frames if 0 <= int(f) < self.n_frames})
        if not frames:
            self.status.emit("nothing to fit")
            return False
        fitter = self._fitter_or_report(whole_video=not some)
        if fitter is None:
            return False
        wanted = set(frames)
        if some and self.params.candidates > 1:
            frames = self._with_context(frames)
        self._edit = Edit(f"{label} ({len(wanted)} frames)")
        worker = FitWorker(fitter, self.fit_detections, frames, backend.fit_chunk_size())
        # a fit let go at a cancel (_let_go) reports nothing more; context frames are not kept
        worker.resultsReady.connect(lambda b: None if worker.released else self._fit_results(
            [r for r in b if r.frame in wanted]))
        worker.progressed.connect(lambda *a: None if worker.released else self.progress.emit(*a))
        worker.failed.connect(lambda m: None if worker.released else self._failed(m))
        worker.finished.connect(lambda: None if worker.released else self._fit_done(worker))
        self._start(worker, f"fitting {len(frames)} frames{self._match_note()} …")
        self._measuring = not some  # only a fit of the whole video measures the threshold
        return True

    def _with_context(self, frames: list[int]) -> list[int]:
        """The frames to fit for a fit of some frames: with up to :data:`FIT_CONTEXT` frames
        before and after each stretch, fitted but not kept, so that the path through time
        sees the movement around it (after a marker is hidden in a view, a few frames alone
        cannot tell a posture from its mirror; with their neighbours they can)."""
        out = set(frames)
        for f in frames:
            out.update(range(max(0, f - FIT_CONTEXT), min(self.n_frames, f + FIT_CONTEXT + 1)))
        return sorted(out)

    def _fit_results(self, batch: list) -> None:
        """Store results as they arrive (part of the running task's undo step). An item is a
        result (a fit: the frame's pins are released) or ``(result, pins)`` (a correction
        that pins those axes)."""
        edit = self._edit
        for item in batch:
            r, pins = item if isinstance(item, tuple) else (item, None)
            edit.record_result(r.frame, self.results.get(r.frame), r)
            self.results[r.frame] = r
            if self._measuring and np.isfinite(r.threshold):
                self.measured_threshold = float(r.threshold)
            if pins or r.frame in self.pins:
                edit.record_pins(r.frame, self.pins.pop(r.frame, None), pins)
                if pins:
                    self.pins[r.frame] = dict(pins)
        frames = [(i[0] if isinstance(i, tuple) else i).frame for i in batch]
        self._freshen(edit, frames)
        self._mark("results")
        self.resultsChanged.emit(frames)

    def _fit_done(self, worker) -> None:
        edit, self._edit = self._edit, None
        if edit is not None:
            self._push(edit)
        verb = "cancelled after" if worker.cancelled or worker.released else "fitted"
        count = worker.count if edit is None else len(edit.results)
        summary = getattr(worker, "summary", "")
        self.status.emit(f"{verb} {count} frames" + (f"; {summary}" if summary else ""))

    def _run_frames(self, work: Callable, label: str, what: str) -> bool:
        """Run ``work(worker)``, which publishes results frame by frame (items as in
        :meth:`_fit_results`), in the background: results show as they arrive, the run is
        one undo step, a cancel keeps what arrived."""
        if self.busy:
            self.error.emit("another task is running; wait for it or cancel it")
            return False
        self._edit = Edit(label)
        worker = TaskWorker(work)
        worker.published.connect(self._fit_results)
        worker.progressed.connect(self.progress)
        worker.failed.connect(self._failed)
        worker.finished.connect(lambda: self._fit_done(worker))
        self._start(worker, what)
        return True

    def fit_bad(self) -> bool:
        """Fit again the frames whose error is above the threshold."""
        return self.fit(adapters.bad_frames(self.results, self.threshold), "re-fit bad frames")

    # -- manual correction --------------------------------------------------------------
    def correct(self, values_deg: Mapping[int, float], refit: bool = True,
                frame: int | None = None, label: str | None = None) -> bool:
        """Set axes of a frame by hand and hold them while the rest is re-fitted.

        The axes given (posture indices -> degrees) join those already pinned in this frame;
        the fitter then holds the pinned axes at the user's values
        (:meth:`kinematics.anneal.Fitter.with_pins`) while it fits the others, starting from
        the current posture.
        Without ``refit``, or when nothing is left free, the posture is taken as it is and
        only its error is computed. The result has status ``corrected``; undo restores the
        frame's previous result.
        """
        frame = self.frame if frame is None else int(frame)
        if self.body is None or self.model is None:
            self.error.emit("no chain and cameras to correct")
            return False
        angles, roots, _ = self.posture(frame)
        pins = {**self.pins.get(frame, {}), **{int(k): float(v) for k, v in values_deg.items()}}
        label = label or "set " + ", ".join(self.body.axis_labels[k] for k in values_deg)
        fitter = self._fitter_or_report()
        if fitter is None:
            return False
        dets = self.frame_input(frame)

        def finish(result) -> None:
            edit = Edit(label)
            edit.record_result(frame, self.results.get(frame), result)
            edit.record_pins(frame, self.pins.get(frame), pins)
            self._freshen(edit, [frame])
            self.preview_angles = None
            self._apply(edit, 1)
            self._push(edit)
            self.status.emit(f"frame {frame} corrected: error {result.error:.2f} px")

        def work(_worker):
            return pinned_result(fitter, self.body, dets, frame, angles, roots, pins, refit)

        if refit and any(k not in pins for k in adapters.free_axes(self.body)):
            return self.run_task(work, finish,
                                 f"re-fitting frame {frame} around the correction …")
        try:
            finish(work(None))
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        return True

    def accept(self, frames: Iterable[int] | None = None) -> int:
        """Mark the postures of fitted frames right (status ``corrected``: *Fit all* leaves
        them alone, a re-fit forward stops there); one undo step. Returns how many."""
        if self.busy:
            self.status.emit("wait for the running task to finish (or cancel it) first")
            return 0
        frames = [self.frame] if frames is None else [int(f) for f in frames]
        edit = Edit("")
        for f in frames:
            r = self.results.get(f)
            if r is not None and r.status != backend.CORRECTED and np.all(
                    np.isfinite(r.angles_deg)):
                edit.record_result(f, r, backend.with_status(r, backend.CORRECTED))
        n = len(edit.results)
        edit.label = f"accept frame {frames[0]}" if frames == [min(edit.results, default=-1)] \
            else f"accept {n} frames"
        self._apply(edit, 1)
        self._push(edit)
        self.status.emit(f"accepted {n} frame{'s' if n != 1 else ''}" if n else
                         "nothing to accept (frames not fitted, or already corrected)")
        return n

    def _held(self) -> set[int]:
        """Frames the user has set or accepted: corrected, or with pinned axes."""
        return ({f for f, r in self.results.items() if r.status == backend.CORRECTED}
                | {f for f, p in self.pins.items() if p})

    def refit_from(self, direction: int, frame: int | None = None) -> bool:
        """Carry the frame's posture to its neighbours (``direction`` +1 forward, -1
        backward): each next frame is fitted starting from the previous frame's result, in
        the background, until a frame's error exceeds the threshold or jumps (above
        :data:`JUMP_FACTOR` times the carried frames' median plus :data:`JUMP_PX`: the
        posture no longer carries, even under a loose bar; that frame is left as it was), a
        frame corrected, accepted or pinned by hand, or the end of the video. One undo step;
        a cancel keeps the frames done."""
        frame = self.frame if frame is None else int(frame)
        step = 1 if direction > 0 else -1
        angles, _, source = self.posture(frame)
        if source != "fit":
            self.error.emit(f"frame {frame} has no posture to carry: fit or correct it first")
            return False
        missing = self._missing_input()
        if missing:
            self.error.emit(missing)
            return False
        fitter = self._fitter_or_report()
        if fitter is None:
            return False
        frames = list(range(frame + step, self.n_frames if step > 0 else -1, step))
        if not frames:
            self.status.emit("no frame beyond this one")
            return False
        held, threshold = self._held(), self.threshold
        detections = self.fit_detections
        known = {f: np.asarray(r.root_positions) for f, r in self.results.items()}

        start = self.results.get(frame)
        carried = [start.error] if start is not None and np.isfinite(start.error) else []

        def jumps(r) -> bool:  # against the frames carried so far
            return bool(carried) and r.error > JUMP_FACTOR * float(np.median(carried)) + JUMP_PX

        def work(worker: TaskWorker):
            prev_angles = angles
            tracked = None
            for k, f in enumerate(frames):
                worker.check_cancel()
                if f in held:
                    worker.summary = f"stopped at frame {f} (set by hand)"
                    return
                if f not in known and tracked is None:  # roots of frames never fitted
                    tracked = fitter.track_roots(detections)
                root = known[f] if f in known else tracked[f]
                data = backend.frame_input(detections, f, fitter.n_views)
                r = fitter.fit_frame(data, f, start_deg=prev_angles, root_positions=root)
                # an anneal, even one started from the carried posture, can fall into
                # another branch with a lower E (a mirror posture): then the carried
                # posture refined in place is taken, if it fits
                kept = fitter.refine_frame(data, f, prev_angles, root_positions=root)
                if kept is not None and kept.error <= threshold and not jumps(kept):
                    r = carried_or_annealed(r, kept, prev_angles)
                if not r.error <= threshold:
                    worker.summary = (f"stopped at frame {f}: error {r.error:.2f} px above the "
                                      f"threshold, left as it was")
                    return
                if jumps(r):
                    worker.summary = (f"stopped at frame {f}: error jumps to {r.error:.2f} px "
                                      f"(carried frames {np.median(carried):.2f}), left as it "
                                      "was")
                    return
                carried.append(r.error)
                worker.publish([r])
                worker.report(k + 1, len(frames))
                prev_angles = r.angles_deg
            worker.summary = "reached the end"

        where = "forward" if step > 0 else "backward"
        return self._run_frames(work, f"re-fit {where} from frame {frame}",
                                f"re-fitting {where} from frame {frame} …")

    def interpolate(self, first: int, last: int, refit: bool = True) -> bool:
        """Set the frames between two corrected frames by linear interpolation of their
        pinned axes (of every free axis when neither end pins one) and, with ``refit``, fit
        the other axes of each frame with those held (background, one undo step). The
        frames get status ``corrected`` with the interpolated axes pinned."""
        first, last = sorted((int(first), int(last)))
        ends = [self.results.get(first), self.results.get(last)]
        if any(r is None or r.status != backend.CORRECTED for r in ends):
            self.error.emit(f"interpolation needs corrected frames at both ends; frames "
                            f"{first} and {last} are not both corrected")
            return False
        if last - first < 2:
            self.status.emit("no frame between the two ends")
            return False
        axes = sorted(set(self.pins.get(first, {})) | set(self.pins.get(last, {}))
                      ) or adapters.free_axes(self.body)
        fitter = self._fitter_or_report()
        if fitter is None:
            return False
        (a0, r0, _), (a1, r1, _) = self.posture(first), self.posture(last)
        plan = []
        for f in range(first + 1, last):
            t = (f - first) / (last - first)
            angles, _, source = self.posture(f)
            roots = (self.posture(f)[1] if source == "fit" else (1 - t) * r0 + t * r1)
            pins = {k: float((1 - t) * a0[k] + t * a1[k]) for k in axes}
            plan.append((f, angles, roots, pins, self.frame_input(f)))
        body = self.body

        def work(worker: TaskWorker):
            for k, (f, angles, roots, pins, dets) in enumerate(plan):
                worker.check_cancel()
                r = pinned_result(fitter, body, dets, f, angles, roots, pins, refit)
                worker.publish([(r, pins)])
                worker.report(k + 1, len(plan))

        return self._run_frames(work, f"interpolate frames {first}–{last}",
                                f"interpolating {len(plan)} frames …")

    def swap_candidate(self, frame: int | None = None) -> bool:
        """Replace the frame's posture by its next candidate posture (the alternatives the
        fit kept: an ``ambiguous`` frame's mirror posture); again cycles through them. The
        result is ``corrected`` (the user chose it). The choice carries to the neighbours
        that took the same wrong branch (:meth:`_carry_choice`); A again on that stretch
        cycles it as one. One undo step restores every frame it changed."""
        if self.busy:
            self.status.emit("wait for the running task to finish (or cancel it) first")
            return False
        frame = self.frame if frame is None else int(frame)
        current = self.results.get(frame)
        if current is None or len(current.candidates) < 2 or self.model is None:
            self.status.emit(f"frame {frame} has no alternative posture")
            return False
        # A again on a stretch the latest A set: the stretch cycles as one (with two
        # candidates, back to where it was)
        stretch = sorted(g for g, r in self._swapped.items() if self.results.get(g) is r)
        try:
            fitter = self._fitter()
            result = self._chosen_result(fitter, frame, current, 1)
            carried = ([self._chosen_result(fitter, g, self.results[g], 1) for g in stretch
                        if g != frame and len(self.results[g].candidates) >= 2]
                       if frame in stretch else
                       self._carry_choice(fitter, frame, current, result))
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        edit = Edit(f"frame {frame}: alternative posture")
        for r in (result, *carried):
            edit.record_result(r.frame, self.results.get(r.frame), r)
        self._freshen(edit, [r.frame for r in (result, *carried)])  # E of today's chain
        self._apply(edit, 1)
        self._push(edit)
        self._swapped = {r.frame: r for r in (result, *carried)
                         if r.status == backend.CORRECTED}
        swapped = sorted(r.frame for r in carried if r.status == backend.CORRECTED)
        flagged = sorted(r.frame for r in carried if r.status != backend.CORRECTED)
        also = "".join([
            f"; carried to frame{'s' if len(swapped) > 1 else ''} "
            f"{', '.join(map(str, swapped))}" if swapped else "",
            f"; frame{'s' if len(flagged) > 1 else ''} {', '.join(map(str, flagged))} still "
            "on the other branch: needs a look" if flagged else ""])
        self.status.emit(f"frame {frame}: alternative posture {len(current.candidates) - 1} "
                         f"of {len(current.candidates)}, error {result.error:.2f} px{also}")
        return True

    def _chosen_result(self, fitter, frame: int, current: backend.FrameResult, k: int
                       ) -> backend.FrameResult:
        """``current`` with its candidate ``k`` chosen: ``corrected``, E of that posture on
        the frame's input, the candidates cycled so that ``k`` is first."""
        cycled = (*current.candidates[k:], *current.candidates[:k])
        chosen = cycled[0]
        error, per_view = backend.posture_error(fitter, chosen.angles_deg,
                                                self.frame_input(frame), chosen.root_positions)
        return replace(backend.manual_result(
            frame, chosen.angles_deg, chosen.root_positions, error, per_view,
            self.params.seed if self.params else 0), candidates=cycled)

    def _carry_choice(self, fitter, frame: int, before: backend.FrameResult,
                      after: backend.FrameResult) -> list[backend.FrameResult]:
        """The neighbours that follow a swap at ``frame``. The fit chose a branch (say the
        mirror posture) for a stretch of frames, not one frame: walking away from ``frame``
        each way, a neighbour swaps too while its posture is nearer the branch given up
        than the one chosen and it kept a candidate clearly nearer the chosen one
        (:data:`CARRY_RATIO`); it stops at a frame set by hand, one without such a
        candidate, or one already on the chosen branch. A frame it stops at that is still
        on the branch given up is flagged ``ambiguous`` (it needs a look)."""
        held, out = self._held(), []
        for step in (1, -1):
            old = np.asarray(before.angles_deg, float)
            new = np.asarray(after.angles_deg, float)
            g = frame + step
            while 0 <= g < self.n_frames and g not in held:
                r = self.results.get(g)
                if r is None:
                    break
                here = np.asarray(r.angles_deg, float)
                to_new = adapters.angle_distance(here, new)
                if not adapters.angle_distance(here, old) < to_new:
                    break  # on the chosen branch already
                dist = np.array([adapters.angle_distance(np.asarray(c.angles_deg, float),
                                                         new) for c in r.candidates] or [np.nan])
                k = int(np.nanargmin(dist)) if np.isfinite(dist).any() else 0
                if k == 0 or not dist[k] < CARRY_RATIO * to_new:
                    # still on the branch given up, and nothing to swap to: a look is
                    # needed (it may be fitted right from its neighbour, F9)
                    if r.status in ("ok", "reanalysed"):
                        out.append(backend.with_status(r, "ambiguous"))
                    break
                out.append(self._chosen_result(fitter, g, r, k))
                old, new = here, np.asarray(r.candidates[k].angles_deg, float)
                g += step
        return out

    def drag_marker(self, view: int, marker: int, target_xy, refit: bool = True,
                    frame: int | None = None) -> bool:
        """Correct a frame (the current one by default) so that ``marker`` appears at
        ``target_xy`` in ``view``.

        The one axis that brings the marker nearest the target is found by
        :func:`ui.adapters.solve_marker_drag` and set; then every axis the marker depends on
        is pinned (so the marker stays where it was dropped) and the rest of the chain, the
        axes beyond the marker and other chains, is re-fitted as in :meth:`correct`.
        """
        if self.body is None or not self.cameras:
            return False
        frame = self.frame if frame is None else int(frame)
        angles, roots, _ = self.posture(frame)
        upstream = adapters.marker_axes(self.body, marker)
        # once a drag (or a nudge) pinned every axis above the marker, moving it again
        # may turn any of them: the user is placing this marker
        free = [k for k in upstream if k not in self.pins.get(frame, {})] or upstream
        solution = adapters.solve_marker_drag(self.body, self.cameras[view], angles, roots,
                                              marker, target_xy, axes=free)
        if solution is None:
            self.status.emit("no free axis moves this marker")
            return False
        values = {k: float(angles[k]) for k in upstream}
        values[solution.axis] = solution.value_deg
        return self.correct(values, refit=refit, frame=frame,
                            label=f"drag {self.body.marker_names[marker]} in "
                                  f"{self.view_names[view]}")

    def release_pins(self, frame: int | None = None) -> None:
        """Forget which axes of a frame were set by hand (undoable)."""
        frame = self.frame if frame is None else frame
        if self.pins.get(frame):
            edit = Edit("release pinned axes")
            edit.record_pins(frame, self.pins[frame], None)
            self._apply(edit, 1)
            self._push(edit)
            self.postureChanged.emit()

    # -- detection edits ----------------------------------------------------------------
    def edit_detection(self, view: int, remove=None, add=None, frame: int | None = None
                       ) -> bool:
        """Remove the detection at ``remove``, add one at ``add`` (both: move it) in a view
        of a frame (undoable). The fit and E use the edited detections at once: the frame's
        error is computed again for its posture (status kept)."""
        frame = self.frame if frame is None else int(frame)
        if self.keypoint_project:  # a keypoint is its tracker's label, not a blob
            self.status.emit("keypoints are not edited here: correct the posture instead "
                             "(sliders, drag a model marker), or fix the labels in the "
                             "tracker")
            return False
        if self.detections is None or not 0 <= frame < self.detections.n_records:
            self.error.emit("no detections to edit: run Detect markers first")
            return False
        if self.busy:  # a running fit has taken the detections as they were
            self.status.emit("wait for the running task to finish (or cancel it) first")
            return False
        edits = self.detection_edits
        if remove is not None:
            edits = detection_edits.remove_point(edits, frame, view, remove)
        if add is not None:
            edits = detection_edits.add_point(edits, frame, view, add)
        what = "move" if remove is not None and add is not None else (
            "remove" if remove is not None else "add")
        edit = Edit(f"{what} a detection in {self.view_names[view]}, frame {frame}",
                    detection_edits=(self.detection_edits, edits))
        return self._commit_edits(edit, edits, [frame])

    def _commit_edits(self, edit: Edit, edits, frames: list[int]) -> bool:
        """Apply detection edits ``edits`` as the undo step ``edit``: each of ``frames`` with a
        posture gets its E under them (status kept). The status bar shows the first frame's
        error."""
        for f in frames:
            result = self.results.get(f)
            if result is None or self.model is None or not np.all(
                    np.isfinite(result.angles_deg)):
                continue
            if self.keypoints is not None:  # the record's keypoints
                frame_input = self.keypoints.observations.take([f])
            else:
                frame_input = [detection_edits.apply_edit(self.detections.points_of(f, v),
                                                          edits.get((f, v)))
                               for v in range(len(self.views))]
            try:
                error, per_view = self._fitter().error(
                    result.angles_deg, frame_input, result.root_positions,
                    self._marks_of(edits, f, self.body.marker_names))
            except LocatedError as err:
                self.error.emit(str(err))
                return False
            edit.record_result(f, result, replace(result, error=error,
                                                  error_per_view=per_view,
                                                  marker_residuals=None))
        self._apply(edit, 1)
        self._push(edit)
        self.status.emit(edit.label + (f": error {self.results[frames[0]].error:.2f} px"
                                       if frames[0] in self.results else ""))
        return True

    def _marks_of(self, edits, frame: int, names) -> np.ndarray | None:
        """(n_views, len(names)) the markers ``names`` hidden in each view of one record under
        ``edits``, or None when none is."""
        marks = detection_edits.hidden_marks({k: e for k, e in edits.items() if k[0] == frame},
                                             frame + 1, len(self.views), names)
        return None if marks is None else marks[frame]

    def toggle_hidden(self, view: int, marker: int, frames: Iterable[int] | None = None
                      ) -> bool:
        """Mark a model marker hidden in a view (occluded, or its blob merged with another's)
        or seen again, in the frame shown or in ``frames`` (undoable, one step): the fit and
        E leave it out of that view at once. The frames' errors are computed again for their
        postures (status kept). In a keypoint project the marker's keypoint there counts as
        missing (a label the tracker put on the wrong spot)."""
        observed = self.fit_detections
        if observed is None or self.body is None:
            self.error.emit("no detections to mark: run Detect markers first"
                            if not self.keypoint_project else "no keypoints to mark")
            return False
        if isinstance(observed, Observations) and observed.kind == "points3d":
            self.error.emit("this project fits triangulated 3D points: a keypoint cannot be "
                            "hidden in one view ([keypoints] route = '2d' can)")
            return False
        if self.busy:
            self.status.emit("wait for the running task to finish (or cancel it) first")
            return False
        fitter = self._fitter_or_report()
        if fitter is None:
            return False
        if not self.keypoint_project and fitter.match_for(observed) == "3d":
            self.error.emit("markers are matched in 3D here (match): a marker cannot be hidden "
                            "in one view; set match = 'views' in the fitting settings first")
            return False
        shown = self.display_body.marker_names  # what was clicked: the drawn chain
        name = shown[marker] if 0 <= marker < len(shown) else None
        if name not in self.body.marker_names:
            self.status.emit("that marker is not in the chain yet: apply the chain edit first")
            return False
        unseen = fitter.unseen
        if unseen is not None and 0 <= view < len(unseen) and unseen[view][
                self.body.marker_names.index(name)]:
            self.status.emit(f"view {self.view_names[view]} does not show {name} ([[views]] "
                             f"model_markers): it is never matched there")
            return False
        frames = [self.frame] if frames is None else sorted({int(f) for f in frames})
        n_records = (observed.n_frames if isinstance(observed, Observations)
                     else observed.n_records)
        frames = [f for f in frames if 0 <= f < n_records]
        if not frames:
            self.status.emit("no detections in this frame to mark a marker hidden in")
            return False
        lead = self.frame if self.frame in frames else frames[0]  # the frame looked at
        hide = not detection_edits.is_hidden(self.detection_edits, lead, view, name)
        edits = self.detection_edits
        for f in frames:
            if detection_edits.is_hidden(edits, f, view, name) != hide:
                edits = detection_edits.toggle_hidden(edits, f, view, name)
        where = f"frame {frames[0]}" if len(frames) == 1 else \
            f"frames {frames[0]}–{frames[-1]}"
        edit = Edit(f"{'hide' if hide else 'show'} {name} in {self.view_names[view]}, {where}",
                    detection_edits=(self.detection_edits, edits))
        return self._commit_edits(edit, edits, frames)

    # -- histograms ---------------------------------------------------------------------
    def learn_histograms(self, within_threshold: bool = True) -> int:
        """Eq. 4 learning from the analysed frames: those within the current threshold
        (corrected, or E ≤ :attr:`threshold` now, see :func:`ui.adapters.trusted`), or every
        fitted frame. Returns the number of frames learned from (0: nothing changed).
        """
        from kinematics.histogram_xml import apply_archive, archive_from_body, update_archive

        angles = (adapters.learning_angles(self.results, threshold=self.threshold)
                  if within_threshold else adapters.learning_angles(self.results, None))
        if self.body is None or len(angles) == 0:
            self.status.emit("no analysed frames to learn from")
            return 0
        archive = update_archive(archive_from_body(self.body), self.body, angles)
        self.commit_body(apply_archive(self.body, archive),
                         f"learn histograms from {len(angles)} frames", geometry=False)
        self.status.emit(f"histograms learned from {len(angles)} frames (Eq. 4)")
        return len(angles)

    def export_histograms(self, path) -> bool:
        """Write every axis' histogram to a histogram archive XML."""
        from kinematics.histogram_xml import archive_from_body, save_archive

        try:
            save_archive(path, archive_from_body(self.body))
        except (LocatedError, OSError) as err:
            self.error.emit(error_text(err) if isinstance(err, LocatedError) else
                            f"{path}: {err.strerror}")
            return False
        self.status.emit(f"wrote histograms to {path}")
        return True

    def import_histograms(self, path) -> bool:
        """Apply a histogram archive to the chain (undoable)."""
        from kinematics.histogram_xml import apply_archive, load_archive

        try:
            body = apply_archive(self.body, load_archive(path))
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        return self.commit_body(body, f"load histograms from {Path(path).name}",
                                geometry=False)

    # -- chain file ---------------------------------------------------------------------
    def save_chain_as(self, path, body: Body | None = None) -> bool:
        """Write the chain (or ``body``) as chain XML (histograms included)."""
        from kinematics.chain_xml import save_body

        try:
            save_body(path, body or self.body)
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        self.status.emit(f"wrote chain to {path}")
        return True

    # -- detection ----------------------------------------------------------------------
    def detect(self) -> bool:
        """Detect markers in every frame (background) and save the detections file."""
        if self.keypoint_project:
            self.status.emit("a keypoint project has no markers to detect")
            return False
        if self.settings is None:
            self.error.emit("the project's views or filters are not valid")
            return False
        config = self.config

        def work(worker: TaskWorker):
            return backend.detect_markers(config, worker.report, worker.cancel_requested)

        def finish(run) -> None:
            self.detections, self.detections_path = run.detections, run.detections_path
            self._frames.clear()
            self.set_frame(min(self.frame, max(self.n_frames - 1, 0)))
            self.status.emit(f"wrote {run.detections_path}: {len(run.detections.points)} "
                             f"markers in {run.detections.n_records} frames")
            for message in run.warnings:
                self.status.emit(f"warning: {message}")
            self.detectionsChanged.emit()
            self.frameChanged.emit(self.frame)

        return self.run_task(work, finish, "detecting markers …")

    # -- saving -------------------------------------------------------------------------
    def save(self) -> bool:
        """Write what changed: the project config, the chain file, the results file."""
        from kinematics.chain_xml import save_body
        from kinematics.fileio import atomic_write_text

        try:
            if "config" in self._dirty:
                from videotrack.config import updated_toml_text

                # edit the file in place: the user's comments and layout survive
                text = self.config.path.read_text(encoding="utf-8")
                atomic_write_text(self.config.path, updated_toml_text(text, self.raw_config))
            if "chain" in self._dirty and self.model is not None:
                save_body(self.model.chain_path, self.body)
            if "detection edits" in self._dirty and self.results_path is not None:
                path = detection_edits.edits_path(self.results_path)
                if self.detection_edits or path.exists():
                    detection_edits.save_edits(path, self.detection_edits, self.view_names)
            if "results" in self._dirty and self.model is not None:
                model = replace(self._fit_model(), body=self.body, params=self.params)
                backend.save_project_results(self.results_path, model, self.body,
                                             self.results, self._records(),
                                             self.detections_path)
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        except OSError as err:
            self.error.emit(f"{err.filename}: {err.strerror}")
            return False
        saved = ", ".join(self.unsaved) or "nothing to save"
        self._dirty.clear()
        self.dirtyChanged.emit(False)
        self.status.emit(f"saved {saved}")
        return True
