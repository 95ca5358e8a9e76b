"""The fitting problem: a body, its cameras and its histograms packed once into the layout
every backend uses (annealing, refinement, root placement, the GUI's pinned corrections).

:class:`FitProblem` is frozen and public. Its *state* is the vector the kernels move::

    state = [ angles of every joint axis (n_axes, radians, y x z per joint, depth-first)
            | translation of each free root (3 per free chain, world x y z, length units) ]

Each entry has a kind (``dof_kind``): ``DOF_HISTOGRAM`` entries are joint angles whose
histograms decide plausibility (Eq. 6) and set the step scale s(H); ``DOF_RANGE`` entries are
values that only have to stay in ``[lo, hi]`` with a step scale of the range's standard
deviation (a free root's translation and its rotation *offsets*).

A free root (``Root.mode == "free"``) is placed per frame by a *seed* pose
(:mod:`kinematics.fit.placement`): a rotation ``root_rot`` (3, 3) and position ``root_pos`` (3,).
Its joint's three angle entries then hold rotation offsets ``δ`` from the seed, and its three
translation entries the offset from the seed position, both searched within the root's
windows; the root's world pose is ``T(root_pos + t) · root_rot · R(δ) · R^d``. The public
posture (:meth:`FitProblem.posture`) turns that back into absolute angles of the root
joint (``R(a) = root_rot · R(δ)``) and a root position, so results, plots and histograms see
plain Eq. 1 angles whatever the root mode.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import NamedTuple

import numpy as np

from kinematics._kernels import codes as _codes
from kinematics.cameras import CameraArrays, pack_cameras
from kinematics.errors import KinematicsError
from kinematics.model import Body, validate_body
from kinematics.model.histograms import Histogram
from kinematics.model.packing import pack_body
from kinematics.model.rotations import euler_yxz, rot_x, rot_y, rot_z

DOF_HISTOGRAM = _codes.DOF_HISTOGRAM
DOF_RANGE = _codes.DOF_RANGE

#: The world axis each rotation of Eq. 1 turns about (x=0, y=1, z=2), in AXIS_ORDER.
_WORLD_AXIS = {"x": 0, "y": 1, "z": 2}
_ELEMENTARY = {"x": rot_x, "y": rot_y, "z": rot_z}
_SQRT3 = float(np.sqrt(3.0))


class FoldedBody(NamedTuple):
    """A body in the kernels' folded layout (see :mod:`kinematics._kernels`).

    Shapes: ``nj`` joints, ``nm`` markers. Joint ``j`` keeps ``A'_j = A'_parent · pre_rot[j]
    · Π_e E(elem_axis[j, e], angle[elem_index[j, e]])`` and ``p_j = p_parent + A'_parent ·
    pre_trans[j] + A'_j · post_trans[j]``; markers sit at ``p_j + A'_j · marker_local``.
    A root joint with the ``ROOT_POSE`` flag is turned by its frame's seed rotation first and
    moved by the state entries ``slide_index[j] .. + 2``.
    """

    parent: np.ndarray  # (nj,) int64, -1 for roots
    chain: np.ndarray  # (nj,) int64
    pre_rot: np.ndarray  # (nj, 3, 3) G_j = Q_parent · R^s · L_j
    pre_trans: np.ndarray  # (nj, 3) g_j = Q_parent · t^s
    post_trans: np.ndarray  # (nj, 3) h_j = Q_j · T_j
    elem_axis: np.ndarray  # (nj, 3) int64 world axis (0 x, 1 y, 2 z) or -1
    elem_index: np.ndarray  # (nj, 3) int64 posture index of each elementary rotation
    joint_flags: np.ndarray  # (nj,) int64, G_IDENTITY | H_ZERO | ROOT_POSE bits
    marker_joint: np.ndarray  # (nm,) int64
    marker_local: np.ndarray  # (nm, 3) Q_j · (t^s + R^s m)
    slide_index: np.ndarray  # (nj,) int64 first state entry of the root's translation, or -1


class DofArrays(NamedTuple):
    """What the kernels need to move the state: the free entries (DOF_HISTOGRAM first), the
    step scale, histogram tables and kind of every entry, and its range."""

    free_idx: np.ndarray  # (n_free,) int64
    step: np.ndarray  # (n_state,)
    hist: np.ndarray  # (n_state, max_bins)
    nbins: np.ndarray  # (n_state,) int64
    dof_kind: np.ndarray  # (n_state,) int64
    lo: np.ndarray  # (n_state,)
    hi: np.ndarray  # (n_state,)


class Schedule(NamedTuple):
    """The annealing schedule and the per-frame procedure of ``fit_frames`` (plain numbers;
    :func:`schedule_of` builds it from :class:`~kinematics.fit.settings.AnnealParams`)."""

    th: float
    max_redraws: int
    n_end: int
    n_l: int
    n_tau: int
    tau0: float
    l0: float
    c_l: float
    c_tau: float
    eps: float
    seed: int
    reanalysis_threshold: float
    max_runs: int
    refine_steps: int
    refine_gate: float
    start_previous: bool
    max_unexplained: int  # -1: not used
    min_runs: int  # runs made even when the first is good (candidate postures)


class ErrorArgs(NamedTuple):
    """The error function's numbers (:class:`~kinematics.fit.settings.ErrorOptions`)."""

    bidirectional: bool
    weight: float
    cap: float
    penalty_cap: float
    one_to_one: bool


