"""``start = "track"``: each frame annealed cold from the previous result, fitted in full
where the track is lost, limbs merged between fits and segments mended.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numba
import numpy as np

from kinematics.fit.flags import flag_e_spikes
from kinematics.fit.result import Candidate, FrameResult, Status, reanalysed
from kinematics.fit.settings import AnnealParams
from kinematics.fit.status import marker_images
from kinematics.observe.observations import Observations


class TrackingMixin:
    """The :class:`~kinematics.fit.Fitter`'s ``start = "track"``."""

    def _track(self, obs: Observations, idx: np.ndarray, roots, rots, p: AnnealParams,
               cancel: Callable[[], bool] | None) -> Iterator[FrameResult]:
        """``start="track"``: :meth:`_track_frames`, E spikes flagged (:func:`flag_e_spikes`)."""
        yield from flag_e_spikes(self._track_frames(obs, idx, roots, rots, p, cancel),
                                 tuning=self.tuning)

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
            r, status=Status.FAILED, threshold=float(p.reanalysis_threshold))

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
        replaces ``tracked`` where its E is below ``Tuning.track_prefer`` times the tracked E,
        or within the threshold where the tracked E is not (:meth:`_taken`)."""
        again = self._fit_full(obs, idx, roots, rots, i, p)
        if tracked is None:
            return reanalysed(again)
        merged = self._merged(obs, int(idx[i]), tracked, again, p)
        best = min((again, merged) if merged is not None else (again,),
                   key=lambda r: r.error if np.isfinite(r.error) else np.inf)
        if not (best.error < self.tuning.track_prefer * tracked.error
                or best.error <= p.reanalysis_threshold < tracked.error):
            return tracked
        return self._taken(tracked, best)

    @staticmethod
    def _taken(old: FrameResult, new: FrameResult) -> FrameResult:
        """``new`` in place of ``old``: ``reanalysed`` where it is ``ok``, its runs and
        iterations added to ``old``'s (a result counts every run made for its frame)."""
        return replace(reanalysed(new), runs=old.runs + new.runs,
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
        (by ``Tuning.track_merge_px``, :meth:`_part_scores`) taken from ``other``, refined in
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
        better = np.flatnonzero(b < a - self.tuning.track_merge_px)
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
        ``Tuning.track_jump`` times the median of the last ``Tuning.track_memory`` kept, plus
        ``Tuning.track_jump_px`` per marker image) is fitted in full too (:meth:`_fit_again`).
        Where that replaces the track of a body of several partitions, the frames before
        are tracked back from it (:meth:`_retrack`): a track that crept off a leg until E
        jumped gets it back. So are they from a tracked frame whose E falls below
        ``Tuning.track_drop`` times that median: a track that lost a leg and found it again."""
        out = [self._fit_full(obs, idx, roots, rots, lo, p)]
        kept_e = [out[0].error] if np.isfinite(out[0].error) else []
        limbs = self._limbs(p)
        for i in range(lo + 1, hi):
            r = self._step(obs, int(idx[i]), out[-1], p)
            images = int(marker_images(obs, idx[i:i + 1], len(self.body.marker_names))[0])
            # (NaN before any E is kept: then E neither jumps nor falls)
            recent = float(np.median(kept_e[-self.tuning.track_memory:])) if kept_e else np.nan
            jump = self.tuning.track_jump * recent + self.tuning.track_jump_px * max(images, 1)
            if r is None or not r.error <= p.reanalysis_threshold or r.error > jump:
                tracked, r = r, self._fit_again(obs, idx, roots, rots, i, p, r)
                mend = r is not tracked  # a cut: mend the frames that led to it
            else:
                mend = r.error < self.tuning.track_drop * recent  # found a leg it had lost?
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
        ``Tuning.track_share`` of the schedule from its posture; None where it has none."""
        if not np.all(np.isfinite(prev.angles_deg)):
            return None
        seed = Candidate(prev.angles_deg, prev.root_positions, prev.error, None, None, None)
        counted: list[int] = []
        c = self._refit_from(obs, position, seed, p, share=self.tuning.track_share, counted=counted)
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
          E below ``Tuning.track_prefer`` times the step's: a merge keeps the result's wrong
          leg where that leg scores well on a neighbour's points (fly, 3 cameras, frame 224).
        - A stretch of such frames replaces the results once its summed E is below
          Tuning.track_prefer times theirs. One frame's E is noise: a leg on a neighbour's points
          can fit a frame as well as the right posture and the next frames worse (fly,
          3 cameras, frames 224-253).
        - Where the re-track meets the results (every model marker within
          ``ambiguous_move`` segment lengths of the result's, and E not below Tuning.track_prefer
          times its), the stretch before is taken where its summed E is below theirs at
          all, and the re-track stops. It also stops after ``Tuning.track_window`` frames not
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
            prefer = self.tuning.track_prefer
            best = (merged if merged is not None and merged.error < prefer * step.error
                    else step)
            if (self._marker_moves(result, [best])[0] <= near
                    and not best.error < self.tuning.track_prefer * result.error):
                # met: the stretch before joins the results here without their jump, so it
                # need only fit better
                if pending and alt_e < res_e:
                    self._take(results, taken, pending)
                return
            pending.append(best)
            alt_e += best.error
            res_e += result.error
            if alt_e < self.tuning.track_prefer * res_e:
                taken = self._take(results, taken, pending)
                pending, alt_e, res_e = [], 0.0, 0.0
            elif len(pending) >= self.tuning.track_window:
                return

    @staticmethod
    def _take(results: list[FrameResult], first: int, stretch: list[FrameResult]) -> int:
        """``results[first:]`` replaced by ``stretch`` (:meth:`_taken`), in place; returns
        the index after it."""
        end = first + len(stretch)
        results[first:end] = [TrackingMixin._taken(r, s) for r, s in
                              zip(results[first:end], stretch, strict=True)]
        return end
