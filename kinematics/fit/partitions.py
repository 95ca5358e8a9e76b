"""Partitions of a body: which state entries are annealed together (parts that share no
marker, each with its joints and markers) and the start search's stages within each part
(:func:`partitions_of`, used by :class:`~kinematics.fit.Fitter`'s dispatch)."""

from __future__ import annotations

import weakref
from typing import NamedTuple

import numpy as np

from kinematics.fit.problem import FitProblem, kind_order
from kinematics.model.fk import forward_kinematics
from kinematics.model.packing import pack_body

#: _first_moved of each problem (a problem is immutable; partitions are built per fit block)
_FIRST_MOVED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class Partitions(NamedTuple):
    """Which entries are annealed together (``fit_frames``): partition p moves
    ``dofs[dof_off[p]:dof_off[p + 1]]`` and reaches joints ``bounds[p, 0]:bounds[p, 1]`` and
    markers ``bounds[p, 2]:bounds[p, 3]`` (its subtree, contiguous in depth-first order), of
    which ``bounds[p, 2]:bounds[p, 4]`` are on its own joints (a trunk's, before its limbs)."""

    bounds: np.ndarray  # (n_parts, 5) int64
    dof_off: np.ndarray  # (n_parts + 1,) int64
    dofs: np.ndarray  # (n_free,) int64
    rounds: int
    claim_gate: float
    samples: int = 0  # postures drawn per beam and stage for a partition's start (round 1)
    # Stages of the start search: partition p's stages are stage_off[p]:stage_off[p + 1];
    # stage s draws the entries stage_dofs[stage_dof_off[s]:stage_dof_off[s + 1]] (one
    # joint's) and is scored by the partition's markers before stage_mark[s].
    stage_off: np.ndarray = np.zeros(1, np.int64)
    stage_dof_off: np.ndarray = np.zeros(1, np.int64)
    stage_dofs: np.ndarray = np.zeros(0, np.int64)
    stage_mark: np.ndarray = np.zeros(0, np.int64)
    stage_joint: np.ndarray = np.zeros(0, np.int64)  # the first joint a stage's entries move
    # Runs agree when every marker of one lies within this distance (length units) of the
    # other's; a frame runs until its best run is confirmed by another (0: not used).
    confirm: float = 0.0


def _first_moved(problem: FitProblem, n_postures: int = 4, step_deg: float = 1.0
                 ) -> np.ndarray:
    """For each state entry, the first marker (in marker order) whose position it changes
    in some of ``n_postures`` random postures within the ranges; the number of markers for
    entries that move none (e.g. a roll about a marker's own axis). Free-root entries (past
    the axes) move every marker of their chain: their chain's first marker."""
    if problem in _FIRST_MOVED:
        return _FIRST_MOVED[problem]
    body = problem.body
    na, nm = body.n_axes, problem.folded.marker_joint.size
    lo, hi = body.ranges_deg().T
    rng = np.random.default_rng(0)
    base = rng.uniform(lo, hi, (n_postures, na))
    moved = np.full(problem.n_state, nm, np.int64)
    ref = forward_kinematics(body, base).markers
    for i in range(na):
        if lo[i] == hi[i]:
            continue
        bumped = base.copy()
        bumped[:, i] = np.where(bumped[:, i] + step_deg <= hi[i], bumped[:, i] + step_deg,
                                bumped[:, i] - step_deg)
        shift = np.abs(forward_kinematics(body, bumped).markers - ref).max(axis=(0, 2))
        hit = np.flatnonzero(shift > 1e-9 * (1.0 + np.abs(ref).max()))
        moved[i] = hit[0] if hit.size else nm
    mj = problem.folded.marker_joint
    for j, k in enumerate(problem.folded.slide_index):
        if k >= 0:  # a free root's translation: the chain's markers follow the root joint
            below = np.flatnonzero(mj >= j)
            moved[k: k + 3] = below[0] if below.size else nm
    _FIRST_MOVED[problem] = moved
    return moved