class FitOutputs(NamedTuple):
    """Output arrays of ``fit_frames`` for n frames."""

    angles: np.ndarray  # (n, n_state)
    error: np.ndarray  # (n,)
    view_error: np.ndarray  # (n, n_views)
    runs: np.ndarray  # (n,) int64
    iterations: np.ndarray  # (n,) int64
    pairs: np.ndarray  # (n,) int64
    run_angles: np.ndarray  # (n, max_runs, n_state) every run's result (refined)
    run_error: np.ndarray  # (n, max_runs) its E; NaN for runs not made

    @classmethod
    def empty(cls, n: int, n_state: int, n_views: int, max_runs: int = 1) -> FitOutputs:
        return cls(np.empty((n, n_state)), np.empty(n), np.empty((n, n_views)),
                   np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64),
                   np.empty((n, max_runs, n_state)), np.empty((n, max_runs)))


def schedule_of(params) -> Schedule:
    """:class:`Schedule` of an :class:`~kinematics.fit.settings.AnnealParams` (typed exactly, so
    the kernels compile once)."""
    p = params
    return Schedule(float(p.threshold), int(p.max_redraws), int(p.n_end), int(p.n_l),
                    int(p.n_tau), float(p.tau0), float(p.l0), float(p.c_l), float(p.c_tau),
                    float(p.epsilon), int(p.seed), float(p.reanalysis_threshold),
                    max(int(p.max_runs), int(p.candidates)),
                    int(p.refine_steps) if p.refine else 0,
                    float(p.refine_gate_px), p.start == "previous",
                    -1 if p.max_unexplained is None else int(p.max_unexplained),
                    int(p.candidates))


def error_args(options) -> ErrorArgs:
    """:class:`ErrorArgs` of an :class:`~kinematics.fit.settings.ErrorOptions`."""
    return ErrorArgs(bool(options.bidirectional), float(options.penalty_weight),
                     float(options.cap), float(options.penalty_cap), bool(options.one_to_one))




def free_root_chains(body: Body) -> list[int]:
    """Indices of the chains whose root is ``free``."""
    return [k for k, c in enumerate(body.chains) if c.root.free]


