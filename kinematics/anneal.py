"""Posture fitting by simulated annealing (paper Sect. 2.3: Eq. 5, Eq. 6, Table 1).

:class:`Fitter` packs a body, its cameras and its histograms once and fits frames of marker
detections: :meth:`Fitter.fit_frame` one frame, :meth:`Fitter.iter_fit` a range or a whole
video as a generator of :class:`FrameResult` in frame order, computing chunks of frames in
parallel on all of numba's threads. Closing the generator cancels the run (between chunks).
The generator never prints and never touches files.

Per frame (numba kernels in :mod:`kinematics._anneal_kernels`):

1. start from the histogram means (Sect. 3.1) or the previous frame's result;
2. anneal (Eq. 6 steps, histogram plausibility, Metropolis, τ and l schedules, stop after
   ``n_end`` iterations or once E < ε), keeping the best posture seen;
3. optionally refine it locally (:mod:`kinematics.refine`) and score it by E again;
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
(:data:`TRACK_SHARE` of the schedule, as the path's re-fits), and a frame whose E is above the
threshold or jumps (:data:`TRACK_JUMP`) is fitted in full again (``Fitter._track``). Limbs are
merged between two fits by how well each explains its own markers, and neighbouring segments
(and the frames before a full fit inside one) are mended by tracking across
(``Fitter._mend``, ``Fitter._retrack``).
"""

from __future__ import annotations

import copy
import itertools
import math
import os
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import NamedTuple

import numba
import numpy as np

from kinematics import _anneal_kernels as _ak
from kinematics import _cuda_kernels as _ck
from kinematics import _lane_codegen as _codegen
from kinematics import _lane_kernels as _lk
from kinematics import _refine_kernels as _rk
from kinematics import placement, temporal
from kinematics.cameras import CameraArrays
from kinematics.cloud import SUPPORT_PX, cloud_observations, view_groups
from kinematics.error_function import projection_error
from kinematics.errors import KinematicsError
from kinematics.fk import forward_kinematics, forward_kinematics_reference
from kinematics.model import Body
from kinematics.observations import ObservationArrays, Observations, sorted_by_x
from kinematics.problem import (  # noqa: F401 (re-exported: the packing lived here)
    ErrorArgs,
    FitOutputs,
    FitProblem,
    FoldedBody,
    error_args,
    fold_body,
    histogram_tables,
    partitions_of,
    schedule_of,
)
from kinematics.rotations import euler_yxz
from kinematics.settings import START_MODES, AnnealParams, ErrorOptions  # noqa: F401 (re-exported)

STATUSES = ("ok", "reanalysed", "ambiguous", "failed", "no-detections")
#: The start search's draws per joint and kept posture (``start_samples`` None) for a body
#: of several partitions (docs/benchmarks.md, the fly).
DEFAULT_START_SAMPLES = 64
#: ``match = "auto"`` matches a single chain in 3D where its views hold more than this many
#: detections per marker image they show (median over the video's frames): other limbs' or
#: animals' markers, which Eq. 5 lets the chain take in one view and another. One fly leg
#: among six drawn (5.7 detections per marker image): 56 % of frames right per view, 100 %
#: in 3D; the free mouse (1.0): per view keeps a marker absent from every view off its
#: neighbours, 3D does not (docs/benchmarks.md, session 27).
CLUTTER_RATIO = 2.0
#: ... and also where the triangulated points cover its markers in at least this share of the
#: frames (at least as many points as markers): one fly leg alone through 3 / 6 cameras
#: (100 % of its frames covered) 89.4 / 93.9 % of frames right per view, 100 / 100 % in 3D;
#: the free mouse (an ankle absent from the mocap, markers seen by 2 cameras: 82 %) folds its
#: leg onto the points left in 3D.
COVERED_SHARE = 0.95
#: Frames triangulated at most to measure that share.
MATCH_SAMPLE = 256
#: Levenberg-Marquardt steps of the final polish at most (it stops once converged).
POLISH_STEPS = 50


class Candidate(NamedTuple):
    """One distinct posture a frame's runs found (``AnnealParams.candidates`` > 1)."""

    angles_deg: np.ndarray  # (n_axes,)
    root_positions: np.ndarray  # (n_chains, 3)
    error: float
    state: np.ndarray  # (n_state,) the kernels' state (for re-scoring) ...
    seed_pos: np.ndarray  # (n_chains, 3) ... relative to these root seeds
    seed_rot: np.ndarray  # (n_chains, 3, 3)



# -- results ------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class FrameResult:
    """The fit of one frame.

    Attributes
    ----------
    frame : int
        Index of the frame (record) in the detections.
    angles_deg : ndarray, shape (n_axes,)
        Fitted posture, each angle expressed within its axis range where possible; NaN when
        the frame had no detections.
    error : float
        E of the fitted posture (Eq. 5 or the chosen variant), pixels; the confidence value.
    error_per_view : ndarray, shape (n_views,)
        The part of E from each view (NaN without detections; 0 for a view without any).
    runs : int
        Annealing runs made (1 + re-analyses).
    iterations : int
        Annealing iterations over all runs.
    seed : int
        The seed; run r drew from the stream of (seed, frame, r).
    status : str
        ``"ok"`` (E within the threshold at the first run; runs made for candidates or to
        confirm a result, ``confirm_runs``, are no re-analyses), ``"reanalysed"`` (within it
        after re-runs), ``"ambiguous"`` (within it, but another candidate posture far from
        this one, ``ambiguous_deg`` on an axis and ``ambiguous_move`` at a marker, fits about
        as well, or the chosen posture jumps from a neighbour's and no re-fit found one that
        continues the movement: see ``candidates``; or, matching in 3D, a limb has a marker
        that neither a cloud point nor two views place), ``"failed"`` (above it after
        ``max_runs``), ``"no-detections"``.
    root_positions : ndarray, shape (n_chains, 3)
        Root of each chain used for this frame (configured or tracked).
    missing_views : tuple of str
        Views without any detection in this frame (fitted from the others).
    dropped : int
        Detected points dropped because a coordinate was NaN or infinite.
    refined_pairs : int or None
        Marker/detection pairs used by refinement, None when refinement was off.
    marker_residuals : ndarray, shape (n_views, n_markers), or None
        Distance in pixels from each fitted model marker to its nearest detection in each
        view (NaN where the view has no detection): which marker is off.
    matched : int
        Marker images (marker × view) within ``claim_gate_px`` of a detection.
    unexplained : int
        Detections farther than ``claim_gate_px`` from every model marker (ghosts, or
        markers the fit left out).
    worst_px : float
        The largest marker residual (NaN without one).
    candidates : tuple of Candidate
        With ``candidates`` > 1: the frame's distinct postures, lowest E first (this
        result's posture among them); empty otherwise.
    threshold : float
        The re-analysis threshold on E that decided the status: with ``threshold_mode``
        'auto' the one measured on the video, which a front end should show as its bar
        (NaN for results not made by a fit).
    """

    frame: int
    angles_deg: np.ndarray
    error: float
    error_per_view: np.ndarray
    runs: int
    iterations: int
    seed: int
    status: str
    root_positions: np.ndarray
    missing_views: tuple[str, ...] = ()
    dropped: int = 0
    refined_pairs: int | None = None
    marker_residuals: np.ndarray | None = None
    matched: int = 0
    unexplained: int = 0
    worst_px: float = float("nan")
    candidates: tuple = ()
    threshold: float = float("nan")

    @property
    def spread_deg(self) -> np.ndarray:
        """Per axis, how far apart the frame's candidate postures are (largest minus smallest,
        degrees, turns wrapped); zeros with fewer than two candidates. Axes with a spread
        are the ones the frame is unsure about."""
        if len(self.candidates) < 2:
            return np.zeros(np.size(self.angles_deg))
        a = np.array([c.angles_deg for c in self.candidates], float)
        d = (a - a[0] + 180.0) % 360.0 - 180.0  # each relative to the chosen posture
        return d.max(axis=0) - d.min(axis=0)

    @property
    def ok(self) -> bool:
        """True for ``ok`` and ``reanalysed`` frames (E within the threshold)."""
        return self.status in ("ok", "reanalysed")


