"""The GUI's one state object: project, video, views, cameras, chain, detections, results.

Widgets call :class:`Session` methods and redraw when its signals fire; they keep no state
of their own that the session also has. Long work (fitting, detection, a correction's
re-fit) runs in a worker thread (:mod:`ui.state.workers`) and its results are applied here,
in the GUI thread. Every change of results or chain is an undoable
:class:`~ui.state.history.Edit`.

:class:`Session` is one QObject (its signals are here) assembled from one mixin per concern,
each in its own module of :mod:`ui.state`; :meth:`Session._clear` lists the state they share.
"""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path

import numpy as np
from PySide6.QtCore import QObject, Signal

from kinematics.model import Body
from ui.state import backend
from ui.state.corrections import CorrectionsMixin
from ui.state.detections import DetectionsMixin
from ui.state.fitting import FittingMixin
from ui.state.frames import FramesMixin
from ui.state.histograms import HistogramsMixin
from ui.state.history import Edit, HistoryMixin
from ui.state.project import ProjectMixin
from ui.state.saving import SavingMixin
from ui.state.tasks import TasksMixin


class Session(ProjectMixin, FramesMixin, DetectionsMixin, HistoryMixin, TasksMixin,
              FittingMixin, CorrectionsMixin, HistogramsMixin, SavingMixin, QObject):
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
        #: σ per view of the noise model the last fit of the whole video measured (or the
        #: results' sidecar records): a fit of some frames is judged by it, not by its own.
        self.measured_noise: list[float] | None = None
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