def fold_body(body: Body, angles_deg=None) -> FoldedBody:
    """Fold the constant parts of Eq. 1 into per-joint constants, once per fit.

    A joint's rotation ``Ry·Rx·Rz`` is split at its first and last free axis: the locked
    rotations before (L) go into the joint's constant ``G_j = Q_parent · R^s · L``; those after
    (S), with R^d, form ``Q_j = S · R^d``, which is folded into the joint's translation, its
    markers and its children. The rotations from the first to the last free axis stay
    (locked ones between them with their constant angle). Locked angles come from the body
    (or ``angles_deg``, shape (n_axes,), when given).
    """
    arrays = pack_body(body)
    refs = body.axis_refs()
    locked = body.locked_mask()
    values = np.deg2rad(body.mean_posture_deg() if angles_deg is None else angles_deg)
    nj = arrays.parent.size
    big_l, big_q = np.empty((nj, 3, 3)), np.empty((nj, 3, 3))
    elem_axis = np.full((nj, 3), -1, np.int64)
    elem_index = np.zeros((nj, 3), np.int64)
    for j in range(nj):
        idx = arrays.axis_index[j]
        free = [e for e in range(3) if not locked[idx[e]]]
        first, last = (free[0], free[-1]) if free else (3, 2)
        prefix, suffix = np.eye(3), np.eye(3)
        for e in range(3):
            rot = refs[idx[e]].axis.rot
            if e < first:
                prefix = prefix @ _ELEMENTARY[rot](values[idx[e]])
            elif e > last:
                suffix = suffix @ _ELEMENTARY[rot](values[idx[e]])
            else:
                elem_axis[j, e - first] = _WORLD_AXIS[rot]
                elem_index[j, e - first] = idx[e]
        big_l[j] = prefix
        big_q[j] = suffix @ arrays.post_rot[j]
    pre_rot = np.empty((nj, 3, 3))
    pre_trans = np.zeros((nj, 3))
    post_trans = np.empty((nj, 3))
    flags = np.zeros(nj, np.int64)
    slide = np.full(nj, -1, np.int64)
    free_chains = free_root_chains(body)
    for j in range(nj):
        p = arrays.parent[j]
        if p < 0:
            pre_rot[j] = big_l[j]
            c = int(arrays.chain[j])
            if c in free_chains:
                flags[j] |= _codes.ROOT_POSE
                slide[j] = body.n_axes + 3 * free_chains.index(c)
        else:
            pre_rot[j] = big_q[p] @ arrays.pre_rot[j] @ big_l[j]
            pre_trans[j] = big_q[p] @ arrays.pre_trans[j]
        post_trans[j] = big_q[j] @ arrays.post_trans[j]
        if np.array_equal(pre_rot[j], np.eye(3)):
            flags[j] |= _codes.G_IDENTITY
        if not post_trans[j].any():
            flags[j] |= _codes.H_ZERO
    local = np.einsum("mij,mj->mi", big_q[arrays.marker_joint], arrays.marker_local)
    return FoldedBody(arrays.parent, arrays.chain, np.ascontiguousarray(pre_rot), pre_trans,
                      post_trans, elem_axis, elem_index, flags, arrays.marker_joint,
                      np.ascontiguousarray(local.reshape(-1, 3)), slide)


def histogram_tables(histograms: Sequence[Histogram]) -> tuple[np.ndarray, np.ndarray,
                                                                np.ndarray]:
    """Histogram lookup tables for the kernels.

    Returns
    -------
    hist : ndarray, shape (n_axes, max_bins)
        Bin values, zero-padded.
    nbins : ndarray of int64, shape (n_axes,)
    step_rad : ndarray, shape (n_axes,)
        s(H_i) in radians: the step scale of Eq. 6.
    """
    nbins = np.array([h.n_bins for h in histograms], dtype=np.int64)
    hist = np.zeros((len(histograms), int(nbins.max(initial=1))))
    for i, h in enumerate(histograms):
        hist[i, : h.n_bins] = h.values
    step = np.deg2rad([h.std_deg() for h in histograms])
    return hist, nbins, np.asarray(step, dtype=float)


def kind_order(free, kind: np.ndarray) -> np.ndarray:
    """Free entries with the DOF_HISTOGRAM ones first (the annealing kernel's order)."""
    free = np.asarray(free, np.int64)
    return np.r_[free[kind[free] == DOF_HISTOGRAM], free[kind[free] != DOF_HISTOGRAM]].astype(
        np.int64)


def euler_yxz_from_matrix(m: np.ndarray) -> np.ndarray:
    """Angles (y, x, z) in radians with ``Ry·Rx·Rz = m`` (x in [-π/2, π/2])."""
    ax = np.arcsin(np.clip(-m[1, 2], -1.0, 1.0))
    ay = np.arctan2(m[0, 2], m[2, 2])
    az = np.arctan2(m[1, 0], m[1, 1])
    return np.array([ay, ax, az])