# -- detections -----------------------------------------------------------------------------
@dataclass(frozen=True)
class _Ragged:
    """Detections of several frames, cleaned: NaN rows dropped, layout as the kernels'."""

    points: np.ndarray  # (n, 2) float64, finite
    offsets: np.ndarray  # (n_frames * n_views + 1,) int64
    dropped: np.ndarray  # (n_frames,) int64 rows dropped per frame
    n_views: int

    @property
    def n_frames(self) -> int:
        return (self.offsets.size - 1) // self.n_views

    def counts(self) -> np.ndarray:
        return np.diff(self.offsets).reshape(self.n_frames, self.n_views)

    def select(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points and frame-major offsets of the given frames only, in that order."""
        nv = self.n_views
        starts = self.offsets[frames * nv]
        stops = self.offsets[frames * nv + nv]
        pts = np.concatenate([self.points[a:b] for a, b in zip(starts, stops, strict=True)]
                             ) if len(frames) else np.empty((0, 2))
        counts = np.diff(self.offsets)[(frames[:, None] * nv + np.arange(nv)).ravel()]
        off = np.zeros(counts.size + 1, np.int64)
        np.cumsum(counts, out=off[1:])
        return np.ascontiguousarray(pts.reshape(-1, 2), dtype=np.float64), off


def _as_ragged(detections, view_names: Sequence[str]) -> _Ragged:
    """Accept a :class:`videotrack.detections.Detections`-like object (``points`` (n, 2),
    ``offsets`` (n_frames * n_views + 1,), optional ``view_names``) or a sequence of frames,
    each a sequence of per-view (n_c, 2) arrays (or an object with such a ``points``)."""
    nv = len(view_names)
    if hasattr(detections, "offsets") and hasattr(detections, "points"):
        names = getattr(detections, "view_names", None)
        if names is not None and list(names) != list(view_names):
            raise KinematicsError(f"detections are for views {list(names)} but the cameras "
                                  f"are {list(view_names)}", field="detections")
        pts = np.asarray(detections.points, dtype=float).reshape(-1, 2)
        off = np.asarray(detections.offsets, dtype=np.int64).ravel()
        if off.size < 1 or (off.size - 1) % nv or off[0] != 0 or off[-1] != len(pts) or np.any(
                np.diff(off) < 0):
            raise KinematicsError(f"offsets must rise from 0 to {len(pts)} in (frames x "
                                  f"{nv} views + 1) entries", field="detections")
    else:
        rows, counts = [], []
        for f, frame in enumerate(detections):
            views = getattr(frame, "points", frame)
            views = list(views)
            if len(views) != nv:
                raise KinematicsError(f"frame {f} has detections for {len(views)} views but "
                                      f"there are {nv} cameras {list(view_names)}",
                                      field="detections")
            for v, det in enumerate(views):
                a = np.asarray(det, dtype=float)
                if a.size and (a.ndim != 2 or a.shape[1] != 2):
                    raise KinematicsError(f"frame {f} view {view_names[v]}: points must have "
                                          f"shape (n, 2), got {a.shape}", field="detections")
                rows.append(a.reshape(-1, 2))
                counts.append(len(rows[-1]))
        pts = np.concatenate(rows) if rows else np.empty((0, 2))
        off = np.zeros(len(counts) + 1, np.int64)
        np.cumsum(counts, out=off[1:])
    good = np.isfinite(pts).all(axis=1)
    n_frames = (off.size - 1) // nv
    if good.all():
        return _Ragged(sorted_by_x(pts, off), off, np.zeros(n_frames, np.int64), nv)
    keep_before = np.concatenate([[0], np.cumsum(good)])
    new_off = keep_before[off].astype(np.int64)
    bad_per_cell = np.diff(off) - np.diff(new_off)
    dropped = bad_per_cell.reshape(n_frames, nv).sum(axis=1)
    return _Ragged(sorted_by_x(pts[good], new_off), new_off, dropped.astype(np.int64), nv)


def unseen_markers(view_markers, view_names: Sequence[str], marker_names: Sequence[str]
                    ) -> np.ndarray | None:
    """(n_views, n_markers) bool: markers a view cannot show, from ``view_markers`` (view
    name -> the marker names it shows; views not named show all); None when every view
    shows every marker."""
    if not view_markers:
        return None
    if not isinstance(view_markers, Mapping):
        raise KinematicsError("view_markers must map view names to marker names",
                              field="view_markers")
    index = {m: k for k, m in enumerate(marker_names)}
    unseen = np.zeros((len(view_names), len(marker_names)), bool)
    for view, shown in view_markers.items():
        if view not in view_names:
            raise KinematicsError(f"no view named {view!r} (views: {', '.join(view_names)})",
                                  field="view_markers")
        if isinstance(shown, str):
            raise KinematicsError(f"view {view!r}: give a list of marker names, not one "
                                  f"string", field="view_markers")
        try:
            shown = [str(m) for m in shown]
        except TypeError:
            raise KinematicsError(f"view {view!r}: give a list of marker names, got "
                                  f"{shown!r}", field="view_markers") from None
        unknown = [m for m in shown if m not in index]
        if unknown:
            raise KinematicsError(f"view {view!r}: {unknown[0]!r} is not a marker of the "
                                  f"body (markers: {', '.join(marker_names)})",
                                  field="view_markers")
        v = view_names.index(view)
        unseen[v] = True
        unseen[v, [index[m] for m in shown]] = False
    return unseen if unseen.any() else None


# -- the fitter -----------------------------------------------------------------------------
class Fitter:
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

    Attributes
    ----------
    problem : FitProblem
        The packed problem every backend uses (:mod:`kinematics.problem`).

    Raises
    ------
    KinematicsError
        The body is invalid, has no markers or no free axis, or there are no cameras.
    """

    def __init__(self, body: Body, cameras, params: AnnealParams | None = None,
                 view_markers: Mapping[str, Sequence[str]] | None = None) -> None:
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

    def with_pins(self, pins) -> Fitter:
        """A fitter that holds the given axes (``joint.axis`` labels or posture indices ->
        degrees) at their values while it fits the rest (:meth:`FitProblem.with_pins`):
        a manual correction re-fitted around what the user set."""
        other = copy.copy(self)
        other.problem = self.problem.with_pins(pins)
        return other

    # -- small helpers --------------------------------------------------------------------
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
            return _ak.NO_HIDDEN
        return np.ascontiguousarray(self.unseen.T, dtype=float)

    def match_for(self, data) -> str:
        """Where these data's markers are matched: 'views' (Eq. 5, each view on its own) or
        '3d' (triangulated first): :meth:`match_why`'s first answer."""
        return self.match_why(data)[0]

    def match_why(self, data) -> tuple[str, str]:
        """Where these data's markers are matched ('views' or '3d') and why, in a few words.

        ``match`` says, or with 'auto' the data. With 3 or more views (of each colour): '3d'
        for a body annealed in several partitions (many limbs); for a single chain, '3d'
        where its views hold more than :data:`CLUTTER_RATIO` detections per marker image
        (other limbs' markers: :meth:`clutter`) or where the triangulated points cover its
        markers in at least :data:`COVERED_SHARE` of the frames (:meth:`covered`), else
        'views'. Labelled keypoints are matched by their labels in the views ('views'); 3D
        points are '3d'. A fit of some frames decides on all the data it is given, so pass
        a video's whole detections (and ``frames``) for its frames to be matched alike; a
        one-frame call (:meth:`fit_frame`, :meth:`error`) decides on that frame, unless
        ``match`` is set (the GUI sets it from the whole video)."""
        if isinstance(data, Observations) and data.kind != "points":
            return ("3d", "3D points") if data.kind in ("cloud", "points3d") else (
                "views", "labelled keypoints")
        p = self.params
        if p.match != "auto":
            return p.match, f"match = {p.match!r}"
        if self._views_3d < 3:
            return "views", "fewer than 3 views to triangulate from"
        if not self.match_measured:
            return "3d", "a body of several limbs"
        obs = data if isinstance(data, Observations) else self._unlabelled(data)
        if obs.hidden is not None:  # marked per view (the GUI's H): kept per view
            return "views", "markers marked hidden in a view"
        clutter = self.clutter(obs)
        if clutter > CLUTTER_RATIO:
            return "3d", (f"{clutter:.1f} detections per marker image, other limbs' markers "
                          f"(above {CLUTTER_RATIO:g})")
        covered = self.covered(obs)
        return ("3d" if covered >= COVERED_SHARE else "views"), (
            f"every marker triangulated in {100 * covered:.0f} % of the frames (3D from "
            f"{100 * COVERED_SHARE:.0f} %)")

    @property
    def match_measured(self) -> bool:
        """Whether :meth:`match_for` decides on the data: ``match`` 'auto' for a single
        chain (one partition) in 3 or more views."""
        p = self.params
        return p.match == "auto" and self._views_3d >= 3 and not self._limbs(p)

    def clutter(self, data) -> float:
        """Unlabelled detections per marker image the views show: the median over the frames
        with any (0 without any); what 'auto' :meth:`match_for` reads for a single chain."""
        obs = data if isinstance(data, Observations) else self._unlabelled(data)
        shown = obs.with_unseen(self.unseen) if self.unseen is not None else obs
        frames = np.arange(obs.n_frames)
        images = marker_images(shown, frames, len(self.body.marker_names))
        found = obs.view_counts(frames).sum(axis=1)
        keep = (images > 0) & (found > 0)
        return float(np.median(found[keep] / images[keep])) if keep.any() else 0.0

    def covered(self, data) -> float:
        """The share of frames with detections whose triangulated points are at least as
        many as the body's markers (:func:`~kinematics.cloud.cloud_observations`; on up to
        :data:`MATCH_SAMPLE` frames spread over the video): where it is low, markers are
        often absent or seen by fewer than 3 views, and matching in 3D lets a limb fold onto
        the points that are there (docs/fitting.md, 'When the defaults match in 3D')."""
        obs = data if isinstance(data, Observations) else self._unlabelled(data)
        seen = np.flatnonzero(obs.view_counts(np.arange(obs.n_frames)).sum(axis=1) > 0)
        if seen.size == 0 or self._views_3d < 3:
            return 0.0
        pick = seen[np.unique(np.linspace(0, seen.size - 1, min(MATCH_SAMPLE, seen.size)
                                          ).astype(int))]
        cloud = cloud_observations(self.cameras, obs.take(pick), self.unseen)
        points = (cloud.points3d[:, :, 3] > 0).sum(axis=1)
        return float(np.mean(points >= len(self.body.marker_names)))

    @property
    def _views_3d(self) -> int:
        """The views a marker can be triangulated from: all, or with ``view_markers`` the
        fewest that show the same markers (one colour's views)."""
        if self.unseen is None:
            return self.n_views
        return min((len(g) for g in view_groups(self.unseen)), default=0)

    def _limbs(self, p: AnnealParams) -> bool:
        """Whether the body is annealed in several partitions (many limbs)."""
        return self._partitions(p, search=False).bounds.shape[0] > 1

    def _partitions(self, p: AnnealParams, search: bool = True, cloud: bool = False):
        """The fit's partitions; the start search as ``start_samples`` says (None: 64 for
        several partitions, none for one) and runs confirmed as ``confirm_runs`` says
        ('auto': for several partitions, or markers matched in 3D, ``cloud``), or neither
        (``search`` False: a re-fit from a neighbour's posture)."""
        parts = self._once(  # the re-fits ask for them hundreds of times per block
            ("partitions", p.partitions, p.partition_rounds, p.claim_gate_px),
            lambda: partitions_of(self.problem, p.partitions, p.partition_rounds,
                                  p.claim_gate_px))
        samples = p.start_samples
        if samples is None:
            samples = DEFAULT_START_SAMPLES if parts.bounds.shape[0] > 1 else 0
        confirm = p.confirm_runs == "on" or (p.confirm_runs == "auto" and (
            parts.bounds.shape[0] > 1 or cloud))
        return parts._replace(samples=int(samples) if search else 0,
                              confirm=float(self._apart(p))
                              if confirm and search else 0.0)

    def observations(self, data) -> Observations:
        """``data`` as :class:`~kinematics.observations.Observations`: an Observations object
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

    def _frame_ragged(self, detections_frame) -> _Ragged:
        return _as_ragged([detections_frame], self.view_names)

    def _unlabelled(self, data) -> Observations:
        """Unlabelled detections in any form :meth:`iter_fit` takes, as Observations."""
        rag = _as_ragged(data, self.view_names)
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

    # -- single evaluations ---------------------------------------------------------------
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
        _ak.project_posture(state, root_pos, root_rot, *f, *self.problem.cams, np.empty(ns),
                            np.empty(ns), np.empty((nj, 3, 3)), np.empty((nj, 3)), mk, proj)
        return (proj, mk) if markers else proj

    def error(self, angles_deg, detections_frame, root_positions=None, hidden=None
              ) -> tuple[float, np.ndarray]:
        """E of a posture for one frame (kernel; e.g. for a manual correction).

        Parameters
        ----------
        angles_deg : array_like, shape (n_axes,)
        detections_frame : sequence of array_like (n_c, 2), one per view, or one record's
            :class:`~kinematics.observations.Observations` (labelled keypoints or 3D points:
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
        e = _ak.posture_error(state, pos, rot, *self.problem.folded, *self.problem.cams,
                              _ak.OBJ_NEAREST, frame.points, np.ones(len(frame.points)),
                              frame.offsets, np.zeros((nm, 4)), *error_args(opts), per_view)
        return float(e), per_view

    # -- root placement -------------------------------------------------------------------
    def track_roots(self, detections, frames=None) -> np.ndarray:
        """Root position of every chain for each frame, shape (n_frames, n_chains, 3).

        Chains with ``root.mode == "marker"`` follow their root marker (Sects. 2.1, 3.3.1):
        frame by frame, in the order of ``frames``, the marker's previous position is
        projected into every view, the nearest detection there is taken as its image (within
        ``params.root_gate_px`` if set, a gate that doubles for every frame the marker is
        lost), and the new 3D position is the least-squares point over the observing views
        (orthographic or pinhole), keeping unobserved directions. The first frame starts
        from the configured root position (the manual offset of the paper) with the root
        marker where the start posture puts it; the root then moves by the tracked marker's
        displacement. Free roots get their per-frame seed position
        (:mod:`kinematics.placement`); fixed chains keep their position.
        """
        obs = self.observations(detections)
        idx = self._frame_indices(frames, obs.n_frames)
        return self._place(obs, idx)[0]

    def _place(self, obs: Observations, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Seed root positions (n, n_chains, 3) and rotations (n, n_chains, 3, 3)."""
        out = np.broadcast_to(self._roots, (len(idx), *self._roots.shape)).copy()
        rot = self.problem.identity_rotations(len(idx))
        if len(idx) == 0 or not (self._tracked or self.problem.free_chains):
            return out, rot
        pts, _, off, _ = obs.select(idx)
        labelled = self._labelled_3d(obs, idx) if obs.labelled else None
        gate = np.inf if self.params.root_gate_px is None else float(self.params.root_gate_px)
        if self._tracked:
            markers0 = forward_kinematics_reference(self.body, self._mean_deg).markers
        for k in self._tracked:
            x0 = np.ascontiguousarray(markers0[self._root_marker[k]], dtype=float)
            if labelled is None:
                track = np.empty((len(idx), 3))
                p_k, off_k = pts, off
                marks = self._marks(obs, idx)
                if marks is not None:  # a view where the root marker is hidden: none
                    p_k, off_k = _emptied(pts, off, marks[:, :, self._root_marker[k]])
                _ak.track_root(p_k, off_k, x0, gate, 1e-9, self.problem.cams, track)
            else:  # a labelled root marker needs no tracking; gaps keep the last position
                track = _carry_forward(labelled[:, self._root_marker[k]], x0)
            out[:, k] = self._roots[k] + (track - x0)
        if self.problem.free_chains:
            if labelled is None:
                nv = self.n_views
                frames = ([pts[off[f * nv + v]: off[f * nv + v + 1]] for v in range(nv)]
                          for f in range(len(idx)))
                tri_gate = placement.DEFAULT_GATE_PX if self.params.root_gate_px is None \
                    else gate
                pos, seed_rot, _ = placement.place_roots(
                    self.body, self.cameras, frames, self.problem.windows, tri_gate,
                    resolve=lambda f, q, poses: self._resolve(obs, idx[f], q, poses))
            else:
                pos, seed_rot, _ = placement.place_roots_from_points(
                    self.body, labelled, self.problem.windows)
            for q, c in enumerate(self.problem.free_chains):
                out[:, c] = pos[:, q]
                rot[:, c] = seed_rot[:, q]
        return out, rot

    def _resolve(self, obs: Observations, frame: int, q: int, poses: list) -> int:
        """Which of several equally good seed poses of free root ``q`` to take in ``frame``:
        the whole body is fitted from each, the lowest E wins (a mirror-symmetric root
        constellation cannot tell left from right; the limbs can)."""
        c = self.problem.free_chains[q]
        one = np.array([frame], np.int64)
        errors = []
        for r, t, *_ in poses:
            roots = self._roots[None].copy()
            rots = self.problem.identity_rotations(1)
            roots[0, c], rots[0, c] = t, r
            res = self._fit_block(obs, one, one, roots, rots, self.problem.start,
                                  np.array([0, 1], np.int64))[0]
            errors.append(res.error)
        return int(np.argmin(errors))

    def _labelled_3d(self, obs: Observations, idx: np.ndarray) -> np.ndarray:
        """3D positions of the labelled markers, (n, n_markers, 3), NaN where unknown:
        the 3D points themselves, or keypoints triangulated over their views."""
        if obs.kind == "points3d":
            p = obs.points3d[idx, :, :3].copy()
            p[obs.points3d[idx, :, 3] <= 0] = np.nan
            return p
        nm = len(self.body.marker_names)
        out = np.empty((len(idx), nm, 3))
        nv = obs.n_views
        for k, f in enumerate(idx):
            rows = [slice(obs.offsets[f * nv + v], obs.offsets[f * nv + v + 1])
                    for v in range(nv)]
            out[k] = placement.triangulate_labelled(
                self.cameras, [obs.points[r] for r in rows], [obs.conf[r] for r in rows], nm)
        return out

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

    # -- fitting --------------------------------------------------------------------------
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
        return _held(*self._polished(obs, 0, self._fit_block(
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
        return _held(*self._polished(obs, 0, self._frame_result(
            obs, 0, int(frame), found.state, found.seed_pos, found.seed_rot, self.params,
            runs=1, iterations=counted[0], pairs=0, error=None, candidates=(found,))),
            self._apart(self.params))

    def iter_fit(self, detections, frames=None, *, chunk_size: int | None = None,
                 sequence_starts: Iterable[int] = (),
                 previous: FrameResult | Sequence[FrameResult] | None = None,
                 cancel: Callable[[], bool] | None = None) -> Iterator[FrameResult]:
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
            :data:`CUT_CONTEXT` are used, the last one is where the path continues from). The
            path decides frames in windows of 2 x :data:`PATH_LAG` frames that start every
            PATH_LAG frames, so a fit resumed at a multiple of PATH_LAG, with the results
            before it, chooses as the whole would (with the final polish,
            ``final_polish_px``, it continues from the polished postures, where the whole
            continued from the fitted ones: a choice between candidates that nearly tie can
            differ at the seam).
        cancel : callable, optional
            Asked before each batch; once it returns True no further batch is fitted and
            the frames fitted so far are yielded (the path through time holds back up to 64
            of them and the misplaced-marker flag 32 more, so closing the generator alone
            can wait that long).

        Raises
        ------
        KinematicsError
            Detections whose views do not match the cameras, bad frame numbers.
        """
        obs = self.observations(detections)
        idx = self._frame_indices(frames, obs.n_frames)
        starts = np.asarray(list(sequence_starts), np.int64)
        before = ([] if previous is None else [previous] if isinstance(previous, FrameResult)
                  else list(previous))
        out = self._final_polish(obs, idx, self._iter(obs, idx, chunk_size, starts, before,
                                                      cancel))
        p = self.params
        if p.candidates > 1 and p.start != "track":  # the frames to look at, after the polish
            out = flag_misplaced(out, p.claim_gate_px, before=before, starts=starts)
        return out

    def _iter(self, obs: Observations, idx: np.ndarray, chunk_size: int | None,
              starts: np.ndarray | None = None, before: Sequence[FrameResult] = (),
              cancel: Callable[[], bool] | None = None) -> Iterator[FrameResult]:
        starts = np.zeros(0, np.int64) if starts is None else starts
        roots, rots = self._place(obs, idx)
        params = self.params
        if params.start == "track":  # measures its threshold on its first tracked frames
            yield from self._track(obs, idx, roots, rots, params, cancel)
            return
        if params.threshold_mode == "auto" and len(idx):
            params = replace(params, reanalysis_threshold=self._video_threshold(
                obs, idx, roots, rots))
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

    def _final_polish(self, obs: Observations, idx, results: Iterable[FrameResult]
                      ) -> Iterator[FrameResult]:
        """``results`` (one per frame of ``idx``, in order) as :meth:`_polished` leaves
        them, a frame with a held limb ``ambiguous`` where its runs put that limb apart or
        the next frame's runs do (:func:`_held`): a wrong stretch that every run fits alike
        (a fly's hind leg through 6 cameras, frames 357-360) ends where they part. The next
        frame only, so a fit resumed from a checkpoint decides every frame as the whole fit
        did."""
        apart = self._apart(self.params)
        pending = None
        for position, r in zip(idx, results, strict=False):  # a cancelled fit yields fewer
            r, spread = self._polished(obs, int(position), r)
            if pending is not None:
                follows = r.frame == pending[0].frame + 1
                yield _held(*pending, apart, spread if follows else None)
            pending = r, spread
        if pending is not None:
            yield _held(*pending, apart)

    def _apart(self, p: AnnealParams) -> float:
        """How far (model units) a model marker must lie from where another posture puts it
        for the two to differ: ``ambiguous_move`` segment lengths. So it is for candidates
        (ambiguous), confirming runs, a held limb's runs, and a re-track meeting the results."""
        return p.ambiguous_move * self._segment_scale

    def _polished(self, obs: Observations, position: int, r: FrameResult
                  ) -> tuple[FrameResult, float | None]:
        """The chosen posture of frame ``position`` fitted by least squares to its cloud
        points within ``final_polish_px``, each point paired with one marker at most
        (Levenberg-Marquardt, the refinement's kernel), and kept though its E grows a
        little: annealing minimises a sum of distances, which puts the misfit of a limb the
        rigid chain cannot fit on one joint; least squares spreads it. A marker without a
        point (its blob fused with a neighbour's in a view, so too few views triangulate
        it) is paired with its detections in the views instead (``OBJ_CLOUD_VIEWS``) where
        :func:`_placed` finds two, and its limb is held if the polished marker is not
        explained (within ``cap_px``) in two views. Only the partitions whose own markers
        are all paired or placed move: a limb missing one would be pulled by the others
        alone. Returns the result and how far apart the frame's runs put the held limbs'
        markers (None: no limb held; :func:`_held` flags the frame). Matching in 3D only;
        the status is otherwise the one decided on the fit, and a posture whose E the polish
        would take above the threshold stays as fitted."""
        p = self.params
        if p.final_polish_px is None or obs.kind != "cloud" or not r.runs:
            return r, None
        pr = self.problem
        arrays = obs.arrays(np.array([position], np.int64))  # with the views' detections
        state, pos, rot = self.state(r.angles_deg, r.root_positions)
        cloud = np.ascontiguousarray(arrays.points3d[0])
        proj, mk = self._project_state(state, pos, rot, markers=True)
        gate = float(p.final_polish_px)
        pair = np.empty(len(mk), np.int64)
        _rk.assign_pairs(_ak.OBJ_CLOUD_ONE, np.empty((0, len(mk), 2)), mk, arrays.points,
                         arrays.conf, arrays.offsets, cloud, gate, pair)
        covered = pair >= 0
        # E's distance beyond which a marker is unexplained (no cap: the gate)
        explained = p.error.cap_px or gate
        own = np.zeros(len(arrays.points), bool)
        if not covered.all() and self.unseen is None:  # (views of one colour: the cloud alone)
            own = _unclaimed(self.cameras, cloud, arrays.points, arrays.offsets)
            covered |= _placed(proj, arrays.points, arrays.offsets, own, gate, explained)
        # the kernel's gate of each detection for a marker without a point (in the views)
        gates = np.where(own, gate, explained)
        parts, start = self._partitions(p, search=False), state
        while True:  # the views must agree where they placed a marker, else its limb is held
            moved, folded, marks = _covered_partitions(parts, pr.folded, covered)
            if moved.size == 0:
                break
            state = start.copy()
            placed = marks[pair[marks] < 0]
            if placed.size == 0:  # the cloud alone: no view's projections to compute
                objective, cams = _ak.OBJ_CLOUD_ONE, self._kernel_inputs(arrays)[0]
            else:
                objective, cams = _ak.OBJ_CLOUD_VIEWS, pr.cams
            _rk.refine_posture(state, moved, pr.lo, pr.hi, pr.dof_kind, POLISH_STEPS, gate,
                               pos, rot, *folded, *cams, objective, arrays.points, gates,
                               arrays.offsets, cloud)
            if placed.size == 0:
                break
            ok = _placed(self._project_state(state, pos, rot)[:, placed], arrays.points,
                         arrays.offsets, own, explained, explained)
            if ok.all():
                break
            covered[placed[~ok]] = False
        held = [np.arange(m0, m_own) for _, _, m0, _, m_own in parts.bounds
                if not covered[m0:m_own].all()]
        spread = None  # how far apart the frame's runs put the held limbs' markers
        if held:
            spread = np.inf
            if len(r.candidates) > 1:
                spread = float(self._marker_moves(r.candidates[0], r.candidates[1:],
                                                  np.concatenate(held)).max())
        if moved.size == 0:
            return r, spread
        new = self._frame_result(obs, position, r.frame, state, pos, rot, p, runs=r.runs,
                                 iterations=r.iterations, pairs=r.refined_pairs or 0,
                                 arrays=arrays)
        if r.error <= r.threshold < new.error:  # E grows a little: never across the threshold
            return r, spread
        # the chosen candidate is the polished posture too (cycling back to it in the GUI)
        cands = tuple(Candidate(new.angles_deg, new.root_positions, new.error, state, pos, rot)
                      if np.array_equal(c.angles_deg, r.angles_deg)
                      and np.array_equal(c.root_positions, r.root_positions) else c
                      for c in r.candidates)
        return replace(r, candidates=cands, **{k: getattr(new, k) for k in (
            "angles_deg", "root_positions", "error", "error_per_view", "marker_residuals",
            "matched", "unexplained", "worst_px")}), spread

    def _video_threshold(self, obs: Observations, idx, roots, rots) -> float:
        """The re-analysis threshold on E measured on the video itself (threshold_mode
        'auto'): a sample of frames is fitted once, and the threshold per marker image is
        median + auto_k · 1.4826 · MAD of their E per marker image (the 10-90 % range /
        2.563 where the MAD collapses below 1 % of the median), at least auto_floor_px;
        times the marker images of a frame seen in every view (a cloud's or 3D points': one
        per marker)."""
        p = self.params
        pick = np.unique(np.linspace(0, len(idx) - 1, min(p.auto_sample, len(idx))).astype(int))
        once = replace(p, max_runs=1, candidates=1, threshold_mode="absolute")
        res = self._fit_block(obs, idx[pick], idx[pick], np.ascontiguousarray(roots[pick]),
                              np.ascontiguousarray(rots[pick]), self.problem.start,
                              np.arange(len(pick) + 1, dtype=np.int64), once)
        return self._threshold_of(obs, idx[pick], [r.error for r in res])

    def _threshold_of(self, obs: Observations, frames, errors) -> float:
        """:meth:`_video_threshold`'s threshold from the E of these frames' fits."""
        p = self.params
        images = marker_images(obs, np.asarray(frames), len(self.body.marker_names))
        score = np.asarray(errors, float) / np.maximum(images, 1)
        score = score[np.isfinite(score) & (images > 0)]
        if score.size == 0:
            return float(p.reanalysis_threshold)
        per_image = auto_threshold(score, p.auto_k, p.auto_floor_px)
        if obs.kind in ("cloud", "points3d"):
            return per_image * len(self.body.marker_names)
        if self.unseen is not None:  # the marker images a frame has at most
            return per_image * int((~self.unseen).sum())
        return per_image * len(self.body.marker_names) * max(obs.n_views, 1)

    def fit(self, detections, frames=None, **kwargs) -> list[FrameResult]:
        """All results of :meth:`iter_fit` as a list."""
        return list(self.iter_fit(detections, frames, **kwargs))

    def _fit_block(self, obs: Observations, sel, frame_ids, roots, rots, start, seg_off,
                   params: AnnealParams | None = None) -> list[FrameResult]:
        """Fit frames ``sel`` of ``obs`` (``frame_ids`` key their random streams)."""
        p, pr = params or self.params, self.problem
        block = obs.arrays(sel)
        cams, arrays = self._kernel_inputs(block)
        n, ns, nv = len(frame_ids), pr.n_state, len(cams.kind)
        out = FitOutputs.empty(n, ns, nv, max(p.max_runs, p.candidates))
        parts = self._partitions(p, cloud=obs.kind == "cloud")
        backend = self._backend(p, arrays.objective, parts, n,
                                hidden=obs.hidden is not None or obs.unseen is not None)
        if backend == "cuda":
            try:
                _ck.fit_frames_rounds(frame_ids, roots, rots, start, pr.folded, pr.cams,
                                      pr.dofs, schedule_of(p),
                                      self._error_args(p, arrays.objective), arrays,
                                      float(p.claim_gate_px), out)
            except _ck.GpuFailed as exc:
                raise KinematicsError(f"the cuda backend failed: {exc}; use backend 'auto'",
                                      field="backend") from exc
        elif backend == "lanes":
            threads = numba.get_num_threads()
            groups = np.unique(np.linspace(0, n, min(threads, n) + 1).astype(np.int64))
            error = self._error_args(p, arrays.objective)
            # labelled keypoints and 3D points have no float32 kernel: theirs stays float64
            single = p.precision == "float32" and arrays.objective == _ak.OBJ_NEAREST
            fused, n_fused = self._fused_kernel(arrays, error, single)
            _lk.fit_frames_lanes(groups, frame_ids, roots, rots, start, pr.folded, pr.cams,
                                 pr.dofs, schedule_of(p), error, arrays,
                                 float(p.claim_gate_px), _lk.LANES, fused, n_fused, single, out)
        else:
            _ak.fit_frames(seg_off, frame_ids, roots, rots, start, pr.folded, cams,
                           pr.dofs, schedule_of(p), self._error_args(p, arrays.objective),
                           arrays, parts, out)
        view_error = out.view_error if nv == self.n_views else np.zeros((n, self.n_views))
        batch = self._block_residuals(obs, block, out, roots, rots, float(p.claim_gate_px))
        results = []
        for k in range(n):
            cands = ()
            if p.candidates > 1 and out.runs[k]:
                cands = self._candidates(out.run_angles[k], out.run_error[k], roots[k],
                                         rots[k], p)
            results.append(self._frame_result(
                obs, int(sel[k]), int(frame_ids[k]), out.angles[k], roots[k], rots[k], p,
                arrays=block.frame(k, obs.n_views),
                runs=int(out.runs[k]), iterations=int(out.iterations[k]),
                pairs=int(out.pairs[k]), error=(float(out.error[k]), view_error[k].copy()),
                candidates=cands, given_residuals=None if batch is None else (
                    batch[0][k], int(batch[1][k])),
                confirmed_only=parts.confirm > 0 and bool(
                    np.nanmin(out.run_error[k, :max(1, p.candidates)], initial=np.inf)
                    <= p.reanalysis_threshold)))
        return results

    def _block_residuals(self, obs: Observations, block: ObservationArrays, out, roots, rots,
                         gate: float):
        """(marker residuals (n, n_views, n_markers), unexplained (n,)) of a block's fitted
        frames, as :meth:`_residuals` gives them frame by frame, in one kernel call; None
        where its per-frame rules apply (keypoints, 3D points, clouds, no views, hidden
        markers, views that show only some markers)."""
        if (obs.kind != "points" or not obs.n_views or obs.hidden is not None
                or obs.unseen is not None or self.unseen is not None):
            return None
        n, pr = len(out.runs), self.problem
        res = np.full((n, self.n_views, pr.folded.marker_joint.size), np.nan)
        unexplained = np.zeros(n, np.int64)
        _ak.block_residuals(out.angles, out.runs > 0, roots, rots, pr.folded, pr.cams,
                            block.points, block.offsets, gate, res, unexplained)
        return res, unexplained

    def _kernel_inputs(self, arrays: ObservationArrays):
        """Cameras and observations as ``fit_frames`` takes them: for a 3D objective (a
        cloud) without the views, whose projections such a fit never reads (they were most
        of an iteration's cost with six pinhole cameras)."""
        if arrays.objective != _ak.OBJ_CLOUD:
            return self.problem.cams, arrays
        cams = CameraArrays(*(np.ascontiguousarray(a[:0]) for a in self.problem.cams))
        return cams, arrays._replace(points=np.empty((0, 2)), conf=np.empty(0),
                                     offsets=np.zeros(1, np.int64))

    def _fused_kernel(self, arrays: ObservationArrays, error: ErrorArgs,
                      single: bool = False):
        """The lane kernel generated for this body, its views and the block's detections
        per view (:mod:`kinematics._lane_codegen`) and the detections it scans; the general
        loops (``no_fused``, 0) where none is made: for a body too large or a view of the
        block with too many detections, with ``VIDEOTRACK_NO_CODEGEN`` set, or where the
        kernel cannot be made (a read-only cache folder: a warning, the same results).
        ``single``: a kernel computing in float32 (precision 'float32'; unlabelled points
        only, as :meth:`_fit_block` asks)."""
        # labelled keypoints and 3D points: point i is marker i's, no scan
        labelled = arrays.objective == _ak.OBJ_LABELLED
        points3d = arrays.objective == _ak.OBJ_POINTS3D
        counts = np.diff(arrays.offsets)
        c_cap = 0 if labelled or points3d else int(counts.max()) if counts.size else 0
        if (arrays.objective not in (_ak.OBJ_NEAREST, _ak.OBJ_LABELLED, _ak.OBJ_POINTS3D)
                or os.environ.get("VIDEOTRACK_NO_CODEGEN")
                or not _codegen.fits(self.problem.folded, self.problem.cams, c_cap,
                                     points3d)):
            return _lk.no_fused, 0
        try:
            fn = _codegen.fused_kernel(self.problem.folded, self.problem.cams, c_cap,
                                       (error.bidirectional, error.weight, error.cap,
                                        error.penalty_cap),
                                       single=single, labelled=labelled,
                                       points3d=points3d)
        except Exception as exc:  # any failure: the general loops give the same results
            warnings.warn(f"lanes: no kernel generated for this body ({exc}); using the "
                          "general loops (the same results, slower)", stacklevel=2)
            return _lk.no_fused, 0
        return fn, _codegen.padded_detections(c_cap)

    def lane_frames(self) -> int:
        """Frames whose runs fill the lanes of every numba thread once, or with backend
        'cuda' half a GPU launch (:data:`kinematics._cuda_kernels.GPU_RUNS`); ``iter_fit``
        fits blocks of twice this, the pipeline hands the fitting thread four times."""
        runs = _ck.GPU_RUNS if self.params.backend == "cuda" else (
            _lk.LANES * numba.get_num_threads())
        return -(-runs // max(1, self.params.candidates))

    @staticmethod
    def _backend(p: AnnealParams, objective: int, parts, n_frames: int, *,
                 hidden: bool = False) -> str:
        """Which kernel fits this block: 'lanes' or 'cuda' where they do what the scalar
        kernel does — unlabelled points, labelled 2D keypoints or 3D points, one partition
        and independent frames, without markers marked hidden (``hidden``) — else 'scalar'.
        'auto' also wants a few runs per thread for the lanes
        (:data:`kinematics._lane_kernels.MIN_RUNS_PER_THREAD`: a single frame, as the GUI
        fits, goes to the scalar kernel), and never takes the GPU: its results equal the
        scalar kernel's to within rounding only, and a result file should not depend on
        the machine (docs/fitting.md, 'Reproducibility')."""
        valid = (objective in (_ak.OBJ_NEAREST, _ak.OBJ_LABELLED, _ak.OBJ_POINTS3D)
                 and parts.bounds.shape[0] == 1
                 and parts.samples == 0 and p.start == "mean" and not p.error.one_to_one
                 and parts.confirm == 0 and not hidden)
        if p.backend in ("lanes", "cuda") and not valid:
            raise KinematicsError(f"the {p.backend} backend fits unlabelled points, labelled "
                                  "2D keypoints or 3D points with one partition, start "
                                  "'mean', no start samples and no hidden markers (nor "
                                  "views that show only some: [[views]] model_markers); use "
                                  "backend 'auto' or 'scalar'",
                                  field="backend")
        if p.backend == "cuda":
            if not _ck.available():
                raise KinematicsError("the cuda backend needs an NVIDIA GPU that numba can "
                                      "use (numba.cuda.is_available() is False here; pip "
                                      "install \"videotrack[gpu]\"); use backend 'auto'",
                                      field="backend")
            return "cuda"
        runs = n_frames * max(1, p.candidates)
        lanes = p.backend == "lanes" or (p.backend == "auto" and valid
                                         and runs >= _lk.MIN_RUNS_PER_THREAD
                                         * numba.get_num_threads())
        return "lanes" if lanes else "scalar"

    def _frame_result(self, obs: Observations, position: int, frame_id: int, state, root_pos,
                      root_rot, p: AnnealParams, *, runs: int, iterations: int, pairs: int,
                      error=None, candidates=(), ambiguous: bool = False,
                      confirmed_only: bool = False, arrays=None,
                      given_residuals=None) -> FrameResult:
        """The :class:`FrameResult` of ``state`` fitted to frame ``position`` of ``obs``;
        ``error`` (E, E per view) is computed unless given. ``confirmed_only``: the runs
        beyond the candidates' only confirmed a result already within the threshold (not a
        re-analysis). ``arrays``: that frame's observation arrays, if the caller has them
        (selecting them again was a tenth of a short fit's time); ``given_residuals``: (marker
        residuals, unexplained) of :meth:`_residuals`, if the caller has them
        (:meth:`_block_residuals`)."""
        pr, nv = self.problem, self.n_views
        if arrays is None:
            arrays = obs.arrays(np.array([position], np.int64))
        counts = arrays.offsets[1:] - arrays.offsets[:-1]  # (np.diff: 4 µs a frame)
        missing = tuple(self.view_names[v] for v in range(len(counts)) if counts[v] == 0)
        angles, fitted_roots = pr.posture(state, root_pos, root_rot)
        residuals = np.full((nv, pr.folded.marker_joint.size), np.nan)
        unexplained = 0
        if runs:
            residuals, unexplained = (given_residuals if given_residuals is not None else
                                      self._residuals(obs, state, root_pos, root_rot, arrays,
                                                      p.claim_gate_px))
            if error is None:
                error = self._state_error(arrays, state, root_pos, root_rot, p)
        err, view_err = error if error is not None else (np.nan, np.full(nv, np.nan))
        too_many = (p.max_unexplained is not None and obs.kind in ("points", "cloud")
                    and unexplained > p.max_unexplained)
        if runs == 0:
            status = "no-detections"
        elif err > p.reanalysis_threshold or too_many:
            status = "failed"
        elif ambiguous:
            status = "ambiguous"
        else:  # the runs made for candidates, or to confirm a result, are not re-analyses
            status = "ok" if runs <= p.candidates or confirmed_only else "reanalysed"
        return FrameResult(
            frame=frame_id,
            angles_deg=self._to_range_deg(angles),
            error=float(err),
            error_per_view=np.asarray(view_err, float).copy(),
            runs=runs,
            iterations=iterations,
            seed=p.seed,
            status=status,
            root_positions=(fitted_roots if runs else np.array(root_pos, float, copy=True)),
            missing_views=missing,
            dropped=int(obs.dropped[position]),
            refined_pairs=pairs if p.refine else None,
            marker_residuals=residuals,
            matched=int((residuals <= p.claim_gate_px).sum()),
            unexplained=int(unexplained),
            worst_px=float(np.fmax.reduce(residuals, axis=None, initial=np.nan)),  # NaN: none
            candidates=candidates,
            threshold=float(p.reanalysis_threshold),
        )

    def _state_error(self, arrays, state, root_pos, root_rot, p: AnnealParams):
        """(E, E per view) of a kernel state for one frame's observation arrays."""
        per_view = np.empty(self.n_views)
        obs3 = (arrays.points3d[0] if arrays.points3d.shape[1]
                else np.zeros((self.problem.folded.marker_joint.size, 4)))
        e = _ak.posture_error(np.ascontiguousarray(state), root_pos, root_rot,
                              *self.problem.folded, *self.problem.cams, arrays.objective,
                              arrays.points, arrays.conf, arrays.offsets, obs3,
                              *self._error_args(p, arrays.objective), per_view)
        return float(e), per_view

    def _error_args(self, p: AnnealParams, objective: int) -> ErrorArgs:
        """The error function's numbers for the kernels. Matching in 3D a marker counts once,
        not once per view, so its caps are the views' together: with the per-view 10-px cap
        a cloud point 0.1 mm away at 100 px/mm already cost the most, and a far limb had no
        slope to follow (the fly with the defaults: 3 % of frames right, 45 % with this)."""
        args = error_args(p.error)
        if objective == _ak.OBJ_CLOUD:
            views = self.n_views if self.unseen is None else int(
                (~self.unseen).sum(axis=0).max())  # the views that show a marker
            return args._replace(cap=args.cap * views, penalty_cap=args.penalty_cap * views)
        return args

    # -- candidates and the path through time ----------------------------------------------
    def _candidates(self, run_states, run_errors, root_pos, root_rot, p: AnnealParams
                    ) -> tuple[Candidate, ...]:
        """The distinct postures among one frame's runs, lowest E first."""
        made = np.flatnonzero(np.isfinite(run_errors))
        found = []
        for r in made:
            angles, fitted = self.problem.posture(run_states[r], root_pos, root_rot)
            found.append(Candidate(self._to_range_deg(angles), fitted, float(run_errors[r]),
                                   run_states[r].copy(), np.array(root_pos, copy=True),
                                   np.array(root_rot, copy=True)))
        return self._distinct(found, p)

    def _distinct(self, found: Sequence[Candidate], p: AnnealParams) -> tuple[Candidate, ...]:
        if not found:
            return ()
        vectors = np.array([self._posture_vector(c) for c in found])
        tol = np.full(vectors.shape[1], p.ambiguous_deg)
        keep = temporal.distinct(vectors, [c.error for c in found], tol,
                                 self._n_wrapped, p.candidates)
        return tuple(found[i] for i in keep)

    @property
    def _n_wrapped(self) -> int:
        """Leading entries of a posture vector that are angles (compared modulo 360)."""
        return self.problem.n_axes - 3 * len(self.problem.free_chains)

    def _once(self, key: tuple, make):
        """``make()``, computed once per problem and ``key`` (a copy made by
        :meth:`with_pins` shares the store but not the problem)."""
        key = (self.problem, *key)
        if key not in self._per_problem:
            self._per_problem[key] = make()
        return self._per_problem[key]

    def _joint_axes(self) -> np.ndarray:
        """Posture indices of the angles that are not free-root rotations."""
        def make():
            root = set(self.problem.root_axes.ravel().tolist())
            return np.array([i for i in range(self.problem.n_axes) if i not in root], np.int64)
        return self._once(("joint axes",), make)

    def _posture_vector(self, c) -> np.ndarray:
        """A candidate's (or result's) posture as one flat vector for comparisons: joint
        angles (degrees), then each free root's rotation matrix (x 180/π, so a small turn by
        1° moves it by about 1: Euler triplets that name the same rotation compare equal),
        then root positions."""
        a = np.asarray(c.angles_deg, float)
        rots = [np.rad2deg(euler_yxz(*np.deg2rad(a[ix]))).ravel()
                for ix in self.problem.root_axes]
        return np.concatenate([a[self._joint_axes()], *rots,
                               np.ravel(np.asarray(c.root_positions, float))])

    def _posture_scale(self) -> np.ndarray:
        """Per posture entry, the size of a change that costs 1 on the path: each axis's
        histogram spread s(H) (at least 1°), each root coordinate a quarter of the body's
        longest segment."""
        spread = np.array([max(h.std_deg(), 1.0) for h in self.body.histograms()])
        length = max((abs(float(seg.length))
                      for _, seg in self.body.segments()), default=1.0) or 1.0
        # a free root's rotation: 30° (about a uniform histogram's spread over 100°) per unit
        turn = np.full(9 * len(self.problem.free_chains), 30.0)
        return np.r_[spread[self._joint_axes()], turn,
                     np.full(3 * self.problem.n_chains, length / 4.0)]

    def _over_time(self, obs: Observations, idx, roots, rots, chunks, starts,
                   before: Sequence[FrameResult], p: AnnealParams) -> Iterator[FrameResult]:
        """Choose one candidate per frame by the path through time (fixed-lag: a frame is
        decided once :data:`PATH_LAG` later frames are fitted), re-fit implausible frames from
        their neighbours' postures, and flag ambiguous ones; ``before``: the results decided
        just before ``idx`` (a resumed fit's)."""
        lag = PATH_LAG
        scale = self._posture_scale()
        images = marker_images(obs, idx, len(self.body.marker_names))
        pending: list[FrameResult] = []
        # the last frames decided: the left anchor, and context for finding cuts
        history = list(before)[-CUT_CONTEXT:]
        done = 0  # frames of idx already yielded
        for chunk in chunks:
            pending.extend(chunk)
            while len(pending) > 2 * lag:
                # a window of fixed length, so the choice does not depend on the chunk size
                decided = self._decide(obs, idx, roots, rots, pending[:2 * lag], done, images,
                                       scale, history, starts, p)
                out, pending = decided[:lag], pending[lag:]
                done += lag
                history = (history + out)[-CUT_CONTEXT:]
                yield from out
        if pending:
            yield from self._decide(obs, idx, roots, rots, pending, done, images, scale,
                                    history, starts, p)

    def _decide(self, obs, idx, roots, rots, window: list, first: int, images, scale,
                history: list[FrameResult], starts, p: AnnealParams) -> list[FrameResult]:
        """The window's results with the path's choice applied (module :mod:`temporal`);
        ``history`` holds the results chosen just before the window, the last one its left
        anchor."""
        n_angles = self._n_wrapped
        window = list(window)
        # decided frames right before the window, consecutive up to its first frame
        context: list[FrameResult] = []
        for r in reversed(history):
            if r.frame != (context[0].frame if context else window[0].frame) - 1 or not (
                    r.runs or r.candidates):
                break
            context.insert(0, r)
        previous = context[-1] if context else None
        anchor = None
        if previous is not None:
            anchor = self._posture_vector(previous)
            # the anchor as a seed for re-fitting the window's first frame
            previous = Candidate(previous.angles_deg, previous.root_positions,
                                 previous.error, None, None, None)

        def path():
            k = max((len(r.candidates) for r in window), default=0)
            if k == 0:  # no frame of the window had observations
                return (np.full(len(window), -1), np.zeros((len(window), 0)),
                        np.zeros((len(window), 0, len(scale))))
            unary = np.full((len(window), k), np.inf)
            post = np.zeros((len(window), k, len(scale)))
            for i, r in enumerate(window):
                if r.candidates:
                    e = np.array([c.error for c in r.candidates])
                    unary[i, : len(e)] = (e - e.min()) / max(images[first + i], 1)
                    post[i, : len(e)] = [self._posture_vector(c) for c in r.candidates]
            choice = temporal.choose_path(unary, post, scale, n_angles, p.path_weight,
                                          breaks, anchor)
            return choice, unary, post

        frames = np.array([r.frame for r in window])
        given = np.r_[False, np.diff(frames) != 1] | np.isin(frames, starts)

        def cut() -> np.ndarray:
            """The given breaks and the cuts in the movement, found from every candidate of
            the window and the decided context."""
            k = max((len(r.candidates) for r in window), default=0)
            cands = np.full((len(context) + len(window), max(k, 1), len(scale)), np.nan)
            for i, r in enumerate(context):
                cands[i, 0] = self._posture_vector(r)
            for i, r in enumerate(window, len(context)):
                for j, c in enumerate(r.candidates):
                    cands[i, j] = self._posture_vector(c)
            return given | temporal.cuts(cands, scale, n_angles, before=len(context))

        breaks = cut()
        choice, unary, post = path()
        # Re-analysis seeded by neighbours: a frame where the chosen path jumps (to or from
        # it) is fitted again, cold and locally, from every candidate of both neighbours;
        # two rounds, so a run of a few wrong frames is entered from both ends. The absolute
        # cap is per partition: limbs move, and a fit's axes vary, independently (a fly's
        # six legs at 330 Hz change by ~10 squared spreads per frame, every frame).
        n_parts = self._partitions(p, search=False).bounds.shape[0]

        def jumps_over(cap: float, markers: np.ndarray | None = None,
                       seen_ratio: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
            """Where the chosen path jumps into frame i, (n,) bool: larger than
            REDO_JUMP_RATIO times the window's typical change (at least REDO_JUMP_MIN, at most
            ``cap``); with ``markers`` (:func:`path_markers`), only where some marker moves
            more than ``seen_ratio`` times the window's typical largest marker move. Second,
            the same with at most EDGE_SEEN_RATIO for that ratio."""
            jumps = np.full(len(window), np.nan)
            if anchor is not None and choice[0] >= 0 and not breaks[0]:
                jumps[0] = temporal.transition_costs(anchor[None], post[0, choice[0]][None],
                                                     scale, n_angles)[0, 0]
            if len(window) > 1 and post.shape[1]:  # every step of the path at once
                chosen = post[np.arange(len(window)), np.maximum(choice, 0)][:, None]
                steps = temporal.transition_costs(chosen[:-1], chosen[1:], scale,
                                                  n_angles)[:, 0, 0]
                made = (choice[1:] >= 0) & (choice[:-1] >= 0) & ~breaks[1:]
                jumps[1:] = np.where(made, steps, np.nan)
            typical = np.nanmedian(jumps) if np.isfinite(jumps).any() else 0.0
            limit = min(cap, max(REDO_JUMP_MIN, REDO_JUMP_RATIO * typical))
            big = jumps > limit
            edge = big.copy()
            if markers is not None:  # ... that the markers show
                moves = np.linalg.norm(markers[1:] - markers[:-1], axis=-1).max(axis=-1)
                moves[breaks] = np.nan  # no move across a cut
                seen = np.nanmedian(moves) if np.isfinite(moves).any() else 0.0
                with np.errstate(invalid="ignore"):
                    big &= ~(moves <= seen_ratio * seen)
                    edge &= ~(moves <= min(seen_ratio, EDGE_SEEN_RATIO) * seen)
            return big, edge

        def jumping() -> set[int]:
            """Frames next to a jump of the chosen path (:func:`jumps_over` within
            REDO_JUMP per partition): re-fitted."""
            at = np.flatnonzero(jumps_over(REDO_JUMP * n_parts)[0])
            return {int(k) for i in at for k in (i - 1, i) if k >= 0}

        def still_jumping(markers: np.ndarray) -> tuple[set[int], set[int]]:
            """Frames next to a jump the re-fits left that the markers show, or, where two
            jumps at most ``temporal.WRONG_STRETCH`` apart (or a jump and a sequence's start
            or end) bound a stretch, the stretch's frames instead: those to flag, and the
            frame just outside each such bound (which a kink there must not flag)."""
            big, edge = jumps_over(np.inf, markers, JUMP_SEEN_RATIO)
            at = [int(i) for i in np.flatnonzero(big)]
            # a short stretch between two jumps is what is suspect, not the frames around it
            out, bounds = set(), set()
            for a, b in itertools.pairwise(at):
                if b - a <= temporal.WRONG_STRETCH and not breaks[a + 1:b].any():
                    out.update(range(a, b))
                    bounds |= {a, b}
            # ... and so is a short stretch between a jump and where the movement starts (a
            # cut, or the window's first frame with nothing decided before it) or ends (a
            # cut): the first frames of a sequence, fitted wrong in the same way while a
            # marker is occluded, jump only where they end (a jump the markers show less,
            # EDGE_SEEN_RATIO: the locust's were 5x the typical move)
            ends = np.flatnonzero(breaks)
            begins = ends if anchor is not None and not breaks[0] else np.r_[0, ends]
            at_edge = np.flatnonzero(edge)
            for i in at_edge:
                if i in bounds:
                    continue
                s = begins[begins < i].max(initial=-1)
                e = ends[ends > i].min(initial=len(window))
                # the shorter side, where both are short (both where they are as long)
                head = i - s if s >= 0 and not ((at_edge > s) & (at_edge < i)).any() \
                    else np.inf
                tail = e - i if e < len(window) and not (
                    (at_edge > i) & (at_edge < e)).any() else np.inf
                if min(head, tail) > temporal.WRONG_STRETCH:
                    continue
                if head <= tail:
                    out.update(range(s, i))
                if tail <= head:
                    out.update(range(i, e))
                bounds.add(int(i))
            outside = {k for i in bounds for k in (i - 1, i) if k >= 0 and k not in out}
            return (out | {k for i in at if i not in bounds for k in (i - 1, i) if k >= 0},
                    outside)

        def path_markers() -> np.ndarray:
            """(n + 1, n_markers, 3) model markers along the chosen path, the frame before the
            window first (NaN where the path has no posture)."""
            first = previous if previous is not None and not breaks[0] else None
            chosen = [first, *(r.candidates[c] if c >= 0 else None
                               for r, c in zip(window, choice, strict=True))]
            have = np.array([c is not None for c in chosen])
            mk = np.full((len(chosen), len(self.body.marker_names), 3), np.nan)
            if have.any():
                mk[have] = self._markers([c for c in chosen if c is not None])
            return mk

        # the seeds tried, by frame and id, each kept alive here: a candidate the merges
        # drop would be freed, and a new one could take its id and be skipped as tried
        tried: dict[tuple[int, int], Candidate] = {}

        def keep(k: int) -> float:
            """A re-fit joins frame k's candidates only when it fits about as well as the
            best."""
            return (min(c.error for c in window[k].candidates)
                    + REFIT_KEEP_PX * max(images[first + k], 1))

        def carried(i: int, step: int, seed: Candidate) -> Iterator[tuple[int, Candidate]]:
            """The seed's posture refined at frame i, then each result refined at the next
            frame in the same direction while it fits about as well and is new there: a
            wrong stretch a lower-E minimum holds (a ghost in an occluded marker's place)
            is crossed with the movement, where a cold anneal would fall back into it."""
            k = i
            while 0 <= k < len(window) and window[k].candidates and abs(k - i) <= \
                    temporal.WRONG_STRETCH:
                c = self._refit_from(obs, int(idx[first + k]), seed, p, polish=True)
                if c is None or c.error > keep(k):
                    return
                yield k, c
                if k != i and len(self._distinct([*window[k].candidates, c], replace(
                        p, candidates=len(window[k].candidates) + 1))) == len(
                        window[k].candidates):
                    return  # frame k had this posture already: the path can take it on
                seed, k = c, k + step
                if not (0 <= k < len(window)) or breaks[max(k, k - step)]:
                    return

        def from_seed(i: int, j: int, seed: Candidate) -> list[tuple[int, Candidate | None]]:
            """Frame i re-fitted from neighbour j's candidate ``seed`` and, with refinement,
            the seed's own posture carried on from i."""
            out = [(i, self._refit_from(obs, int(idx[first + i]), seed, p))]
            if p.refine:
                out.extend(carried(i, i - j, seed))
            return out

        pools: list[ThreadPoolExecutor] = []  # for the re-fits, made when first needed
        changed_any = False
        try:
            for _ in range(2):
                redo = jumping()
                grown = changed = False
                for i in sorted(redo):
                    seeds = []
                    for j in (i - 1, i + 1):
                        if j == -1 and anchor is not None and not breaks[0]:
                            of_j = (previous,)  # the frame just before the window
                        elif not (0 <= j < len(window)) or breaks[max(i, j)]:
                            continue
                        else:
                            of_j = window[j].candidates
                        for cand in of_j:
                            if (i, id(cand)) not in tried:
                                tried[i, id(cand)] = cand
                                seeds.append((i, j, cand))
                    # the seeds' re-fits are independent (each keyed by its frame, the window
                    # unchanged until they are merged): on every thread at once, merged in order
                    found: dict[int, list[Candidate]] = {}
                    for out in self._each(from_seed, seeds, pools):
                        for k, c in out:
                            found.setdefault(k, []).append(c)
                    # merged at once: the next frame's re-fits start from these too
                    for k, extra in sorted(found.items()):
                        extra = [c for c in extra if c is not None and c.error <= keep(k)]
                        if extra:
                            before = len(window[k].candidates)
                            # bounded: the re-fits seed the next frame's, so a frame that
                            # kept every distinct re-fit multiplied them along the window
                            merged = self._distinct(list(window[k].candidates) + extra, replace(
                                p, candidates=min(p.candidates + len(extra),
                                                  p.candidates + REFIT_CANDIDATES)))
                            window[k] = replace(window[k], candidates=merged)
                            grown = grown or len(merged) > before
                            changed = True
                if changed:  # the path's choice indexes the candidates as they are now
                    choice, unary, post = path()
                    changed_any = True
                if not grown:
                    break
        finally:
            for pool in pools:
                pool.shutdown()
        # a cut whose first frames had only wrong candidates until the re-fits (no frame
        # before the cut moved little then): found now, so its jump is no jump to flag (the
        # path, chosen already on these candidates, again only where the cuts changed)
        if changed_any and ((found := cut()) != breaks).any():
            breaks = found
            choice, unary, post = path()
        # a jump the re-fits could not remove: the frames on both sides need a look (relative
        # to the window's own movement only: a fast or coarsely sampled one jumps throughout)
        # if the markers show it: a change of axes the markers barely see (a fly's coxa roll,
        # which its other axes nearly undo) is nothing a person could correct (fly 0:660: 142
        # frames ambiguous, 7 of them off, before)
        mk = path_markers()  # the path is final: its markers, for the jumps and the kinks
        flagged, beside = still_jumping(mk)
        # ... and a frame off the line through its neighbours (a jump too small to see
        # against the movement, e.g. a marker a ghost took for a frame or two)
        chosen = np.array([post[i, c] if c >= 0 else np.full(len(scale), np.nan)
                           for i, c in enumerate(choice)])
        # ... that the markers show, as for the jumps: off its neighbours' midpoint by more
        # than JUMP_SEEN_RATIO x the window's median such distance
        off_line = np.full(len(mk), np.nan)  # the frame before the window first
        off_line[1:-1] = np.linalg.norm(mk[1:-1] - (mk[:-2] + mk[2:]) / 2.0,
                                        axis=-1).max(axis=-1)
        cut = np.r_[breaks, False]  # not across a cut in the movement
        off_line[1:][cut[:-1] | cut[1:]] = np.nan
        typical_off = np.nanmedian(off_line) if np.isfinite(off_line).any() else 0.0
        with np.errstate(invalid="ignore"):
            seen = ~(off_line <= JUMP_SEEN_RATIO * typical_off)
        if anchor is not None and not breaks[0]:
            kinked = temporal.kinks(np.r_[anchor[None], chosen], scale, n_angles,
                                    np.r_[False, breaks], seen)[1:]
        else:
            kinked = temporal.kinks(chosen, scale, n_angles, breaks, seen[1:])
        flagged |= set(np.flatnonzero(kinked).tolist()) - beside
        # "about as well": within ambiguous_px per marker image, and within half the typical
        # E per image of the window (on a clean video a posture 60x worse than the chosen
        # one is a poor local minimum, not an ambiguity)
        typical = np.median([min(c.error for c in r.candidates) / max(images[first + i], 1)
                             for i, r in enumerate(window) if r.candidates] or [0.0])
        margin = min(p.ambiguous_px, max(AMBIGUOUS_FLOOR_PX, 0.5 * typical))
        # per candidate, the least movement of a path through it (min-marginals of the path
        # without E): a candidate the movement rules out is no ambiguity
        moved = temporal.solve_path(np.where(np.isfinite(unary), 0.0, np.inf), post, scale,
                                    n_angles, p.path_weight, breaks, anchor)[1]
        results = []
        for i, r in enumerate(window):
            if choice[i] < 0:
                results.append(r)
                continue
            chosen = r.candidates[choice[i]]
            near = np.abs(unary[i] - unary[i, choice[i]]) <= margin
            near[choice[i]] = False
            if near.any() and p.ambiguous_move > 0:  # ... and visibly elsewhere
                moves = np.zeros(len(near))  # (the window's rows are padded)
                moves[:len(r.candidates)] = self._marker_moves(chosen, r.candidates)
                near &= moves > self._apart(p)
            # ... and the movement does not rule it out: the smoothest path through it moves
            # about as little as the smoothest through the chosen one (a mirror branch as
            # smooth as the chosen one costs nothing more, a flip for one frame two jumps)
            near &= moved[i] - moved[i, choice[i]] <= AMBIGUOUS_MOVEMENT
            ambiguous = bool(near.any()) or i in flagged
            cands = (chosen, *(c for k, c in enumerate(r.candidates) if k != choice[i]))
            if np.array_equal(chosen.angles_deg, r.angles_deg) and np.array_equal(
                    chosen.root_positions, r.root_positions):
                # the frame's own best: scored already, only the flag may change
                ambiguous = ambiguous and r.status not in ("failed", "no-detections")
                results.append(replace(r, candidates=cands,
                                       status="ambiguous" if ambiguous else r.status))
                continue
            results.append(self._frame_result(
                obs, int(idx[first + i]), r.frame, chosen.state, chosen.seed_pos,
                chosen.seed_rot, p,
                runs=r.runs, iterations=r.iterations, pairs=r.refined_pairs or 0,
                candidates=cands, ambiguous=ambiguous, confirmed_only=r.status == "ok"))
        return results

    @staticmethod
    def _each(fn, args: list[tuple], pools: list) -> list:
        """``[fn(*a) for a in args]``, on numba's threads at once where its threading layer
        takes kernels from several threads (:func:`concurrent_fits`); each call's results
        depend only on its arguments, so the order of work changes nothing. The pool is made
        on first use and kept in ``pools`` for the caller to shut down (one costs ~0.4 ms,
        about a re-fit of the locust)."""
        threads = numba.get_num_threads()
        if min(threads, len(args)) < 2 or not concurrent_fits():
            return [fn(*a) for a in args]
        if not pools:
            pools.append(ThreadPoolExecutor(threads))
        return list(pools[0].map(lambda a: fn(*a), args))

    def _track(self, obs: Observations, idx: np.ndarray, roots, rots, p: AnnealParams,
               cancel: Callable[[], bool] | None) -> Iterator[FrameResult]:
        """``start="track"``: :meth:`_track_frames`, E spikes flagged (:func:`flag_e_spikes`)."""
        yield from flag_e_spikes(self._track_frames(obs, idx, roots, rots, p, cancel))

    def _track_frames(self, obs: Observations, idx: np.ndarray, roots, rots,
                      p: AnnealParams, cancel: Callable[[], bool] | None
                      ) -> Iterator[FrameResult]:
        """``start="track"``: frames in segments of at most ``segment_length`` consecutive
        frame numbers, one segment per thread at once; results in the order of ``idx``.
        With ``threshold_mode="auto"`` the threshold is measured on the first segments'
        tracked E (a tracked frame costs a tenth of the sample of full fits that measure it
        otherwise), and their frames above it are then fitted in full. With several
        partitions each segment is mended with the one before (:meth:`_mend`) before it is
        yielded, so the last one done is held back until its next one is."""
        cut = np.flatnonzero(np.diff(idx) != 1) + 1  # a gap in the frames starts a segment
        bounds = sorted({0, len(idx), *cut.tolist(),
                         *range(0, len(idx), max(1, p.segment_length))})
        segments = list(itertools.pairwise(bounds))
        p = replace(p, start="mean")  # the full fits of a segment's frames
        measure = p.threshold_mode == "auto"
        if measure:
            p = replace(p, reanalysis_threshold=1e9)  # (the largest allowed): none yet
        pools: list[ThreadPoolExecutor] = []
        held: list[FrameResult] = []  # the last segment, until its next one mended it
        limbs = self._limbs(p)  # mending merges limbs: a body of several partitions
        try:
            for a in range(0, len(segments), numba.get_num_threads()):
                if cancel is not None and cancel():
                    break  # what is fitted is still yielded
                group = segments[a:a + numba.get_num_threads()]
                blocks = self._each(self._track_segment,
                                    [(obs, idx, roots, rots, lo, hi, p) for lo, hi in group],
                                    pools)
                if measure:
                    found = [r for block in blocks for r in block]
                    p = replace(p, reanalysis_threshold=self._threshold_of(
                        obs, [r.frame for r in found], [r.error for r in found]))
                    blocks = [[self._decided(obs, r, idx, roots, rots, lo + k, p)
                               for k, r in enumerate(block)]
                              for (lo, _), block in zip(group, blocks, strict=True)]
                    measure = False
                for (lo, _), block in zip(group, blocks, strict=True):
                    if limbs and held and idx[lo] == idx[lo - 1] + 1:
                        self._mend(obs, p, held, block)
                    if held:
                        yield from held
                    held = block
            if held:
                yield from held
        finally:
            for pool in pools:
                pool.shutdown()

    def _decided(self, obs: Observations, r: FrameResult, idx, roots, rots, i: int,
                 p: AnnealParams) -> FrameResult:
        """A result of the frames the threshold was measured on, decided by it: above it,
        the frame is fitted in full too (:meth:`_fit_again`; no re-track back from it, as
        :meth:`_track_segment` makes, since the frames before are already decided)."""
        if r.error <= p.reanalysis_threshold:
            return replace(r, threshold=float(p.reanalysis_threshold))
        again = self._fit_again(obs, idx, roots, rots, i, p, r)
        return again if again is not r else replace(
            r, status="failed", threshold=float(p.reanalysis_threshold))

    def _fit_full(self, obs: Observations, idx, roots, rots, i: int,
                  p: AnnealParams) -> FrameResult:
        """Frame ``idx[i]`` fitted in full on its own (runs from the means)."""
        return self._fit_block(obs, idx[i:i + 1], idx[i:i + 1],
                               np.ascontiguousarray(roots[i:i + 1]),
                               np.ascontiguousarray(rots[i:i + 1]), self.problem.start,
                               np.array([0, 1], np.int64), p)[0]

    def _fit_again(self, obs: Observations, idx, roots, rots, i: int, p: AnnealParams,
                   tracked: FrameResult | None) -> FrameResult:
        """A tracked frame fitted in full as well: of the full fit and — with several
        partitions — its merge with ``tracked`` (:meth:`_merged`), the one with the lower E
        replaces ``tracked`` where its E is below :data:`TRACK_PREFER` times the tracked E,
        or within the threshold where the tracked E is not (:meth:`_taken`)."""
        again = self._fit_full(obs, idx, roots, rots, i, p)
        if tracked is None:
            return _reanalysed(again)
        merged = self._merged(obs, int(idx[i]), tracked, again, p)
        best = min((again, merged) if merged is not None else (again,),
                   key=lambda r: r.error if np.isfinite(r.error) else np.inf)
        if not (best.error < TRACK_PREFER * tracked.error
                or best.error <= p.reanalysis_threshold < tracked.error):
            return tracked
        return self._taken(tracked, best)

    @staticmethod
    def _taken(old: FrameResult, new: FrameResult) -> FrameResult:
        """``new`` in place of ``old``: ``reanalysed`` where it is ``ok``, its runs and
        iterations added to ``old``'s (a result counts every run made for its frame)."""
        return replace(_reanalysed(new), runs=old.runs + new.runs,
                       iterations=old.iterations + new.iterations)

    def _part_scores(self, r: FrameResult, p: AnnealParams) -> np.ndarray | None:
        """Per partition, the mean over its own markers' images of the distance to the
        nearest detection (px), capped at ``cap_px`` (a marker image without one counts the
        cap); None without residuals or with one partition."""
        marks = self._partitions(p, search=False).bounds[:, [2, 4]]
        res = r.marker_residuals
        if res is None or len(marks) < 2 or res.size == 0:
            return None
        cap = p.error.cap_px or p.claim_gate_px
        d = np.where(np.isnan(res), cap, np.minimum(res, cap))
        return np.array([d[:, a:b].mean() if b > a else 0.0 for a, b in marks])

    def _merged(self, obs: Observations, position: int, base: FrameResult,
                other: FrameResult, p: AnnealParams) -> FrameResult | None:
        """``base`` with each limb partition whose own markers ``other`` explains better
        (by :data:`TRACK_MERGE_PX`, :meth:`_part_scores`) taken from ``other``, refined in
        place; ``other`` where every partition is; None where none is. A track that lost
        one leg and a full fit that put another leg on a neighbour's points (fly frames 367,
        480: the lower E of the two was still off) merge into a posture with every leg
        right. Only limbs are swapped: a trunk or a free root stays, the limbs hang off it.
        The merge's runs and iterations are ``other``'s (the work beyond ``base``)."""
        a, b = self._part_scores(base, p), self._part_scores(other, p)
        if a is None or b is None or not (np.all(np.isfinite(base.angles_deg))
                                          and np.all(np.isfinite(other.angles_deg))):
            return None
        parts = self._partitions(p, search=False)
        better = np.flatnonzero(b < a - TRACK_MERGE_PX)
        if len(better) == len(a):
            return other
        free = set(self.problem.root_axes.ravel().tolist())
        angles = np.array(base.angles_deg, float)
        swapped = 0
        tops = parts.bounds[:, 0]
        for k in better:
            dofs = parts.dofs[parts.dof_off[k]: parts.dof_off[k + 1]]
            j0, j1 = parts.bounds[k, :2]
            if (np.any((tops > j0) & (tops < j1)) or np.any(dofs >= self.problem.n_axes)
                    or free.intersection(dofs.tolist())):
                continue  # a trunk (limbs below it) or a free root: the limbs hang off it
            angles[dofs] = other.angles_deg[dofs]
            swapped += 1
        if swapped == 0:
            return None
        seed = Candidate(angles, base.root_positions, np.nan, None, None, None)
        c = self._refit_from(obs, position, seed, p, polish=True)
        return None if c is None else self._result_of(obs, position, c, p, other.runs,
                                                      other.iterations)

    def _track_segment(self, obs: Observations, idx, roots, rots, lo: int, hi: int,
                       p: AnnealParams) -> list[FrameResult]:
        """Frames ``idx[lo:hi]`` tracked: the first fitted in full, each next one annealed
        cold from the previous result; one above the threshold or whose E jumps (above
        :data:`TRACK_JUMP` times the median of the last :data:`TRACK_MEMORY` kept, plus
        :data:`TRACK_JUMP_PX` per marker image) is fitted in full too (:meth:`_fit_again`).
        Where that replaces the track of a body of several partitions, the frames before
        are tracked back from it (:meth:`_retrack`): a track that crept off a leg until E
        jumped gets it back. So are they from a tracked frame whose E falls below
        :data:`TRACK_DROP` times that median: a track that lost a leg and found it again."""
        out = [self._fit_full(obs, idx, roots, rots, lo, p)]
        kept_e = [out[0].error] if np.isfinite(out[0].error) else []
        limbs = self._limbs(p)
        for i in range(lo + 1, hi):
            r = self._step(obs, int(idx[i]), out[-1], p)
            images = int(marker_images(obs, idx[i:i + 1], len(self.body.marker_names))[0])
            # (NaN before any E is kept: then E neither jumps nor falls)
            recent = float(np.median(kept_e[-TRACK_MEMORY:])) if kept_e else np.nan
            jump = TRACK_JUMP * recent + TRACK_JUMP_PX * max(images, 1)
            if r is None or not r.error <= p.reanalysis_threshold or r.error > jump:
                tracked, r = r, self._fit_again(obs, idx, roots, rots, i, p, r)
                mend = r is not tracked  # a cut: mend the frames that led to it
            else:
                mend = r.error < TRACK_DROP * recent  # found a leg it had lost?
            if mend and limbs:
                self._retrack_back(obs, p, out, r)
                kept_e = [q.error for q in out if np.isfinite(q.error)]
            out.append(r)
            if np.isfinite(r.error):
                kept_e.append(r.error)
        return out

    def _step(self, obs: Observations, position: int, prev: FrameResult,
              p: AnnealParams) -> FrameResult | None:
        """Frame ``position`` tracked from a neighbour's result ``prev``: one cold anneal of
        :data:`TRACK_SHARE` of the schedule from its posture; None where it has none."""
        if not np.all(np.isfinite(prev.angles_deg)):
            return None
        seed = Candidate(prev.angles_deg, prev.root_positions, prev.error, None, None, None)
        counted: list[int] = []
        c = self._refit_from(obs, position, seed, p, share=TRACK_SHARE, counted=counted)
        return None if c is None else self._result_of(obs, position, c, p, 1, counted[0])

    def _result_of(self, obs: Observations, position: int, c: Candidate, p: AnnealParams,
                   runs: int, iterations: int) -> FrameResult:
        """The :class:`FrameResult` of frame ``position`` fitted to candidate ``c``."""
        return self._frame_result(obs, position, position, c.state, c.seed_pos, c.seed_rot,
                                  p, runs=runs, iterations=iterations, pairs=0,
                                  candidates=(c,))

    def _mend(self, obs: Observations, p: AnnealParams, before: list[FrameResult],
              after: list[FrameResult]) -> None:
        """Two segments tracked apart, ``after`` starting on the frame after ``before``'s
        last, re-tracked across their boundary (:meth:`_retrack`, in place): ``after`` from
        ``before``'s last result, then ``before`` backwards from ``after``'s first. A
        segment's first frame is fitted alone and can put a leg on a neighbour's points (fly
        frame 480), and a track that lost a leg keeps it lost to its segment's end
        (367-383): the neighbouring segment's track finds both."""
        self._retrack(obs, p, after, before[-1])
        self._retrack_back(obs, p, before, after[0])

    def _retrack_back(self, obs: Observations, p: AnnealParams, results: list[FrameResult],
                      seed: FrameResult) -> None:
        """:meth:`_retrack` backwards: ``results`` from their last, ``seed`` the result of
        the frame after it."""
        back = results[::-1]
        self._retrack(obs, p, back, seed)
        results[:] = back[::-1]

    def _retrack(self, obs: Observations, p: AnnealParams, results: list[FrameResult],
                 seed: FrameResult) -> None:
        """``results`` (consecutive frames, in the order to track them) tracked again from
        ``seed``, the result of the frame before the first (in place).

        - Each frame takes the step, or its merge with the result there where that has an
          E below :data:`TRACK_PREFER` times the step's: a merge keeps the result's wrong
          leg where that leg scores well on a neighbour's points (fly, 3 cameras, frame 224).
        - A stretch of such frames replaces the results once its summed E is below
          TRACK_PREFER times theirs. One frame's E is noise: a leg on a neighbour's points
          can fit a frame as well as the right posture and the next frames worse (fly,
          3 cameras, frames 224-253).
        - Where the re-track meets the results (every model marker within
          ``ambiguous_move`` segment lengths of the result's, and E not below TRACK_PREFER
          times its), the stretch before is taken where its summed E is below theirs at
          all, and the re-track stops. It also stops after :data:`TRACK_WINDOW` frames not
          taken."""
        near = self._apart(p)
        taken = 0  # results[:taken] are decided
        pending: list[FrameResult] = []
        alt_e = res_e = 0.0
        for k, result in enumerate(results):
            prev = pending[-1] if pending else seed if k == 0 else results[k - 1]
            step = self._step(obs, int(result.frame), prev, p)
            if step is None:
                return
            merged = self._merged(obs, int(result.frame), result, step, p)
            best = (merged if merged is not None and merged.error < TRACK_PREFER * step.error
                    else step)
            if (self._marker_moves(result, [best])[0] <= near
                    and not best.error < TRACK_PREFER * result.error):
                # met: the stretch before joins the results here without their jump, so it
                # need only fit better
                if pending and alt_e < res_e:
                    self._take(results, taken, pending)
                return
            pending.append(best)
            alt_e += best.error
            res_e += result.error
            if alt_e < TRACK_PREFER * res_e:
                taken = self._take(results, taken, pending)
                pending, alt_e, res_e = [], 0.0, 0.0
            elif len(pending) >= TRACK_WINDOW:
                return

    @staticmethod
    def _take(results: list[FrameResult], first: int, stretch: list[FrameResult]) -> int:
        """``results[first:]`` replaced by ``stretch`` (:meth:`_taken`), in place; returns
        the index after it."""
        end = first + len(stretch)
        results[first:end] = [Fitter._taken(r, s) for r, s in
                              zip(results[first:end], stretch, strict=True)]
        return end

    def _marker_moves(self, chosen: Candidate, cands: Sequence[Candidate],
                      markers: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Per candidate, the largest distance of a model marker (of ``markers``) from where
        the chosen posture puts it (length units)."""
        mk = self._markers([chosen, *cands])[:, markers]
        return np.linalg.norm(mk[1:] - mk[0], axis=-1).max(axis=-1)

    def _markers(self, cands: Sequence[Candidate]) -> np.ndarray:
        """(n, n_markers, 3) model markers of candidate postures (or results)."""
        angles = np.array([c.angles_deg for c in cands])
        roots = np.array([c.root_positions for c in cands])
        return forward_kinematics(self.body, angles, roots).markers

    @property
    def _segment_scale(self) -> float:
        """The body's median segment length (the unit of ``ambiguous_move``)."""
        lengths = [abs(float(seg.length)) for _, seg in self.body.segments()]
        return float(np.median([v for v in lengths if v > 0] or [1.0]))

    def _refit_from(self, obs: Observations, position: int, neighbour: Candidate,
                    p: AnnealParams, polish: bool = False, share: float | None = None,
                    counted: list | None = None) -> Candidate | None:
        """Anneal frame ``position`` again, cold and locally, from a neighbour's posture;
        with ``polish``, only refine the neighbour's posture there (one annealing step too
        small to move it, then the refinement): a posture a wrong minimum with a lower E
        would draw even a cold anneal into (a ghost in an occluded marker's place) stays
        where the movement has it. ``share``: the part of the schedule the cold anneal
        runs (default :data:`REFIT_SHARE`); ``counted``, if given, gets the iterations it ran
        appended."""
        share = REFIT_SHARE if share is None else share
        state, pos, rot = self.problem.state(neighbour.angles_deg, neighbour.root_positions)
        if polish:
            local = replace(p, candidates=1, max_runs=1, tau0=p.tau0 * 1e-6, l0=p.l0 * 1e-6,
                            n_end=1, n_l=1, n_tau=1, start="mean")
        else:
            local = replace(p, candidates=1, max_runs=1, tau0=p.tau0 * 0.01, l0=p.l0 * 0.1,
                            n_end=max(1, int(p.n_end * share)), n_l=max(1, int(p.n_l * share)),
                            n_tau=max(1, int(p.n_tau * share)), start="mean")
        cams, arrays = self._kernel_inputs(obs.arrays(np.array([position], np.int64)))
        out = FitOutputs.empty(1, self.problem.n_state, len(cams.kind), 1)
        # no start search: the neighbour's posture is the start
        parts = self._partitions(p, search=False)
        # keyed by frame + 1_000_003: a random stream apart from the frames' own runs
        _ak.fit_frames(np.array([0, 1], np.int64), np.array([position + 1_000_003], np.int64),
                       np.ascontiguousarray(pos[None]), np.ascontiguousarray(rot[None]),
                       state, self.problem.folded, cams, self.problem.dofs,
                       schedule_of(local), self._error_args(p, arrays.objective), arrays,
                       parts, out)
        if counted is not None:
            counted.append(int(out.iterations[0]))
        if not out.runs[0]:
            return None
        return self._candidates(out.run_angles[0], out.run_error[0], pos, rot, local)[0]

    def _residuals(self, obs: Observations, state, root_pos, root_rot, arrays,
                   gate: float) -> tuple[np.ndarray, int]:
        """(n_views, n_markers) distance of each model marker to its nearest detection (to
        its own keypoint for labelled keypoints; NaN where there is none), and the number of
        detections farther than ``gate`` from every marker (for a cloud: of its 3D points,
        as the kernel counts them)."""
        proj, mk = self._project_state(state, root_pos, root_rot, markers=True)
        pts, view_off = arrays.points, arrays.offsets
        out = np.full(proj.shape[:2], np.nan)
        seen = np.ones(proj.shape[:2], bool)
        if obs.hidden is not None or obs.unseen is not None:  # no residual, explain nothing
            seen = arrays.points3d[0].T == 0.0
        elif self.unseen is not None:  # a cloud of several colours: views show some
            seen = ~self.unseen
        unexplained = 0
        if obs.labelled:
            for v in range(obs.n_views):  # a missing keypoint (weight 0) has no residual
                d = pts[view_off[v]: view_off[v + 1]]
                if len(d):
                    out[v] = np.where(arrays.conf[view_off[v]: view_off[v + 1]] > 0,
                                      np.linalg.norm(proj[v] - d, axis=1), np.nan)
        elif obs.n_views:  # 3D points have no views, even with cameras
            unexplained = int(_ak.nearest_residuals(proj, pts, view_off, seen, float(gate),
                                                    out))
        if obs.kind == "cloud":
            unexplained = int(_ak.count_unexplained_cloud(mk, arrays.points3d[0], gate))
        return out, unexplained


def _reanalysed(r: FrameResult) -> FrameResult:
    """``r`` made ``reanalysed`` where it is ``ok`` (a result that replaced another)."""
    return replace(r, status="reanalysed" if r.status == "ok" else r.status)


def misplaced(results: Sequence[FrameResult], gate: float) -> np.ndarray:
    """Per result: a marker lies off every detection of its view (``worst_px`` above the
    results' median + :data:`MISPLACED_K` robust SDs, and above ``gate``) while the frame
    leaves more detections unexplained than these frames do (above their median +
    :data:`MISPLACED_UNEXPLAINED_K` robust SDs): a limb on another limb's points, its own
    left over. A marker off its point alone is an occluded one, a frame's unexplained
    detections alone its ghosts."""
    worst = np.array([r.worst_px if r.runs else np.nan for r in results], float)
    left = np.array([r.unexplained for r in results], float)
    fitted = np.isfinite(worst)
    out = np.zeros(len(results), bool)
    if fitted.sum() < 3:  # no statistics of a video
        return out
    limit = max(gate, auto_threshold(worst[fitted], MISPLACED_K, 0.0))
    # a count: where over half the frames share one value its MAD is 0, so the spread is at
    # least half the 10-90 % range (a ghost that flickers in half the frames: 1)
    counts = left[fitted]
    med = float(np.median(counts))
    lo, hi = np.percentile(counts, [10.0, 90.0])
    spread = max(1.4826 * float(np.median(np.abs(counts - med))), float(hi - lo) / 2.0)
    usual = med + MISPLACED_UNEXPLAINED_K * spread
    with np.errstate(invalid="ignore"):
        return (worst > limit) & (left > usual)


def flag_misplaced(results: Iterable[FrameResult], gate: float,
                   before: Sequence[FrameResult] = (), starts=()) -> Iterator[FrameResult]:
    """``results`` (frames in order), each ``ok`` or ``reanalysed`` one that :func:`misplaced`
    finds among the :data:`MISPLACED_HALF` results on either side and itself made
    ``ambiguous`` (neighbours in the same run of consecutive frames only, not across a frame
    of ``starts``, where a new sequence starts); a result is yielded once MISPLACED_HALF
    later ones are known. ``before``: results just before the first (a resumed fit's),
    counted but not yielded."""
    starts = np.asarray(list(starts), np.int64)

    def judge(window: list[FrameResult], k: int) -> FrameResult:
        r = window[k]
        lo = max(0, k - MISPLACED_HALF)  # the same run of consecutive frames only
        around = [w for j, w in enumerate(window[lo: k + MISPLACED_HALF + 1], lo)
                  if w.frame - r.frame == j - k and not (
                      (starts > min(w.frame, r.frame)) & (starts <= max(w.frame, r.frame))
                  ).any()]
        if r.status in ("ok", "reanalysed") and misplaced(around, gate)[
                next(j for j, w in enumerate(around) if w is r)]:
            return replace(r, status="ambiguous")
        return r
    return _judged(results, MISPLACED_HALF, judge, before)


def flag_e_spikes(results: Iterable[FrameResult], ratio: float | None = None,
                  half: int | None = None) -> Iterator[FrameResult]:
    """``results`` (frames in order), each ``ok`` or ``reanalysed`` one whose E is above
    ``ratio`` (:data:`TRACK_SPIKE`) times the median E of the ``half``
    (:data:`TRACK_SPIKE_HALF`) consecutive frames on either side and itself, plus
    :data:`TRACK_JUMP_PX` per marker image with a residual, made ``ambiguous``; a result is
    yielded once ``half`` later ones are known. A frame with fewer than ``half`` + 1 such
    frames around it (a run of frames that short) is not flagged. A tracked frame has no
    candidates to compare; a wrong one stands out from its neighbours by E (fly 0:660: 16
    flagged of 660, 11 of them off by > 0.2 mm; 9 of the 10 frames off by > 0.3 mm)."""
    ratio = TRACK_SPIKE if ratio is None else ratio
    half = TRACK_SPIKE_HALF if half is None else half

    def judge(window: list[FrameResult], k: int) -> FrameResult:
        r = window[k]
        lo = max(0, k - half)  # the same run of consecutive frames only
        around = [w.error for j, w in enumerate(window[lo: k + half + 1], lo)
                  if np.isfinite(w.error) and w.frame - r.frame == j - k]
        images = (0 if r.marker_residuals is None
                  else int(np.isfinite(r.marker_residuals).sum()))
        if (r.status in ("ok", "reanalysed") and np.isfinite(r.error) and len(around) > half
                and r.error > ratio * float(np.median(around)) + TRACK_JUMP_PX * images):
            return replace(r, status="ambiguous")
        return r
    return _judged(results, half, judge)


def _judged(results: Iterable[FrameResult], half: int,
            judge: Callable[[list[FrameResult], int], FrameResult],
            before: Sequence[FrameResult] = ()) -> Iterator[FrameResult]:
    """``judge(window, k)`` of each of ``results``, in order, where ``window[k]`` is that
    result and ``window`` holds up to ``half`` results on either side of it; each is yielded
    once ``half`` later ones are known. ``before``: results just before the first, in the
    window but not judged."""
    window = list(before)[-half:] if half else []
    done = len(window)  # how many of ``window`` are yielded (or came before)
    for r in results:
        window.append(r)
        while len(window) - done > half:
            yield judge(window, done)
            done += 1
            if done > half:
                window.pop(0)
                done -= 1
    for k in range(done, len(window)):
        yield judge(window, k)


def concurrent_fits() -> bool:
    """Whether kernels may run from several Python threads at once: numba's OpenMP and TBB
    threading layers take parallel kernels from several threads, its workqueue layer aborts
    the process (and before the first parallel kernel the layer is not known)."""
    try:
        return numba.threading_layer() in ("omp", "tbb")
    except ValueError:
        return False


#: A chosen posture change between consecutive frames larger than this (in squared
#: histogram spreads, :mod:`kinematics.temporal`) re-fits both frames from their neighbours.
REDO_JUMP = 1.0
#: ... or larger than this many times the window's median change (at least REDO_JUMP_MIN).
REDO_JUMP_RATIO, REDO_JUMP_MIN = 16.0, 0.02
#: A jump the re-fits leave (or a kink) makes frames ``ambiguous`` only where some model
#: marker moves more than this many times the window's median largest marker move per frame
#: (off its neighbours' midpoint: that distance's median); a distance, where the ratios
#: above are of squared changes. Fly 0:660 at 2 / 4 / 8 / 16: 21 / 14 / 12 / 12 frames
#: flagged, 8 of them off each time; locust clutter (bench_status, 8 seeds): 18 / 17 / 16 /
#: 14 flagged, 3 of 5 off frames each. Not for the re-fits: a rat's femur roll 29° off with
#: every marker where it was (0.7-0.9 of the median move) is found by them.
JUMP_SEEN_RATIO = 8.0
#: ... except next to a cut, where a jump within ``temporal.WRONG_STRETCH`` frames of it
#: counts where some marker moves more than this many times that typical move
EDGE_SEEN_RATIO = 3.0
#: A re-fit from a neighbour becomes a candidate only within this E per marker image (px)
#: of the frame's best ...
REFIT_KEEP_PX = 1.0
#: ... and a frame keeps at most this many re-fits beyond its own ``candidates`` (lowest E
#: first; postures 5° apart on any axis count as distinct, which on a 42-axis body is almost
#: any two: unbounded, a fly's 20-frame window grew from 40 to 3 627 candidates).
REFIT_CANDIDATES = 4
#: The part of the schedule a cold re-fit from a neighbour anneals (it starts close). Fly
#: over the whole clip, 6 cameras, at 0.25 / 0.1 / 0.05: 98.5 % right each time at 5.2 /
#: 7.1 / 7.8 frames/s, 12 / 11 / 17 frames flagged, 8 of them off each time; 3 cameras
#: 96.5 / 97.0 / 97.1 %. The rat of docs/markerless.md 2.02 / 2.03 / 2.02°; the locust
#: (bench_temporal, bench_status) the same (docs/benchmarks.md, session 24).
REFIT_SHARE = 0.1

#: ``start="track"``: the part of the schedule a frame's cold anneal from the previous frame
#: runs. On the fly's contiguous frames 0-65 a tenth kept every frame a full fit got right
#: (86.4 %) at 82 frames/s on one thread; a quarter the same at 35 (docs/benchmarks.md).
TRACK_SHARE = 0.1
#: ... a tracked frame whose E exceeds this times the median E of the last TRACK_MEMORY
#: frames kept is fitted in full (the track lost: on the fly's frame 338 E doubled and stayed
#: so, every joint of a leg off by 1-2 mm, for the rest of the clip).
TRACK_JUMP = 1.5
TRACK_MEMORY = 16
#: ... plus this per marker image of the frame (px): on a clean video E is noise, and
#: noise doubles from frame to frame.
TRACK_JUMP_PX = 0.05
#: ... and the full fit (or a merge) replaces the tracked result only where its E is below
#: this times the tracked E; a re-track (``Fitter._retrack``) takes a merge only below this
#: times its step's E, and replaces results by a stretch whose summed E is below this times
#: theirs: on the fly the lower E of two fits often has a leg on a neighbour's points (0:660:
#: 95.2 % within 0.2 mm at 0.9, 94.5 % at 0.95, 94.8 % at 0.85; session 13).
TRACK_PREFER = 0.9
#: ... a re-track gives up after this many frames it has not taken (fly, 3 cameras, 0:660:
#: one frame at a time 88.5 %, stretches of up to 8 frames 92.4 %; session 26).
TRACK_WINDOW = 8
#: A tracked frame whose E falls below this times the median of the last TRACK_MEMORY kept
#: is tracked back (``Fitter._retrack``): a track that lost a leg finds it again with a
#: lower E, and the frames before are mended from it (fly, 3 cameras, 0:660: 93.3 % within
#: 0.2 mm without, 95.9 / 95.9 / 96.2 / 96.5 % at 0.8 / 0.85 / 0.9 / 1.0, 96.7 % tracking
#: every frame back at 0.9 times the frames/s of 1.0).
TRACK_DROP = 1.0
#: A tracked frame whose E is above this times the median E of the TRACK_SPIKE_HALF frames
#: on either side (and itself), plus TRACK_JUMP_PX per marker image, is ``ambiguous`` (fly
#: 0:660, 32 frames off by > 0.2 mm: 1.2 flagged 35 frames, 13 of them off; 1.3 16 with 11;
#: with no TRACK_JUMP_PX 1.3 flagged 38 with 13, and noise on a clean video).
TRACK_SPIKE = 1.3
TRACK_SPIKE_HALF = 8
#: A limb (partition) is taken from another fit where its own markers lie this much closer
#: (px per marker image, :meth:`Fitter._part_scores`) to their detections (fly 0:660: 94.2 %
#: at 0.25, 95.2 % at 0.5 and 1.0).
TRACK_MERGE_PX = 0.5
#: A frame whose worst marker residual lies this many robust SDs above its window's median
#: (:func:`misplaced`) ... (fly 0:660, k = 3 / 4 / 5 / 6 / 8: 22 / 11 / 8 / 5 / 3 frames, of
#: them 9 / 8 / 8 / 5 / 3 of the 10 off by > 0.2 mm)
MISPLACED_K = 5.0
#: ... and leaves more detections unexplained than its window's median + this many robust SDs
#: (locust clutter: 3-7 ghosts unexplained a frame, median 5, robust SD 1.5) is ``ambiguous``.
MISPLACED_UNEXPLAINED_K = 2.0
#: ... both among the results this many frames on either side of it and itself.
MISPLACED_HALF = 32
#: Decided frames kept before a window: the cut rule (:func:`temporal.cuts`) looks 2 back.
CUT_CONTEXT = 2
#: The path through time decides a window of 2 x PATH_LAG frames and keeps its first
#: PATH_LAG (fixed lag: a frame is decided once PATH_LAG later frames are fitted).
PATH_LAG = 32
#: A candidate whose smoothest path moves more than this (squared histogram spreads, the
#: path's units) beyond the chosen candidate's smoothest is ruled out by the movement and
#: makes no frame ambiguous.
AMBIGUOUS_MOVEMENT = 0.5
#: The least difference in E per marker image (px) that still counts as "about as well".
AMBIGUOUS_FLOOR_PX = 1e-3


def auto_threshold(score: np.ndarray, k: float, floor: float) -> float:
    """Threshold per marker image from a sample's E per marker image ``score``: median + k ·
    1.4826 · MAD, at least ``floor``. Where E comes in steps (each unclaimed ghost adds the
    same cost) and over half the sample sits on one, the MAD collapses (below 1 % of the
    median) and every frame on the next step would fail: the spread is then the 10-90 %
    range / 2.563, the same for normal data."""
    med = float(np.median(score))
    spread = 1.4826 * float(np.median(np.abs(score - med)))
    if spread < 0.01 * med:
        lo, hi = np.percentile(score, [10.0, 90.0])
        spread = max(spread, float(hi - lo) / 2.563)
    return max(floor, med + k * spread)


def marker_images(obs: Observations, frames, n_markers: int) -> np.ndarray:
    """Marker images each frame is scored on: markers × views with observations (3D points:
    the markers with a point)."""
    if obs.kind == "points3d":
        return (obs.points3d[frames, :, 3] > 0).sum(axis=1)
    if obs.kind == "cloud":  # E sums one distance per marker
        return n_markers * (obs.points3d[frames, :, 3] > 0).any(axis=1)
    marks = obs.marks(frames)
    seen = n_markers if marks is None else n_markers - marks.sum(axis=2)
    return (seen * (obs.view_counts(frames) > 0)).sum(axis=1)


def _emptied(points: np.ndarray, offsets: np.ndarray, cells: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Ragged points (frame-major offsets) with the (frame, view) ``cells`` flagged True
    emptied."""
    counts = np.diff(offsets)
    keep = np.repeat(~np.asarray(cells, bool).ravel(), counts)
    new_off = np.zeros_like(offsets)
    np.cumsum(np.where(cells.ravel(), 0, counts), out=new_off[1:])
    return np.ascontiguousarray(points[keep]), new_off


def _carry_forward(points: np.ndarray, first: np.ndarray) -> np.ndarray:
    """(n, 3) points with each NaN row replaced by the last finite one (``first`` before
    any)."""
    out = np.array(points, dtype=float, copy=True)
    last = np.asarray(first, dtype=float)
    for k in range(len(out)):
        if np.isfinite(out[k]).all():
            last = out[k]
        else:
            out[k] = last
    return out


# -- functional wrappers ----------------------------------------------------------------------
def fit_frame(body: Body, cameras, detections_frame, params: AnnealParams | None = None,
              **kwargs) -> FrameResult:
    """:meth:`Fitter.fit_frame` without keeping a fitter (packs the body every call)."""
    return Fitter(body, cameras, params).fit_frame(detections_frame, **kwargs)


def iter_fit(body: Body, cameras, detections, params: AnnealParams | None = None,
             frames: Iterable[int] | None = None, **kwargs) -> Iterator[FrameResult]:
    """:meth:`Fitter.iter_fit` for a body, cameras and parameters."""
    return Fitter(body, cameras, params).iter_fit(detections, frames, **kwargs)


# -- the readable twin of the annealing kernel -----------------------------------------------
_MASK64 = (1 << 64) - 1
_GOLDEN = 0x9E3779B97F4A7C15


def _mix64(z: int) -> int:
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


class SplitMix64:
    """The kernels' random stream in plain Python: same (seed, frame, run) -> same draws."""

    def __init__(self, seed: int, frame: int = 0, run: int = 0) -> None:
        s = _mix64((seed + _GOLDEN) & _MASK64)
        s = _mix64(s ^ ((frame * 0xD1B54A32D192ED03) & _MASK64))
        self.state = _mix64(s ^ ((run * 0x8CB92BA72F3D8DD7 + _GOLDEN) & _MASK64))

    def uniform(self) -> float:
        """Next draw, uniform in [0, 1) with 53 bits."""
        self.state = (self.state + _GOLDEN) & _MASK64
        return (_mix64(self.state) >> 11) * 2.0**-53


def anneal_reference(body: Body, cameras, detections_frame, params: AnnealParams | None = None,
                     *, frame: int = 0, run: int = 0, start_deg=None, root_positions=None
                     ) -> tuple[np.ndarray, float, int]:
    """One annealing run written plainly (Sect. 2.3, Eq. 6): the specification of
    :func:`kinematics._anneal_kernels.anneal_chain`, on the same random stream, with E from
    :func:`kinematics.error_function.posture_error` (4×4 forward kinematics, NumPy
    projection). Slow (tens of microseconds per iteration); for tests and benchmarks.

    Returns
    -------
    best_deg : ndarray, shape (n_axes,)
        Best posture seen (degrees, not wrapped).
    best_error : float
    iterations : int
    """
    p = params or AnnealParams()
    cams = list(cameras.values()) if isinstance(cameras, Mapping) else list(cameras)
    dets = [np.asarray(d, dtype=float).reshape(-1, 2) for d in detections_frame]
    dets = [d[np.isfinite(d).all(axis=1)] for d in dets]
    hists = body.histograms()
    step_deg = np.array([h.std_deg() for h in hists])
    free = np.flatnonzero(~body.locked_mask())
    th = p.threshold
    rng = SplitMix64(p.seed, frame, run)

    def energy(angles_deg):
        markers = forward_kinematics_reference(body, angles_deg, root_positions).markers
        proj = np.stack([cam.project(markers) for cam in cams])
        return projection_error(proj, dets, p.error)[0]

    cur = body.mean_posture_deg() if start_deg is None else np.asarray(start_deg, float).copy()
    cur[body.locked_mask()] = body.mean_posture_deg()[body.locked_mask()]
    best, e_cur = cur.copy(), energy(cur)
    e_best, tau, length, it = e_cur, p.tau0, p.l0, 0
    while it < p.n_end and not e_best < p.epsilon:
        u = rng.uniform()  # Metropolis draw first, then the step of Eq. 6
        e_accept = e_cur + tau * -math.log(u) if u > 0 else math.inf
        cand = cur.copy()
        for i in free:
            for _ in range(p.max_redraws + 1):  # Eq. 6, redrawn where implausible
                x = cur[i] + length * step_deg[i] * (2.0 * rng.uniform() - 1.0)
                if hists[i].at(x) >= th:
                    cand[i] = x
                    break
        e = energy(cand)
        if e <= e_cur or e < e_accept:  # Metropolis: u < exp(-(e - e_cur) / tau)
            cur, e_cur = cand, e
            if e < e_best:
                best, e_best = cand.copy(), e
        it += 1
        if it % p.n_tau == 0:
            tau *= p.c_tau
        if it % p.n_l == 0:
            length *= p.c_l
    return best, float(e_best), it


def _unclaimed(cameras, cloud: np.ndarray, points: np.ndarray, offsets: np.ndarray
               ) -> np.ndarray:
    """Which of one frame's detections (``points``, ``offsets`` per view) support no point
    of its ``cloud``: farther than :data:`~kinematics.cloud.SUPPORT_PX` (the support the
    fitter triangulates with) from every point's projection."""
    xyz = cloud[cloud[:, 3] > 0, :3]
    free = np.ones(len(points), bool)
    for v, cam in enumerate(cameras):
        pts = points[offsets[v]: offsets[v + 1]]
        if len(pts) and len(xyz):
            d2 = ((pts[:, None] - cam.project(xyz)[None]) ** 2).sum(-1)
            free[offsets[v]: offsets[v + 1]] = ~(d2 <= SUPPORT_PX ** 2).any(axis=1)
    return free


def _views_near(proj: np.ndarray, points: np.ndarray, offsets: np.ndarray, gates: np.ndarray
                ) -> np.ndarray:
    """Per marker (``proj``: n_views, n_markers, 2), the views with a detection within its
    own gate (``gates``, px) of the marker's projection."""
    n = np.zeros(proj.shape[1], np.int64)
    for v in range(len(offsets) - 1):
        pts, g = points[offsets[v]: offsets[v + 1]], gates[offsets[v]: offsets[v + 1]]
        if len(pts):
            n += (((proj[v][:, None] - pts[None]) ** 2).sum(-1) <= g * g).any(axis=1)
    return n


def _placed(proj: np.ndarray, points: np.ndarray, offsets: np.ndarray, own: np.ndarray,
            own_gate: float, shared_gate: float) -> np.ndarray:
    """Per marker (``proj``: n_views, n_markers, 2), whether the views place it without a
    cloud point: a detection in two views, within ``own_gate`` px where no point has it
    (``own``: the marker's blob seen apart) and within ``shared_gate`` where a point has it
    (its blob fused with a neighbour's there), one of them its own. A marker hidden in every
    view but lying on a neighbour's point has only the neighbour's blobs: not placed."""
    both = _views_near(proj, points, offsets, np.where(own, own_gate, shared_gate))
    alone = _views_near(proj, points, offsets, np.where(own, own_gate, np.nan))  # NaN: none
    return (both >= 2) & (alone >= 1)


def _held(r: FrameResult, spread: float | None, apart: float,
          next_spread: float | None = None) -> FrameResult:
    """A fit within the threshold whose limb has a marker that neither a cloud point nor two
    views place (``spread`` not None: how far apart its runs put that limb's markers, inf
    with one run): ``ambiguous`` where the runs put it more than ``apart`` apart, or the next
    frame's runs do (``next_spread``, where it holds a limb too): nothing in the frame says
    where that limb is, unless every run found it in one place (through 3 cameras 120 of
    the fly's 660 frames held a limb, 104 of them right, most with runs within 0.07 mm;
    docs/benchmarks.md, session 25)."""
    if spread is None or r.status not in ("ok", "reanalysed"):
        return r
    if spread > apart or (next_spread is not None and next_spread > apart):
        return replace(r, status="ambiguous")
    return r


def _covered_partitions(parts, folded, covered: np.ndarray):
    """The final polish's entries, body and markers: the partitions whose own markers are
    all ``covered`` (a cloud point, or placed by the views), and the covered markers they
    move (a trunk's reach its limbs'). A limb with a marker nothing places would be pulled
    by the others alone; the markers no moving entry reaches stay out, as they do not move
    and paired they could only take the moving markers' points."""
    active = [k for k, (_, _, m0, _, m_own) in enumerate(parts.bounds)
              if covered[m0:m_own].all()]
    if not active:
        return np.zeros(0, np.int64), folded, np.zeros(0, np.int64)
    reached = np.zeros(len(covered), bool)  # a trunk's entries move its held limbs too
    for k in active:
        reached[parts.bounds[k, 2]: parts.bounds[k, 3]] = True
    marks = np.flatnonzero(reached & covered)
    return (np.concatenate([parts.dofs[parts.dof_off[k]: parts.dof_off[k + 1]]
                            for k in active]),
            folded._replace(marker_joint=folded.marker_joint[marks],
                            marker_local=folded.marker_local[marks]), marks)
