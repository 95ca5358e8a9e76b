"""Candidate postures: the distinct postures among a frame's runs, comparing postures and
their markers, and the cold re-fit from a neighbour's posture that the path and tracking use.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numba
import numpy as np

from kinematics._kernels import frames as _frames
from kinematics.fit import temporal
from kinematics.fit.problem import (
    FitOutputs,
    schedule_of,
)
from kinematics.fit.result import Candidate
from kinematics.fit.settings import AnnealParams
from kinematics.model.fk import forward_kinematics
from kinematics.model.rotations import euler_yxz
from kinematics.observe.observations import Observations


class CandidatesMixin:
    """The :class:`~kinematics.fit.Fitter`'s candidate postures and re-fits."""

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
        runs (default ``Tuning.refit_share``); ``counted``, if given, gets the iterations it ran
        appended."""
        share = self.tuning.refit_share if share is None else share
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
        _frames.fit_frames(np.array([0, 1], np.int64), np.array([position + 1_000_003], np.int64),
                       np.ascontiguousarray(pos[None]), np.ascontiguousarray(rot[None]),
                       state, self.problem.folded, cams, self.problem.dofs,
                       schedule_of(local), self._error_args(p, arrays.objective), arrays,
                       parts, out)
        if counted is not None:
            counted.append(int(out.iterations[0]))
        if not out.runs[0]:
            return None
        return self._candidates(out.run_angles[0], out.run_error[0], pos, rot, local)[0]

def concurrent_fits() -> bool:
    """Whether kernels may run from several Python threads at once: numba's OpenMP and TBB
    threading layers take parallel kernels from several threads, its workqueue layer aborts
    the process (and before the first parallel kernel the layer is not known)."""
    try:
        return numba.threading_layer() in ("omp", "tbb")
    except ValueError:
        return False
