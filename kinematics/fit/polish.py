"""The final polish: a chosen posture fitted by least squares to its cloud points, and
limbs held where nothing places their markers (matching in 3D).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import replace

import numpy as np

from kinematics._kernels import codes as _codes
from kinematics._kernels import refine as _rk
from kinematics._kernels.records import FrameObs
from kinematics.fit.result import WITHIN, Candidate, FrameResult, Status
from kinematics.fit.settings import AnnealParams
from kinematics.observe.cloud import SUPPORT_PX
from kinematics.observe.observations import Observations


class PolishMixin:
    """The :class:`~kinematics.fit.Fitter`'s final polish."""

    def _final_polish(self, obs: Observations, idx, results: Iterable[FrameResult]
                      ) -> Iterator[FrameResult]:
        """``results`` (one per frame of ``idx``, in order) as :meth:`_polished` leaves
        them, a frame with a held limb ``ambiguous`` where its runs put that limb apart or
        the next frame's runs do (:func:`held_limb`): a wrong stretch that every run fits alike
        (a fly's hind leg through 6 cameras, frames 357-360) ends where they part. The next
        frame only, so a fit resumed from a checkpoint decides every frame as the whole fit
        did."""
        apart = self._apart(self.params)
        pending = None
        for position, r in zip(idx, results, strict=False):  # a cancelled fit yields fewer
            r, spread = self._polished(obs, int(position), r)
            if pending is not None:
                follows = r.frame == pending[0].frame + 1
                yield held_limb(*pending, apart, spread if follows else None)
            pending = r, spread
        if pending is not None:
            yield held_limb(*pending, apart)

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
        markers (None: no limb held; :func:`held_limb` flags the frame). Matching in 3D only;
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
        _rk.assign_pairs(_codes.OBJ_CLOUD_ONE, np.empty((0, len(mk), 2)), mk, arrays.points,
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
                objective, cams = _codes.OBJ_CLOUD_ONE, self._kernel_inputs(arrays)[0]
            else:
                objective, cams = _codes.OBJ_CLOUD_VIEWS, pr.cams
            _rk.refine_posture(state, moved, pr.dofs, self.tuning.polish_steps, gate, pos,
                               rot, folded, cams, cams.kind,
                               FrameObs(objective, arrays.points, gates, arrays.offsets, cloud))
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

def _unclaimed(cameras, cloud: np.ndarray, points: np.ndarray, offsets: np.ndarray
               ) -> np.ndarray:
    """Which of one frame's detections (``points``, ``offsets`` per view) support no point
    of its ``cloud``: farther than :data:`~kinematics.observe.cloud.SUPPORT_PX` (the support the
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

def held_limb(r: FrameResult, spread: float | None, apart: float,
          next_spread: float | None = None) -> FrameResult:
    """A fit within the threshold whose limb has a marker that neither a cloud point nor two
    views place (``spread`` not None: how far apart its runs put that limb's markers, inf
    with one run): ``ambiguous`` where the runs put it more than ``apart`` apart, or the next
    frame's runs do (``next_spread``, where it holds a limb too): nothing in the frame says
    where that limb is, unless every run found it in one place (through 3 cameras 120 of
    the fly's 660 frames held a limb, 104 of them right, most with runs within 0.07 mm;
    docs/benchmarks.md, 'Markers without a point placed by the views')."""
    if spread is None or r.status not in WITHIN:
        return r
    if spread > apart or (next_spread is not None and next_spread > apart):
        return replace(r, status=Status.AMBIGUOUS)
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
