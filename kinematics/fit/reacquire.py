"""Free roots that re-acquire: a placement the detections contradict is searched afresh.

A free root's seed follows the previous frame's (:func:`placement.register_root`): once its
constellation is matched to the wrong candidates (a left-right mirror of the pelvis, a hip
marker taken for a knee's), the prediction keeps matching them and the wrong placement is
held. Here each fitted frame is judged by the noise model as the status will be; a frame
that fails it has its free roots placed again without a prediction (every pose of the
constellation among the frame's 3D candidates, :func:`placement.search_poses`), the whole
body fitted from each, and the best one that passes taken. The new placement then becomes
the prediction the following frames are placed from, each re-fitted while its new fit is
better than the one it had; where both agree the track has merged and the stage falls
silent again. Frames before a re-acquired one that were held by the same wrong placement
(:attr:`Tuning.reacquire_back` at most, the stretch since it began) are placed backwards from
it and re-fitted the same way.

Only unlabelled detections (blobs) place roots by registration; labelled keypoints and 3D
points name their markers, so their placement cannot be held wrong. Rigid constellations only
(three root markers or more): a root placed by one marker has no pose to search.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator
from itertools import chain

import numpy as np

from kinematics.fit import placement
from kinematics.fit.result import FrameResult, Status
from kinematics.observe.observations import Observations


class ReacquireMixin:
    """The :class:`~kinematics.fit.Fitter`'s re-acquisition of free roots."""

    def _reacquiring(self, obs: Observations) -> list[tuple[int, placement.RootModel]]:
        """(chain, its model) of each free root that re-acquires on ``obs``; empty where
        none does."""
        pr = self.problem
        if (not pr.free_chains or obs.labelled or obs.n_views < 2 or self.tuning.reacquire_back
                < 0 or self._seeds is None or self._run_params is None):
            return []
        out = []
        for q, c in enumerate(pr.free_chains):
            model = placement.RootModel(self.body, c, float(pr.windows[q, 0]))
            if model.rigid:
                out.append((q, model))
        return out

    def _reacquired(self, obs: Observations, idx, results: Iterable[FrameResult]
                    ) -> Iterator[FrameResult]:
        """``results`` (one per frame of ``idx``, in order) with the free roots re-acquired
        where their placement fails the noise test (see the module)."""
        results = iter(results)
        first = next(results, None)  # the fit has placed its roots (_iter) once it yields
        if first is None:
            return
        models = self._reacquiring(obs)
        if not models:
            yield first
            yield from results
            return
        results = chain([first], results)
        seeds_pos, seeds_rot = self._seeds
        extras = self._extras(obs, idx)
        back = int(self.tuning.reacquire_back)
        held: deque = deque()  # (k, result, passed) of the frames not yet yielded
        track = None  # {q: (R, t)}: the prediction of a re-acquired placement
        for k, r in enumerate(results):
            position = int(idx[k])
            passed = self._passes(obs, position, r, extras)
            if track is not None:
                r, passed, track = self._follow(obs, k, position, r, passed, track, models,
                                                seeds_pos, seeds_rot, extras)
            if not passed and track is None and r.runs:
                found = self._search(obs, k, position, r, models, seeds_pos, seeds_rot,
                                     extras)
                if found is not None:
                    r, passed, track = found
                    held = self._back(obs, idx, held, track, models, seeds_pos, seeds_rot,
                                      extras)
            held.append((k, r, passed))
            while len(held) > back:
                yield held.popleft()[1]
        yield from (h[1] for h in held)

    def _passes(self, obs: Observations, position: int, r: FrameResult, extras) -> bool:
        """Whether ``r`` passes the noise test (without a noise model: whether it is not
        ``failed``)."""
        if not r.runs:
            return True
        if self.noise is None:
            return r.status != Status.FAILED
        judged, verdict = self._judge(obs, position, r, extras)
        return judged.status != Status.FAILED and (verdict is None or verdict.passed)

    def _refit(self, obs: Observations, k: int, position: int, poses: list[dict],
               seeds_pos, seeds_rot, extras) -> list[tuple[FrameResult, bool]]:
        """Frame ``position`` fitted from each of ``poses`` ({q: (R, t)} replacing those
        free roots' seeds), polished, with whether each passes."""
        if not poses:
            return []
        pr = self.problem
        n = len(poses)
        roots = np.repeat(seeds_pos[k][None], n, axis=0)
        rots = np.repeat(seeds_rot[k][None], n, axis=0)
        for i, pose in enumerate(poses):
            for q, (rot, t) in pose.items():
                c = pr.free_chains[q]
                roots[i, c], rots[i, c] = t, rot
        sel = np.full(n, position, np.int64)
        fits = self._fit_block(obs, sel, sel, np.ascontiguousarray(roots),
                               np.ascontiguousarray(rots), pr.start,
                               np.arange(n + 1, dtype=np.int64),
                               self._run_params)
        out = []
        for f in fits:
            f = self._polished(obs, position, f)[0]
            out.append((f, self._passes(obs, position, f, extras)))
        return out

    @staticmethod
    def _better(new: tuple[FrameResult, bool], old: tuple[FrameResult, bool]) -> bool:
        """A fit that passes beats one that fails; between equals, the lower E."""
        (n, n_ok), (o, o_ok) = new, old
        if n_ok != o_ok:
            return n_ok
        return bool(n.error < o.error)

    def _search(self, obs, k, position, r, models, seeds_pos, seeds_rot, extras):
        """A fresh placement of frame ``position``: (result, passed, track) of the best pose
        that passes and beats ``r``, or None."""
        cands = self._candidates_3d(obs, position)
        if cands is None:
            return None
        poses: list[dict] = []
        for q, model in models:
            c = self.problem.free_chains[q]
            here = _markers(model, seeds_rot[k, c], seeds_pos[k, c])
            for rot, t, *_ in placement.search_poses(model, cands):
                if np.abs(_markers(model, rot, t) - here).max() > 2.0 * model.tol:
                    poses.append({q: (rot, t)})
        best = None
        for pose, fit in zip(poses, self._refit(obs, k, position, poses, seeds_pos,
                                                seeds_rot, extras), strict=True):
            if fit[1] and (best is None or self._better(fit, best[0])):
                best = fit, pose
        if best is None or not self._better(best[0], (r, False)):
            return None
        (fit, passed), pose = best
        return fit, passed, pose

    def _follow(self, obs, k, position, r, passed, track, models, seeds_pos, seeds_rot,
                extras):
        """Frame ``position`` placed from ``track`` (a re-acquired placement's prediction)
        and re-fitted: the better of that fit and ``r``, and the track to carry on (None
        once it has merged with the seeds' or lost its constellation)."""
        pose = self._registered(obs, k, position, track, models, seeds_pos, seeds_rot)
        if not pose:  # the track's constellation lost (None), or merged with the seeds ({})
            return r, passed, None
        fit = self._refit(obs, k, position, [pose], seeds_pos, seeds_rot, extras)[0]
        if self._better(fit, (r, passed)):
            return fit[0], fit[1], {**track, **pose}
        return r, passed, None

    def _registered(self, obs, k, position, track, models, seeds_pos, seeds_rot):
        """The free roots of frame ``position`` placed from ``track``: {q: (R, t)} of those
        whose pose differs from the seed's ({} where none does), or None where the track's
        constellation is not found."""
        cands = self._candidates_3d(obs, position)
        if cands is None:
            return None
        pose = {}
        for q, model in models:
            if q not in track:
                continue
            seed = placement.register_root(model, cands, track[q])
            if seed is None:
                return None
            c = self.problem.free_chains[q]
            here = _markers(model, seeds_rot[k, c], seeds_pos[k, c])
            if np.abs(_markers(model, seed[0], seed[1]) - here).max() > 2.0 * model.tol:
                pose[q] = (seed[0], seed[1])
        return pose

    def _back(self, obs, idx, held: deque, track, models, seeds_pos, seeds_rot, extras
              ) -> deque:
        """The held frames before a re-acquired one placed backwards from ``track`` and
        re-fitted while the new fit is better (the stretch the wrong placement held)."""
        items = list(held)
        for j in range(len(items) - 1, -1, -1):
            k, r, passed = items[j]
            if not r.runs:
                break
            pose = self._registered(obs, k, int(idx[k]), track, models, seeds_pos,
                                    seeds_rot)
            if not pose:
                break
            fit = self._refit(obs, k, int(idx[k]), [pose], seeds_pos, seeds_rot, extras)[0]
            if not self._better(fit, (r, passed)):
                break
            items[j] = (k, fit[0], fit[1])
            track = {**track, **pose}
        return deque(items)

    def _candidates_3d(self, obs: Observations, position: int) -> np.ndarray | None:
        """The 3D candidates of frame ``position`` (:func:`placement.triangulate_candidates`),
        None where there are none."""
        gate = (placement.DEFAULT_GATE_PX if self.params.root_gate_px is None
                else float(self.params.root_gate_px))
        views = [np.asarray(v, float) for v in obs.frame_views(position)]
        cands, _ = placement.triangulate_candidates(self.cameras, views, gate)
        return cands if cands is not None and len(cands) else None


def _markers(model: placement.RootModel, rot: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The root's markers placed by pose (R, t)."""
    return model.local @ np.asarray(rot).T + np.asarray(t)
