"""The path through time: one candidate per frame chosen over a fixed-lag window,
implausible frames re-fitted from their neighbours, ambiguous ones flagged.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from kinematics.fit import temporal
from kinematics.fit.result import Candidate, FrameResult, Status
from kinematics.fit.settings import AnnealParams
from kinematics.fit.status import marker_images
from kinematics.observe.observations import Observations


class PathMixin:
    """The :class:`~kinematics.fit.Fitter`'s path through time."""

    def _over_time(self, obs: Observations, idx, roots, rots, chunks, starts,
                   before: Sequence[FrameResult], p: AnnealParams) -> Iterator[FrameResult]:
        """Choose one candidate per frame by the path through time (fixed-lag: a frame is
        decided once ``Tuning.path_lag`` later frames are fitted), re-fit implausible frames from
        their neighbours' postures, and flag ambiguous ones; ``before``: the results decided
        just before ``idx`` (a resumed fit's)."""
        lag = self.tuning.path_lag
        scale = self._posture_scale()
        images = marker_images(obs, idx, len(self.body.marker_names))
        pending: list[FrameResult] = []
        # the last frames decided: the left anchor, and context for finding cuts
        history = list(before)[-self.tuning.cut_context:]
        done = 0  # frames of idx already yielded
        for chunk in chunks:
            pending.extend(chunk)
            while len(pending) > 2 * lag:
                # a window of fixed length, so the choice does not depend on the chunk size
                decided = self._decide(obs, idx, roots, rots, pending[:2 * lag], done, images,
                                       scale, history, starts, p)
                out, pending = decided[:lag], pending[lag:]
                done += lag
                history = (history + out)[-self.tuning.cut_context:]
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
            Tuning.redo_jump_ratio times the window's typical change (at least
            Tuning.redo_jump_min, at most
            ``cap``); with ``markers`` (:func:`path_markers`), only where some marker moves
            more than ``seen_ratio`` times the window's typical largest marker move. Second,
            the same with at most Tuning.edge_seen_ratio for that ratio."""
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
            limit = min(cap, max(self.tuning.redo_jump_min, self.tuning.redo_jump_ratio * typical))
            big = jumps > limit
            edge = big.copy()
            if markers is not None:  # ... that the markers show
                moves = np.linalg.norm(markers[1:] - markers[:-1], axis=-1).max(axis=-1)
                moves[breaks] = np.nan  # no move across a cut
                seen = np.nanmedian(moves) if np.isfinite(moves).any() else 0.0
                with np.errstate(invalid="ignore"):
                    big &= ~(moves <= seen_ratio * seen)
                    edge &= ~(moves <= min(seen_ratio, self.tuning.edge_seen_ratio) * seen)
            return big, edge

        def jumping() -> set[int]:
            """Frames next to a jump of the chosen path (:func:`jumps_over` within
            Tuning.redo_jump per partition): re-fitted."""
            at = np.flatnonzero(jumps_over(self.tuning.redo_jump * n_parts)[0])
            return {int(k) for i in at for k in (i - 1, i) if k >= 0}

        def still_jumping(markers: np.ndarray) -> tuple[set[int], set[int]]:
            """Frames next to a jump the re-fits left that the markers show, or, where two
            jumps at most ``temporal.WRONG_STRETCH`` apart (or a jump and a sequence's start
            or end) bound a stretch, the stretch's frames instead: those to flag, and the
            frame just outside each such bound (which a kink there must not flag)."""
            big, edge = jumps_over(np.inf, markers, self.tuning.jump_seen_ratio)
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
            # Tuning.edge_seen_ratio: the locust's were 5x the typical move)
            ends = np.flatnonzero(breaks)
            begins = ends if anchor is not None and not breaks[0] else np.r_[0, ends]
            at_edge = np.flatnonzero(edge)
            for i in at_edge:
                if i in bounds:
                    continue
                s = begins[begins < i].max(initial=-1)
                e = ends[ends > i].min(initial=len(window))
                # the shorter side, where both are short (both where they are as long)
                head = i - s if s >= 0 and not ((at_edge > s) & (at_edge < i)).any()\
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
                    + self.tuning.refit_keep_px * max(images[first + k], 1))

        def carried(i: int, step: int, seed: Candidate) -> Iterator[tuple[int, Candidate]]:
            """The seed's posture refined at frame i, then each result refined at the next
            frame in the same direction while it fits about as well and is new there: a
            wrong stretch a lower-E minimum holds (a ghost in an occluded marker's place)
            is crossed with the movement, where a cold anneal would fall back into it."""
            k = i
            while 0 <= k < len(window) and window[k].candidates and abs(k - i) <=\
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
                                                  p.candidates + self.tuning.refit_candidates)))
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
        # than Tuning.jump_seen_ratio x the window's median such distance
        off_line = np.full(len(mk), np.nan)  # the frame before the window first
        off_line[1:-1] = np.linalg.norm(mk[1:-1] - (mk[:-2] + mk[2:]) / 2.0,
                                        axis=-1).max(axis=-1)
        cut = np.r_[breaks, False]  # not across a cut in the movement
        off_line[1:][cut[:-1] | cut[1:]] = np.nan
        typical_off = np.nanmedian(off_line) if np.isfinite(off_line).any() else 0.0
        with np.errstate(invalid="ignore"):
            seen = ~(off_line <= self.tuning.jump_seen_ratio * typical_off)
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
        margin = min(p.ambiguous_px, max(self.tuning.ambiguous_floor_px, 0.5 * typical))
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
            near &= moved[i] - moved[i, choice[i]] <= self.tuning.ambiguous_movement
            ambiguous = bool(near.any()) or i in flagged
            cands = (chosen, *(c for k, c in enumerate(r.candidates) if k != choice[i]))
            if np.array_equal(chosen.angles_deg, r.angles_deg) and np.array_equal(
                    chosen.root_positions, r.root_positions):
                # the frame's own best: scored already, only the flag may change
                ambiguous = ambiguous and r.status not in (Status.FAILED, Status.NO_DETECTIONS)
                results.append(replace(r, candidates=cands,
                                       status=Status.AMBIGUOUS if ambiguous else r.status))
                continue
            results.append(self._frame_result(
                obs, int(idx[first + i]), r.frame, chosen.state, chosen.seed_pos,
                chosen.seed_rot, p,
                runs=r.runs, iterations=r.iterations, pairs=r.refined_pairs or 0,
                candidates=cands, ambiguous=ambiguous, confirmed_only=r.status == Status.OK))
        return results