@dataclass(frozen=True, eq=False)
class FitProblem:
    """Everything a backend needs to fit a body to observations, packed once.

    Build with :meth:`FitProblem.build`. Arrays are the kernels' (radians for angles).

    Attributes
    ----------
    body, cameras, view_names
        What the problem was built from.
    folded : FoldedBody
    cams : CameraArrays
    n_axes, n_state : int
        Joint angles, and all state entries (angles + free-root translations).
    free_idx : (n_free,) int64
        State entries the fit moves (unlocked, unpinned angles; free-root offsets), the
        DOF_HISTOGRAM ones first.
    dof_kind, step, lo, hi : (n_state,)
        Kind of each entry, its step scale and its range (radians or length units).
    hist, nbins
        Histogram tables (rows for translation entries are unused).
    start : (n_state,)
        The start state (histogram means; free roots at their seed).
    mean_deg : (n_axes,)
        Histogram-mean posture (Sect. 3.1).
    pins : mapping label -> degrees
        Axes held at a value (e.g. a manual correction); never moved by the fit.
    """

    body: Body
    cameras: tuple
    view_names: tuple[str, ...]
    folded: FoldedBody
    cams: CameraArrays
    n_axes: int
    n_state: int
    free_idx: np.ndarray
    dof_kind: np.ndarray
    step: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    hist: np.ndarray
    nbins: np.ndarray
    start: np.ndarray
    mean_deg: np.ndarray
    free_chains: tuple[int, ...]
    root_axes: np.ndarray  # (n_free_chains, 3) angle entries of each free root joint
    windows: np.ndarray  # (n_free_chains, 2) translation window, rotation window (deg)
    pins: Mapping[str, float]

    @classmethod
    def build(cls, body: Body, cameras, windows=None) -> FitProblem:
        """Pack ``body`` and ``cameras`` (mapping name -> camera, or a sequence).

        ``windows`` (n_free_chains, 2) overrides the free roots' translation and rotation
        windows; default :func:`kinematics.fit.placement.root_windows`.
        """
        from kinematics.fit.placement import root_windows

        validate_body(body)
        if isinstance(cameras, Mapping):
            names = tuple(str(k) for k in cameras)
            cams = tuple(cameras.values())
        else:
            cams = tuple(cameras)
            names = tuple(getattr(c, "name", f"view{k}") for k, c in enumerate(cams))
        if not body.marker_names:
            raise KinematicsError(f"body '{body.name}' has no markers: nothing to fit",
                                  field="markers")
        na = body.n_axes
        free_chains = tuple(free_root_chains(body))
        ns = na + 3 * len(free_chains)
        mean_deg = body.mean_posture_deg()
        hist, nbins, step = histogram_tables(body.histograms())
        hist = np.vstack([hist, np.ones((ns - na, hist.shape[1]))])
        nbins = np.r_[nbins, np.full(ns - na, hist.shape[1], np.int64)]
        ranges = np.deg2rad(body.ranges_deg())
        lo = np.r_[ranges[:, 0], np.zeros(ns - na)]
        hi = np.r_[ranges[:, 1], np.zeros(ns - na)]
        step = np.r_[step, np.zeros(ns - na)]
        kind = np.full(ns, DOF_HISTOGRAM, np.int64)
        kind[na:] = DOF_RANGE
        start = np.r_[np.deg2rad(mean_deg), np.zeros(ns - na)]
        folded = fold_body(body, mean_deg)
        root_axes = np.zeros((len(free_chains), 3), np.int64)
        win = np.asarray(root_windows(body) if windows is None else windows, float)
        win = win.reshape(len(free_chains), 2)
        joints = pack_body(body)
        for q, c in enumerate(free_chains):
            j = int(np.flatnonzero((joints.chain == c) & (joints.parent < 0))[0])
            ix = joints.axis_index[j]
            root_axes[q] = ix
            w_t, w_r = win[q, 0], np.deg2rad(win[q, 1])
            tr = slice(na + 3 * q, na + 3 * q + 3)
            kind[ix] = DOF_RANGE
            lo[ix], hi[ix], step[ix], start[ix] = -w_r, w_r, w_r / _SQRT3, 0.0
            lo[tr], hi[tr], step[tr] = -w_t, w_t, w_t / _SQRT3
        locked = np.r_[body.locked_mask(), np.zeros(ns - na, bool)]
        free_idx = kind_order(np.flatnonzero(~locked), kind)
        if free_idx.size == 0:
            raise KinematicsError(f"body '{body.name}' has no free axis: nothing to fit",
                                  field="axes")
        c = np.ascontiguousarray
        return cls(body, cams, names, folded, pack_cameras(cams), na, ns, free_idx, kind,
                   c(step), c(lo), c(hi), c(hist), c(nbins), c(start), mean_deg, free_chains,
                   root_axes, win, {})

    @property
    def dofs(self) -> DofArrays:
        return DofArrays(self.free_idx, self.step, self.hist, self.nbins, self.dof_kind,
                         self.lo, self.hi)

    # -- pins -----------------------------------------------------------------------------
    def with_pins(self, pins: Mapping[str | int, float]) -> FitProblem:
        """The same problem with the given axes (``joint.axis`` labels or posture indices)
        held at the given values in degrees, clipped into their ranges: the fit never moves
        them (a manual correction)."""
        labels = self.body.axis_labels
        named = {}
        for k, v in pins.items():
            if isinstance(k, int | np.integer) and not isinstance(k, bool):
                if not 0 <= k < len(labels):
                    raise KinematicsError(f"no axis number {k}", field="pins")
                k = labels[int(k)]
            if k not in labels:
                raise KinematicsError(f"no such axis: {k}", field="pins")
            lo, hi = self.body.ranges_deg()[labels.index(k)]
            named[k] = float(np.clip(float(v), lo, hi))
        merged = {**self.pins, **named}
        held = {labels.index(k) for k in merged}
        free = kind_order([i for i in self.free_idx if int(i) not in held], self.dof_kind)
        if free.size == 0:
            raise KinematicsError("every axis is pinned: nothing to fit", field="pins")
        start = self.start.copy()
        for k, v in merged.items():
            if self.dof_kind[labels.index(k)] == DOF_HISTOGRAM:  # not a free root's offset
                start[labels.index(k)] = np.deg2rad(v)
        return replace(self, free_idx=free, pins=merged, start=start)

    # -- state <-> posture ------------------------------------------------------------------
    @property
    def n_chains(self) -> int:
        return len(self.body.chains)

    def identity_rotations(self, n: int | None = None) -> np.ndarray:
        """Root seed rotations for fixed and marker roots: identity, (n_chains, 3, 3) or
        (n, n_chains, 3, 3)."""
        shape = (self.n_chains, 1, 1) if n is None else (n, self.n_chains, 1, 1)
        return np.tile(np.eye(3), shape)

    def state(self, angles_deg, root_positions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Kernel state of a public posture.

        Parameters
        ----------
        angles_deg : (n_axes,) posture; locked axes are reset to their value, pinned ones
            to their pin.
        root_positions : (n_chains, 3)

        Returns
        -------
        state : (n_state,); root_pos : (n_chains, 3); root_rot : (n_chains, 3, 3)
            For a free root the seed is the posture itself (offsets zero).
        """
        a = np.asarray(angles_deg, dtype=float).copy()
        locked, pinned, values = self._held
        a[locked] = self.mean_deg[locked]
        a[pinned] = values
        rad = np.deg2rad(a)
        state = np.r_[rad, np.zeros(self.n_state - self.n_axes)]
        rot = self.identity_rotations()
        for q, c in enumerate(self.free_chains):
            ix = self.root_axes[q]
            rot[c] = euler_yxz(*rad[ix])
            state[ix] = 0.0
        pos = np.ascontiguousarray(np.asarray(root_positions, dtype=float))
        return np.ascontiguousarray(state), pos, rot

    @cached_property
    def _held(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What :meth:`state` resets: the (n_axes,) locked mask, and the pinned axes' indices
        and values (degrees). Computed once: each walks the body, and the path's re-fits ask
        for a state thousands of times a video."""
        labels = self.body.axis_labels
        return (self.body.locked_mask(), np.array([labels.index(k) for k in self.pins], np.int64),
                np.array(list(self.pins.values()), float))

    def posture(self, state, root_pos, root_rot) -> tuple[np.ndarray, np.ndarray]:
        """Public posture of a kernel state: angles (n_axes,) radians, absolute for free
        roots, and root positions (n_chains, 3) including free-root translations."""
        s = np.asarray(state, dtype=float)
        angles = s[: self.n_axes].copy()
        roots = np.array(root_pos, dtype=float, copy=True)
        for q, c in enumerate(self.free_chains):
            ix = self.root_axes[q]
            angles[ix] = euler_yxz_from_matrix(root_rot[c] @ euler_yxz(*s[ix]))
            roots[c] += s[self.n_axes + 3 * q: self.n_axes + 3 * q + 3]
        return angles, roots