def _stages(problem: FitProblem, parts, owner: np.ndarray) -> tuple[np.ndarray, ...]:
    """The start search's stages of each partition (:class:`Partitions`): its free entries
    grouped by the first marker they move, root side first; a stage is scored by the
    markers before the next stage's first (those the entries drawn so far place), the last
    by all of the partition's. An entry that moves no marker before a later stage's (a
    joint's roll about the limb's own axis) is drawn with the stage that first shows it.
    A stage's draws recompute the kinematics from its first joint (of ``owner``, the joint
    of each state entry) on."""
    moved = _first_moved(problem)
    stage_off, dof_off, dofs, mark, first_joint = [0], [0], [], [], []
    for (j0, _, m0, m1, _), entries in parts:
        firsts = sorted({int(min(max(moved[i], m0), m1)) for i in entries})
        for k, first in enumerate(firsts):
            stage = [int(i) for i in entries if min(max(moved[i], m0), m1) == first]
            dofs += stage
            dof_off.append(len(dofs))
            mark.append(firsts[k + 1] if k + 1 < len(firsts) else m1)
            first_joint.append(max(j0, min(int(owner[i]) for i in stage)))
        stage_off.append(len(mark))
    return (np.array(stage_off, np.int64), np.array(dof_off, np.int64),
            np.array(dofs, np.int64), np.array(mark, np.int64),
            np.array(first_joint, np.int64))


def partitions_of(problem: FitProblem, mode: str = "auto", rounds: int = 2,
                  claim_gate: float = 10.0, samples: int = 0) -> Partitions:
    """The partitions of a problem's free entries.

    ``"auto"``: every chain is annealed on its own; within a chain, the trunk (the root joint
    and the joints below it down to the first joint with several child joints, free-root
    translations included) comes first and reaches the whole chain, then each child subtree
    is partitioned the same way (hierarchical, root before limbs; in the first round a trunk
    is scored by its own markers only, its limbs not fitted yet). ``"none"``, or a body that
    is a single unbranched chain: one partition with every free entry (the paper).
    ``samples``: the start search of :func:`kinematics._kernels.anneal.anneal_partitions`.
    """
    f = problem.folded
    nj, nm = f.parent.size, f.marker_joint.size
    free = problem.free_idx
    axis_index = pack_body(problem.body).axis_index
    owner = np.full(problem.n_state, -1, np.int64)  # the joint each state entry belongs to
    for j in range(nj):
        owner[axis_index[j]] = j
        if f.slide_index[j] >= 0:
            owner[f.slide_index[j]: f.slide_index[j] + 3] = j
    whole = Partitions(np.array([[0, nj, 0, nm, nm]], np.int64),
                       np.array([0, free.size], np.int64), free.copy(), int(rounds),
                       float(claim_gate), int(samples),
                       *_stages(problem, [((0, nj, 0, nm, nm), [int(i) for i in free])], owner))
    if mode == "none":
        return whole
    children: list[list[int]] = [[] for _ in range(nj)]
    for j in range(nj):
        if f.parent[j] >= 0:
            children[f.parent[j]].append(j)
    end = np.arange(1, nj + 1)  # one past the last joint of each subtree (depth-first order)
    for j in range(nj - 1, -1, -1):
        if children[j]:
            end[j] = max(end[c] for c in children[j])
    parts: list[tuple[tuple[int, int, int, int, int], list[int]]] = []

    def visit(top: int) -> None:
        trunk, j = [top], top
        while len(children[j]) == 1:
            j = children[j][0]
            trunk.append(j)
        marks = np.flatnonzero((f.marker_joint >= top) & (f.marker_joint < end[top]))
        m0, m1 = (int(marks[0]), int(marks[-1]) + 1) if marks.size else (0, 0)
        own = np.flatnonzero((f.marker_joint >= top) & (f.marker_joint <= j))
        m_own = int(own[-1]) + 1 if own.size else m1  # the trunk's own markers come first
        dofs = [int(i) for i in free if owner[i] in trunk]
        if dofs:
            parts.append(((top, int(end[top]), m0, m1, m_own), dofs))
        for c in children[j]:
            visit(c)

    for j in range(nj):
        if f.parent[j] < 0:
            visit(j)
    if len(parts) <= 1:
        return whole
    dofs = [kind_order(d, problem.dof_kind) for _, d in parts]
    off = np.r_[0, np.cumsum([len(d) for d in dofs])].astype(np.int64)
    return Partitions(np.array([b for b, _ in parts], np.int64), off,
                      np.concatenate(dofs).astype(np.int64), int(rounds), float(claim_gate),
                      int(samples), *_stages(problem, parts, owner))
