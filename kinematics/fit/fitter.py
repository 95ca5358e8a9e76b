"""Posture fitting by simulated annealing (paper Sect. 2.3: Eq. 5, Eq. 6, Table 1).

:class:`Fitter` packs a body, its cameras and its histograms once and fits frames of marker
detections: :meth:`Fitter.fit_frame` one frame, :meth:`Fitter.iter_fit` a range or a whole
video as a generator of :class:`FrameResult` in frame order, computing chunks of frames in
parallel on all of numba's threads. Closing the generator cancels the run (between chunks).
The generator never prints and never touches files.

Per frame (numba kernels in :mod:`kinematics._kernels.frames`; the jobs around them
in the mixins of :mod:`kinematics.fit`):

1. start from the histogram means (Sect. 3.1) or the previous frame's result;
2. anneal (Eq. 6 steps, histogram plausibility, Metropolis, τ and l schedules, stop after
   ``n_end`` iterations or once E < ε), keeping the best posture seen;
3. optionally refine it locally (:mod:`kinematics.fit.refine`) and score it by E again;
4. if E > ``reanalysis_threshold`` fit again on a new random stream, at most ``max_runs``
   runs in all, keeping the run with the lowest E (Table 1 note).

With refinement, E of a correct fit drops to the centroid noise level, so a much lower
re-analysis threshold separates right from wrong minima, which is what lets a short
schedule keep the accuracy (docs/fitting.md).

Reproducibility: run ``r`` of frame ``f`` draws from a splitmix64 stream keyed by
``(seed, f, r)``, so results are bit-identical whatever the number of threads or the chunking,
and a single frame can be replayed from its seed and frame number.

Start posture trade-off. ``start="mean"`` (the default, and the paper's spirit) makes every
frame independent: a badly fitted frame never spoils the next one, concatenated sequences
need no care, and all frames run in parallel. ``start="previous"`` starts each frame from the
previous frame's result; with the Table 1 schedule this buys nothing (τ0 = 200 px lets the
first thousands of iterations wander far from any start), but it lets a much shorter and
colder schedule (small ``tau0`` and ``l0``) track smooth movement. It makes frames depend on
each other, so frames are cut into independent segments of ``segment_length`` consecutive
frames (each starting from the means), fitted one segment per thread; results still do not
depend on the thread count. Re-runs of a frame always start from the means.
``start="track"`` is that short cold schedule, for video filmed fast enough that a posture
moves little from frame to frame (a fly at 330 frames/s): each segment's first frame is
fitted in full, every next frame by one cold local anneal from the previous frame's result
(``Tuning.track_share`` of the schedule, as the path's re-fits), and a frame whose E is above the
threshold or jumps (``Tuning.track_jump``) is fitted in full again (``Fitter._track``). Limbs are
merged between two fits by how well each explains its own markers, and neighbouring segments
(and the frames before a full fit inside one) are mended by tracking across
(``Fitter._mend``, ``Fitter._retrack``).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import replace

import numba
import numpy as np

from kinematics._kernels import codes as _codes
from kinematics._kernels import objective as _objective
from kinematics._kernels import posture as _posture
from kinematics._kernels.records import FrameObs
from kinematics.errors import KinematicsError
from kinematics.fit import tuning as _tuning
from kinematics.fit.candidates import CandidatesMixin
from kinematics.fit.confidence import ConfidenceMixin
from kinematics.fit.dispatch import DispatchMixin
from kinematics.fit.flags import flag_misplaced
from kinematics.fit.inputs import Ragged, as_ragged, unseen_markers
from kinematics.fit.match import MatchMixin
from kinematics.fit.path import PathMixin
from kinematics.fit.polish import PolishMixin, held_limb
from kinematics.fit.problem import (
    FitProblem,
    error_args,
)
from kinematics.fit.reacquire import ReacquireMixin
from kinematics.fit.result import Candidate, FrameResult
from kinematics.fit.roots import RootsMixin
from kinematics.fit.settings import AnnealParams
from kinematics.fit.status import StatusMixin
from kinematics.fit.tracking import TrackingMixin
from kinematics.fit.tuning import Tuning
from kinematics.fit.uncertainty import UncertaintyMixin
from kinematics.model import Body
from kinematics.observe.cloud import cloud_observations
from kinematics.observe.observations import Observations


class Fitter(MatchMixin, RootsMixin, DispatchMixin, StatusMixin, PolishMixin, CandidatesMixin,
             PathMixin, TrackingMixin, ConfidenceMixin, UncertaintyMixin, ReacquireMixin):
    """Fits a body's posture to marker detections, frame by frame.

    Parameters
    ----------
    body : Body
        The kinematic chains with their histograms (constraints and step scales).
    cameras : mapping name -> Camera, or sequence of Camera
        One camera per view, in the order of the detections' views; a sequence takes the
        cameras' names as view names.
    params : AnnealParams, optional
        Table 1 defaults.
    view_markers : mapping view name -> sequence of marker names, optional
        The model markers a view can show; a view not named shows all. Markers left out
        are hidden in that view in every frame (:meth:`Observations.with_hidden`): a view
        that keeps only one colour of marker (``hsv_lower``/``hsv_upper`` of a project's
        ``[[views]]``) matches its detections to the markers of that colour only, so legs
        marked in different colours cannot take each other's markers; a camera that never
        sees the far side of the body leaves those markers out.
    tuning : Tuning, optional
        The fitter's measured constants (:mod:`kinematics.fit.tuning`); default the
        record :data:`kinematics.fit.tuning.TUNING` holds when the fitter is made.

    Attributes
    ----------
    problem : FitProblem
        The packed problem every backend uses (:mod:`kinematics.fit.problem`).
    noise : NoiseModel or None
        σ per view of the last :meth:`iter_fit` (:mod:`kinematics.fit.noise`), once known.
    setup_warnings : list of str
        The set-up problems the last :meth:`iter_fit` found and ``accept_setup`` accepted.

    Raises
    ------
    KinematicsError
        The body is invalid, has no markers or no free axis, or there are no cameras.
    """


    def __init__(self, body: Body, cameras, params: AnnealParams | None = None,
                 view_markers: Mapping[str, Sequence[str]] | None = None,
                 tuning: Tuning | None = None) -> None:
        self.tuning = tuning if tuning is not None else _tuning.TUNING
        self.params = params if params is not None else AnnealParams()
        if not isinstance(self.params, AnnealParams):
            raise KinematicsError("params must be an AnnealParams", field="params")
        self.problem = FitProblem.build(body, cameras)
        self.body = body
        self.cameras = list(self.problem.cameras)
        self.view_names = list(self.problem.view_names)
        self.unseen = unseen_markers(view_markers, self.view_names, body.marker_names)
        self._locked = body.locked_mask()
        self._mean_deg = self.problem.mean_deg
        self._range_centres_deg = body.ranges_deg().mean(axis=1)  # (per result: 8 µs each)
        self._roots = body.root_positions()
        self._tracked = [k for k, c in enumerate(body.chains) if c.root.mode == "marker"]
        names = body.marker_names
        self._root_marker = {k: names.index(body.chains[k].root.marker) for k in self._tracked}
        self._per_problem: dict = {}  # what depends only on the problem (_once)
        self.noise = None
        #: a noise model to judge by instead of measuring one (a resumed fit: the one that
        #: judged the frames kept)
        self.fixed_noise = None
        self._noise_measured = False
        self._seeds = self._run_params = None  # a fit's root seeds and settings (_iter)
        self.setup_warnings: list[str] = []

    def with_pins(self, pins) -> Fitter:
        """A fitter that holds the given axes (``joint.axis`` labels or posture indices ->
        degrees) at their values while it fits the rest (:meth:`FitProblem.with_pins`):
        a manual correction re-fitted around what the user set."""
        other = copy.copy(self)
        other.problem = self.problem.with_pins(pins)
        return other

    @property
    def n_views(self) -> int:
        return len(self.cameras)

    @property
    def axis_labels(self) -> list[str]:
        return self.body.axis_labels

    @property
    def start_posture_deg(self) -> np.ndarray:
        """The histogram-mean start posture (Sect. 3.1), shape (n_axes,)."""
        return self._mean_deg.copy()

    def _posture_deg(self, angles_deg) -> np.ndarray:
        a = np.asarray(angles_deg, dtype=float)
        if a.shape != (self.body.n_axes,):
            raise KinematicsError(f"posture needs {self.body.n_axes} angles, got shape "
                                  f"{a.shape}", field="angles_deg")
        if not np.all(np.isfinite(a)):
            raise KinematicsError("posture angles must be finite", field="angles_deg")
        return a

    def _root_array(self, root_positions) -> np.ndarray:
        if root_positions is None:
            return np.ascontiguousarray(self._roots, dtype=float)
        r = np.asarray(root_positions, dtype=float)
        if r.shape != self._roots.shape or not np.all(np.isfinite(r)):
            raise KinematicsError(f"root positions need finite shape {self._roots.shape}, got "
                                  f"{r.shape}", field="root_positions")
        return np.ascontiguousarray(r)

    def state(self, angles_deg, root_positions=None):
        """Kernel state of a posture: ``(state, root_pos, root_rot)``
        (:meth:`FitProblem.state`), after checking shapes and values."""
        return self.problem.state(self._posture_deg(angles_deg),
                                  self._root_array(root_positions))

    @property
    def unseen_marks(self) -> np.ndarray:
        """A frame's ``obs3`` slot for detections given per view: the markers no view shows
        (``view_markers``) as the kernels read hidden marks, or no mark."""
        if self.unseen is None:
            return _codes.NO_HIDDEN
        return np.ascontiguousarray(self.unseen.T, dtype=float)

    def observations(self, data) -> Observations:
        """``data`` as :class:`~kinematics.observe.observations.Observations`: an
        Observations object
        (checked against the cameras), or unlabelled detections in any form
        :meth:`iter_fit` takes."""
        if isinstance(data, Observations):
            if data.kind == "points3d":
                return data
            obs = data
        else:
            obs = None
        if not self.cameras:
            raise KinematicsError("no cameras: 2D observations need one camera per view",
                                  field="cameras")
        if obs is None:
            obs = self._unlabelled(data)
        elif list(obs.view_names) != self.view_names:
            raise KinematicsError(f"observations are for views {list(obs.view_names)} but "
                                  f"the cameras are {self.view_names}", field="observations")
        nm = len(self.body.marker_names)
        for marks in (obs.hidden, obs.unseen):
            if marks is not None and marks.shape[-1] != nm:
                raise KinematicsError(f"hidden marks are for {marks.shape[-1]} markers, the "
                                      f"body has {nm}", field="hidden")
        if obs.kind == "cloud" and obs.points3d.shape[2] not in (4, 4 + nm):
            raise KinematicsError(f"a cloud needs 4 columns, or 4 + {nm} (one per marker), "
                                  f"got {obs.points3d.shape[2]}", field="cloud")
        if obs.kind == "points" and self.match_for(obs) == "3d":
            if self._views_3d < 3:
                each = " of each colour (views that show the same markers)" if (
                    self.unseen is not None) else ""
                raise KinematicsError(f"match '3d' triangulates markers seen in 3 or more "
                                      f"views{each}; there are {self._views_3d}: use 'views'",
                                      field="match")
            return cloud_observations(self.cameras, obs, self.unseen)
        if self.unseen is not None and obs.kind in ("points", "keypoints"):
            obs = obs.with_unseen(self.unseen)
        return obs

    def _frame_ragged(self, detections_frame) -> Ragged:
        return as_ragged([detections_frame], self.view_names)

    def _unlabelled(self, data) -> Observations:
        """Unlabelled detections in any form :meth:`iter_fit` takes, as Observations."""
        rag = as_ragged(data, self.view_names)
        return Observations.unlabelled(rag.points, rag.offsets, self.view_names, rag.dropped)

    def _marks(self, obs: Observations, frames) -> np.ndarray | None:
        """(len(frames), n_views, n_markers) markers hidden in each view: the observations'
        marks, or for a cloud the views' (``view_markers``), or None."""
        if obs.kind == "cloud" and self.unseen is not None:
            return np.broadcast_to(self.unseen, (len(frames), *self.unseen.shape))
        return obs.marks(frames)

    def _to_range_deg(self, angles_rad: np.ndarray) -> np.ndarray:
        """Degrees, each angle moved by whole turns to lie nearest its range centre."""
        deg = np.rad2deg(angles_rad)
        return deg + 360.0 * np.round((self._range_centres_deg - deg) / 360.0)

    def project(self, angles_deg, root_positions=None) -> np.ndarray:
        """Model markers of a posture projected into every view (the annealing kernel's
        forward kinematics), shape (n_views, n_markers, 2) pixels."""
        return self._project_state(*self.state(angles_deg, root_positions))

    def _project_state(self, state, root_pos, root_rot, *, markers: bool = False):
        """Projections (n_views, n_markers, 2) of a kernel state; with ``markers`` also the
        3D markers (n_markers, 3)."""
        f = self.problem.folded
        nj, nm, ns = f.parent.size, f.marker_joint.size, state.size
        proj = np.empty((self.n_views, nm, 2))
        mk = np.empty((nm, 3))
        _posture.project_posture(state, root_pos, root_rot, f, self.problem.cams, np.empty(ns),
                                 np.empty(ns), np.empty((nj, 3, 3)), np.empty((nj, 3)), mk,
                                 proj)
        return (proj, mk) if markers else proj

    def error(self, angles_deg, detections_frame, root_positions=None, hidden=None
              ) -> tuple[float, np.ndarray]:
        """E of a posture for one frame (kernel; e.g. for a manual correction).

        Parameters
        ----------
        angles_deg : array_like, shape (n_axes,)
        detections_frame : sequence of array_like (n_c, 2), one per view, or one record's
            :class:`~kinematics.observe.observations.Observations` (labelled keypoints or 3D points:
            E is then the objective they are fitted by)
        root_positions : array_like, shape (n_chains, 3), optional
        hidden : array_like of bool, shape (n_views, n_markers), optional
            Markers hidden in a view (:meth:`Observations.with_hidden`), for detections
            given per view.

        Returns
        -------
        error : float
        error_per_view : ndarray, shape (n_views,) (zeros for 3D points)
        """
        frame = (detections_frame if isinstance(detections_frame, Observations)
                 else self._unlabelled([detections_frame]))
        if hidden is not None:
            marks = np.asarray(hidden, bool)
            shape = (self.n_views, len(self.body.marker_names))
            if marks.shape != shape:
                raise KinematicsError(f"hidden marks need shape {shape} (views, markers), "
                                      f"got {marks.shape}", field="hidden")
            if frame.kind == "points":  # before the match is decided: marks keep it per view
                frame = frame.with_hidden(marks[None])
        if isinstance(detections_frame, Observations) or self.match_for(frame) == "3d" or (
                hidden is not None or self.unseen is not None):
            obs = self.observations(frame)
            if hidden is not None:
                obs = obs.with_hidden(marks[None])
            state, pos, rot = self.state(angles_deg, root_positions)
            return self._state_error(obs.arrays(np.array([0], np.int64)), state, pos, rot,
                                     self.params)
        per_view = np.empty(self.n_views)
        opts = self.params.error
        state, pos, rot = self.state(angles_deg, root_positions)
        nm = self.problem.folded.marker_joint.size
        obs = FrameObs(_codes.OBJ_NEAREST, frame.points, np.ones(len(frame.points)),
                       frame.offsets, np.zeros((nm, 4)))
        e = _objective.posture_error(state, pos, rot, self.problem.folded, self.problem.cams,
                                     obs, error_args(opts), per_view)
        return float(e), per_view

    @staticmethod
    def _frame_indices(frames, n_frames: int) -> np.ndarray:
        if frames is None:
            return np.arange(n_frames, dtype=np.int64)
        if isinstance(frames, range):
            idx = np.arange(frames.start, frames.stop, frames.step, dtype=np.int64)
        else:
            idx = np.asarray(list(frames) if not isinstance(frames, np.ndarray) else frames)
            if idx.size and idx.dtype.kind not in "iu":
                raise KinematicsError("frame numbers must be integers", field="frames")
            idx = idx.astype(np.int64).ravel()
        if idx.size and (idx.min() < 0 or idx.max() >= n_frames):
            raise KinematicsError(f"frame numbers must be in [0, {n_frames}), got "
                                  f"{idx.min()}..{idx.max()}", field="frames")
        return idx

    def fit_frame(self, detections_frame, frame: int = 0, *, start_deg=None,
                  root_positions=None) -> FrameResult:
        """Fit one frame.

        Parameters
        ----------
        detections_frame : sequence of array_like (n_c, 2), one per view
            Detected points of each view (NaN rows are dropped and counted).
        frame : int
            Frame number: keys the random streams, so a frame of a video fitted alone gives
            the same result as within :meth:`iter_fit` (same start and root).
        start_deg : array_like, shape (n_axes,), optional
            Start posture of the first run; default the histogram means.
        root_positions : array_like, shape (n_chains, 3), optional
            Root of each chain; default the configured positions (a single frame cannot
            track a root marker). Free roots are placed from this frame's detections unless
            given here.
        """
        obs, roots, rots = self._one_frame(detections_frame, frame, root_positions,
                                           "fit_frame")
        start = self.problem.start
        if start_deg is not None:
            start = self.problem.state(self._posture_deg(start_deg), roots[0])[0]
            for q in range(len(self.problem.free_chains)):
                start[self.problem.root_axes[q]] = 0.0  # the seed holds the root's rotation
        return held_limb(*self._polished(obs, 0, self._fit_block(
            obs, np.zeros(1, np.int64), np.array([int(frame)], np.int64), roots, rots, start,
            np.array([0, 1], np.int64))[0]), self._apart(self.params))

    def _one_frame(self, detections_frame, frame, root_positions, caller: str):
        """The observations of one frame, its roots (1, n_chains, 3) and root rotations:
        the configured roots, or ``root_positions``; free roots placed from the frame's
        detections unless given."""
        if isinstance(frame, bool) or not isinstance(frame, int | np.integer) or frame < 0:
            raise KinematicsError(f"frame must be an integer >= 0, got {frame!r}",
                                  field="frame")
        obs = self.observations(detections_frame if isinstance(detections_frame, Observations)
                                else [detections_frame])
        if obs.n_frames != 1:
            raise KinematicsError(f"{caller} takes one frame, got {obs.n_frames}",
                                  field="observations")
        roots = self._root_array(root_positions)[None].copy()
        rots = self.problem.identity_rotations(1)
        if self.problem.free_chains:
            seed_pos, seed_rot = self._place(obs, np.zeros(1, np.int64))
            for c in self.problem.free_chains:
                rots[0, c] = seed_rot[0, c]
                if root_positions is None:
                    roots[0, c] = seed_pos[0, c]
        return obs, roots, rots

    def refine_frame(self, detections_frame, frame: int, start_deg,
                     root_positions=None) -> FrameResult | None:
        """A posture refined at one frame without annealing away from it (the start,
        refined as the path's carried re-fits refine a neighbour's posture): a posture
        carried from a neighbour stays on its branch where a lower-E minimum (a mirror
        posture, a ghost in an occluded marker's place) would draw even a cold anneal
        away. Arguments as :meth:`fit_frame`; None where the frame has nothing to fit."""
        obs, roots, _ = self._one_frame(detections_frame, frame, root_positions,
                                        "refine_frame")
        seed = Candidate(self._posture_deg(start_deg), roots[0], np.nan, None, None, None)
        counted: list[int] = []
        found = self._refit_from(obs, 0, seed, self.params, polish=True, counted=counted)
        if found is None:
            return None
        return held_limb(*self._polished(obs, 0, self._frame_result(
            obs, 0, int(frame), found.state, found.seed_pos, found.seed_rot, self.params,
            runs=1, iterations=counted[0], pairs=0, error=None, candidates=(found,))),
            self._apart(self.params))

    def iter_fit(self, detections, frames=None, *, chunk_size: int | None = None,
                 sequence_starts: Iterable[int] = (),
                 previous: FrameResult | Sequence[FrameResult] | None = None,
                 cancel: Callable[[], bool] | None = None,
                 check_setup: bool = True) -> Iterator[FrameResult]:
        """Fit frames of a video; yields one :class:`FrameResult` per frame, in order.

        Parameters
        ----------
        detections : Detections-like or sequence of frames
            ``points`` (n, 2) with ``offsets`` (n_frames * n_views + 1,) (and optionally
            ``view_names``, checked against the cameras), or a sequence of frames each
            holding one (n_c, 2) array per view.
        frames : iterable of int, optional
            Frame indices to fit, in the order wanted (root tracking and
            ``start="previous"`` follow this order); default all.
        chunk_size : int, optional
            Frames computed per parallel batch (default 8 per thread, or 2 segments per
            thread with ``start="previous"``, or with the lane backend enough runs to fill
            its lanes twice; rounded up to whole segments); closing the generator takes
            effect between batches.
        sequence_starts : iterable of int
            Frames where a new, independent sequence starts (concatenated recordings): the
            path through time (``candidates`` > 1) never links across them. Gaps in
            ``frames`` and jumps of the movement itself are found without help.
        previous : FrameResult or sequence of FrameResult, optional
            The results chosen just before the first of ``frames`` (a resumed fit; the last
            ``Tuning.cut_context`` are used, the last one is where the path continues from). The
            path decides frames in windows of 2 x ``Tuning.path_lag`` frames that start every
            Tuning.path_lag frames, so a fit resumed at a multiple of Tuning.path_lag, with
            the results
            before it, chooses as the whole would (with the final polish,
            ``final_polish_px``, it continues from the polished postures, where the whole
            continued from the fitted ones: a choice between candidates that nearly tie can
            differ at the seam).
        cancel : callable, optional
            Asked before each batch; once it returns True no further batch is fitted and
            the frames fitted so far are yielded (the path through time holds back up to 64
            of them and the misplaced-marker flag 32 more, so closing the generator alone
            can wait that long).
        check_setup : bool
            Check the detections before fitting (:meth:`check_setup`); False where the
            caller does, on detections still to come (fitting while detecting).

        Raises
        ------
        KinematicsError
            Detections whose views do not match the cameras, bad frame numbers.
        SetupError
            A set-up the checks find wrong (unless ``accept_setup``; then
            :attr:`setup_warnings` says it): :mod:`kinematics.fit.confidence`.
        """
        obs = self.observations(detections)
        idx = self._frame_indices(frames, obs.n_frames)
        self.noise, self._noise_measured = self.fixed_noise, self.fixed_noise is not None
        self._seeds = self._run_params = None
        if check_setup:  # (else the caller checks and keeps what it accepts)
            self.setup_warnings = []
            self._check_detections(obs)
        starts = np.asarray(list(sequence_starts), np.int64)
        before = ([] if previous is None else [previous] if isinstance(previous, FrameResult)
                  else list(previous))
        out = self._final_polish(obs, idx, self._iter(obs, idx, chunk_size, starts, before,
                                                      cancel))
        p = self.params
        if p.candidates > 1 and p.start != "track":  # the frames to look at, after the polish
            out = flag_misplaced(out, p.claim_gate_px, before=before, starts=starts,
                                 tuning=self.tuning)
        return self._noise_judged(obs, idx, self._reacquired(obs, idx, out))

    def _iter(self, obs: Observations, idx: np.ndarray, chunk_size: int | None,
              starts: np.ndarray | None = None, before: Sequence[FrameResult] = (),
              cancel: Callable[[], bool] | None = None) -> Iterator[FrameResult]:
        starts = np.zeros(0, np.int64) if starts is None else starts
        roots, rots = self._place(obs, idx)
        self._seeds = roots, rots  # what a free root re-acquires from (reacquire.py)
        params = self.params
        if params.start == "track":  # measures its threshold on its first tracked frames
            yield from self._track(obs, idx, roots, rots, params, cancel)
            return
        noise_wanted = (params.noise_floor_px is not None and params.noise_px is None
                        and self.fixed_noise is None)
        if (params.threshold_mode == "auto" or noise_wanted) and len(idx):
            positions, sample = self._video_sample(obs, idx, roots, rots)
            if params.threshold_mode == "auto":
                params = replace(params, reanalysis_threshold=self._threshold_of(
                    obs, positions, [r.error for r in sample]))
            self._measure_video(obs, list(zip(positions.tolist(), sample, strict=True)))
        self._run_params = params  # (with its threshold measured): re-fits use the same
        threads = numba.get_num_threads()
        seg = self.params.segment_length if self.params.start == "previous" else 1
        if chunk_size is None:  # enough frames (or segments) to keep every thread busy
            chunk = 8 * threads if seg == 1 else 2 * threads * seg
            if seg == 1 and params.backend != "scalar":  # and, for lanes, their lanes
                chunk = max(chunk, 2 * self.lane_frames())
        else:
            chunk = chunk_size
        if isinstance(chunk, bool) or not isinstance(chunk, int | np.integer) or chunk < 1:
            raise KinematicsError(f"chunk_size must be an integer >= 1, got {chunk!r}",
                                  field="chunk_size")
        chunk = -(-chunk // seg) * seg

        def chunks():
            for a in range(0, len(idx), chunk):
                if cancel is not None and cancel():
                    return
                sel = idx[a: a + chunk]
                n = len(sel)
                seg_off = np.unique(np.r_[np.arange(0, n, seg), n]).astype(np.int64)
                yield self._fit_block(obs, sel, sel, np.ascontiguousarray(roots[a: a + chunk]),
                                      np.ascontiguousarray(rots[a: a + chunk]),
                                      self.problem.start, seg_off, params)

        if params.candidates > 1:
            yield from self._over_time(obs, idx, roots, rots, chunks(), starts, before,
                                       params)
        else:
            for block in chunks():
                yield from block

    def fit(self, detections, frames=None, **kwargs) -> list[FrameResult]:
        """All results of :meth:`iter_fit` as a list."""
        return list(self.iter_fit(detections, frames, **kwargs))

    def _once(self, key: tuple, make):
        """``make()``, computed once per problem and ``key`` (a copy made by
        :meth:`with_pins` shares the store but not the problem)."""
        key = (self.problem, *key)
        if key not in self._per_problem:
            self._per_problem[key] = make()
        return self._per_problem[key]


def fit_frame(body: Body, cameras, detections_frame, params: AnnealParams | None = None,
              **kwargs) -> FrameResult:
    """:meth:`Fitter.fit_frame` without keeping a fitter (packs the body every call)."""
    return Fitter(body, cameras, params).fit_frame(detections_frame, **kwargs)


def iter_fit(body: Body, cameras, detections, params: AnnealParams | None = None,
             frames: Iterable[int] | None = None, **kwargs) -> Iterator[FrameResult]:
    """:meth:`Fitter.iter_fit` for a body, cameras and parameters."""
    return Fitter(body, cameras, params).iter_fit(detections, frames, **kwargs)
