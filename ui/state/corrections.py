"""Manual correction: pinned axes, accepting, carrying a posture to the neighbours,
interpolating, alternative postures and marker drags (a part of :class:`ui.state.Session`)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import replace

import numpy as np

from kinematics.errors import LocatedError
from kinematics.fit.result import WITHIN
from kinematics.model import Body
from ui import adapters
from ui.state import backend
from ui.state.history import Edit
from ui.state.workers import TaskWorker

#: Re-fitting forward/backward stops where a frame's error exceeds JUMP_FACTOR times the
#: median error of the frames carried so far plus JUMP_PX: the carried posture no longer
#: fits there (a loose bar alone let it overwrite right frames with wrong ones).
JUMP_FACTOR = 3.0
JUMP_PX = 2.0

#: Re-fitting forward/backward takes the carried posture refined in place instead of the
#: anneal's result when the two differ by more than this (degrees, all axes): the anneal
#: went to another branch (a mirror posture with a lower E). Below it they are the same
#: posture, and the anneal's is taken (refining alone drifted over 40 frames).
BRANCH_DEG = 20.0
#: ... and only when the refined posture's E is at most this times the anneal's: a mirror
#: posture that flickering ghosts favour is a few per cent lower; a refinement stuck far
#: from the data (2-5 times the anneal's E, seen on a keypoint project) is no branch.
BRANCH_E_RATIO = 1.25

#: An alternative posture chosen with A carries to a neighbour (Session._carry_choice) only
#: when the neighbour kept a candidate nearer the chosen posture than this share of its own
#: posture's distance: clearly the same branch, not a candidate close to both.
CARRY_RATIO = 0.5


def carried_or_annealed(annealed: backend.FrameResult, carried: backend.FrameResult,
                        previous_deg) -> backend.FrameResult:
    """Of a frame re-fitted from its neighbour's posture ``previous_deg``: the anneal's
    result, unless it left the neighbour's branch (more than :data:`BRANCH_DEG` from the
    neighbour's posture refined in place, ``carried``, which is nearer the neighbour) for
    an E not much lower (:data:`BRANCH_E_RATIO`): then the refined posture, with the
    anneal's kept as its alternative candidate."""
    d = adapters.angle_distance
    if (carried.error <= BRANCH_E_RATIO * annealed.error
            and d(annealed.angles_deg, carried.angles_deg) > BRANCH_DEG
            and d(carried.angles_deg, previous_deg) < d(annealed.angles_deg, previous_deg)):
        # the anneal's posture stays the frame's alternative (A swaps to it)
        return replace(carried, candidates=(*carried.candidates[:1],
                                            *annealed.candidates[:1]))
    return annealed



def pinned_result(fitter, body: Body, dets, frame: int, angles, roots,
                  pins: Mapping[int, float], refit: bool) -> backend.FrameResult:
    """The ``corrected`` result of a frame set by hand (thread-safe: no session state).

    ``dets`` is the frame's fitting input (:func:`ui.state.backend.frame_input`). ``pins``
    (posture index -> degrees, clipped to the ranges) are held while the other free axes
    are fitted from ``angles`` (:meth:`kinematics.fit.Fitter.with_pins`); without
    ``refit``, or with nothing left free, the posture is taken as it is and only E is
    computed. A frame without observations keeps the user's posture.
    """
    angles = adapters.clamp_to_range(body, angles)
    lo, hi = body.ranges_deg().T
    for k, v in pins.items():
        angles[k] = float(np.clip(v, lo[k], hi[k]))
    seed = fitter.params.seed
    result = None
    if refit and any(k not in pins for k in adapters.free_axes(body)):
        result = fitter.with_pins(pins).fit_frame(dets, frame, start_deg=angles,
                                                  root_positions=roots)
    if result is None or result.status == "no-detections":
        if backend.has_observations(dets):
            error, per_view = backend.posture_error(fitter, angles, dets, roots)
        else:
            error, per_view = np.nan, np.full(fitter.n_views, np.nan)
        result = backend.manual_result(frame, angles, roots, error, per_view, seed)
    return backend.with_status(result, backend.CORRECTED)



class CorrectionsMixin:
    """Corrections of postures by hand and their pins."""

    # -- manual correction --------------------------------------------------------------
    def correct(self, values_deg: Mapping[int, float], refit: bool = True,
                frame: int | None = None, label: str | None = None) -> bool:
        """Set axes of a frame by hand and hold them while the rest is re-fitted.

        The axes given (posture indices -> degrees) join those already pinned in this frame;
        the fitter then holds the pinned axes at the user's values
        (:meth:`kinematics.fit.Fitter.with_pins`) while it fits the others, starting from
        the current posture.
        Without ``refit``, or when nothing is left free, the posture is taken as it is and
        only its error is computed. The result has status ``corrected``; undo restores the
        frame's previous result.
        """
        frame = self.frame if frame is None else int(frame)
        if self.body is None or self.model is None:
            self.error.emit("no chain and cameras to correct")
            return False
        angles, roots, _ = self.posture(frame)
        pins = {**self.pins.get(frame, {}), **{int(k): float(v) for k, v in values_deg.items()}}
        label = label or "set " + ", ".join(self.body.axis_labels[k] for k in values_deg)
        fitter = self._fitter_or_report()
        if fitter is None:
            return False
        dets = self.frame_input(frame)

        def finish(result) -> None:
            edit = Edit(label)
            edit.record_result(frame, self.results.get(frame), result)
            edit.record_pins(frame, self.pins.get(frame), pins)
            self._freshen(edit, [frame])
            self.preview_angles = None
            self._apply(edit, 1)
            self._push(edit)
            self.status.emit(f"frame {frame} corrected: error {result.error:.2f} px")

        def work(_worker):
            return pinned_result(fitter, self.body, dets, frame, angles, roots, pins, refit)

        if refit and any(k not in pins for k in adapters.free_axes(self.body)):
            return self.run_task(work, finish,
                                 f"re-fitting frame {frame} around the correction …")
        try:
            finish(work(None))
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        return True

    def accept(self, frames: Iterable[int] | None = None) -> int:
        """Mark the postures of fitted frames right (status ``corrected``: *Fit all* leaves
        them alone, a re-fit forward stops there); one undo step. Returns how many."""
        if self.busy:
            self.status.emit("wait for the running task to finish (or cancel it) first")
            return 0
        frames = [self.frame] if frames is None else [int(f) for f in frames]
        edit = Edit("")
        for f in frames:
            r = self.results.get(f)
            if r is not None and r.status != backend.CORRECTED and np.all(
                    np.isfinite(r.angles_deg)):
                edit.record_result(f, r, backend.with_status(r, backend.CORRECTED))
        n = len(edit.results)
        edit.label = f"accept frame {frames[0]}" if frames == [min(edit.results, default=-1)] \
            else f"accept {n} frames"
        self._apply(edit, 1)
        self._push(edit)
        self.status.emit(f"accepted {n} frame{'s' if n != 1 else ''}" if n else
                         "nothing to accept (frames not fitted, or already corrected)")
        return n

    def _held(self) -> set[int]:
        """Frames the user has set or accepted: corrected, or with pinned axes."""
        return ({f for f, r in self.results.items() if r.status == backend.CORRECTED}
                | {f for f, p in self.pins.items() if p})

    def refit_from(self, direction: int, frame: int | None = None) -> bool:
        """Carry the frame's posture to its neighbours (``direction`` +1 forward, -1
        backward): each next frame is fitted starting from the previous frame's result, in
        the background, until a frame's error exceeds the threshold or jumps (above
        :data:`JUMP_FACTOR` times the carried frames' median plus :data:`JUMP_PX`: the
        posture no longer carries, even under a loose bar; that frame is left as it was), a
        frame corrected, accepted or pinned by hand, or the end of the video. One undo step;
        a cancel keeps the frames done."""
        frame = self.frame if frame is None else int(frame)
        step = 1 if direction > 0 else -1
        angles, _, source = self.posture(frame)
        if source != "fit":
            self.error.emit(f"frame {frame} has no posture to carry: fit or correct it first")
            return False
        missing = self._missing_input()
        if missing:
            self.error.emit(missing)
            return False
        fitter = self._fitter_or_report()
        if fitter is None:
            return False
        frames = list(range(frame + step, self.n_frames if step > 0 else -1, step))
        if not frames:
            self.status.emit("no frame beyond this one")
            return False
        held, threshold = self._held(), self.threshold
        detections = self.fit_detections
        known = {f: np.asarray(r.root_positions) for f, r in self.results.items()}

        start = self.results.get(frame)
        carried = [start.error] if start is not None and np.isfinite(start.error) else []

        def jumps(r) -> bool:  # against the frames carried so far
            return bool(carried) and r.error > JUMP_FACTOR * float(np.median(carried)) + JUMP_PX

        def work(worker: TaskWorker):
            prev_angles = angles
            tracked = None
            for k, f in enumerate(frames):
                worker.check_cancel()
                if f in held:
                    worker.summary = f"stopped at frame {f} (set by hand)"
                    return
                if f not in known and tracked is None:  # roots of frames never fitted
                    tracked = fitter.track_roots(detections)
                root = known[f] if f in known else tracked[f]
                data = backend.frame_input(detections, f, fitter.n_views)
                r = fitter.fit_frame(data, f, start_deg=prev_angles, root_positions=root)
                # an anneal, even one started from the carried posture, can fall into
                # another branch with a lower E (a mirror posture): then the carried
                # posture refined in place is taken, if it fits
                kept = fitter.refine_frame(data, f, prev_angles, root_positions=root)
                if kept is not None and kept.error <= threshold and not jumps(kept):
                    r = carried_or_annealed(r, kept, prev_angles)
                if not r.error <= threshold:
                    worker.summary = (f"stopped at frame {f}: error {r.error:.2f} px above the "
                                      f"threshold, left as it was")
                    return
                if jumps(r):
                    worker.summary = (f"stopped at frame {f}: error jumps to {r.error:.2f} px "
                                      f"(carried frames {np.median(carried):.2f}), left as it "
                                      "was")
                    return
                carried.append(r.error)
                worker.publish([r])
                worker.report(k + 1, len(frames))
                prev_angles = r.angles_deg
            worker.summary = "reached the end"

        where = "forward" if step > 0 else "backward"
        return self._run_frames(work, f"re-fit {where} from frame {frame}",
                                f"re-fitting {where} from frame {frame} …")

    def interpolate(self, first: int, last: int, refit: bool = True) -> bool:
        """Set the frames between two corrected frames by linear interpolation of their
        pinned axes (of every free axis when neither end pins one) and, with ``refit``, fit
        the other axes of each frame with those held (background, one undo step). The
        frames get status ``corrected`` with the interpolated axes pinned."""
        first, last = sorted((int(first), int(last)))
        ends = [self.results.get(first), self.results.get(last)]
        if any(r is None or r.status != backend.CORRECTED for r in ends):
            self.error.emit(f"interpolation needs corrected frames at both ends; frames "
                            f"{first} and {last} are not both corrected")
            return False
        if last - first < 2:
            self.status.emit("no frame between the two ends")
            return False
        axes = sorted(set(self.pins.get(first, {})) | set(self.pins.get(last, {}))
                      ) or adapters.free_axes(self.body)
        fitter = self._fitter_or_report()
        if fitter is None:
            return False
        (a0, r0, _), (a1, r1, _) = self.posture(first), self.posture(last)
        plan = []
        for f in range(first + 1, last):
            t = (f - first) / (last - first)
            angles, _, source = self.posture(f)
            roots = (self.posture(f)[1] if source == "fit" else (1 - t) * r0 + t * r1)
            pins = {k: float((1 - t) * a0[k] + t * a1[k]) for k in axes}
            plan.append((f, angles, roots, pins, self.frame_input(f)))
        body = self.body

        def work(worker: TaskWorker):
            for k, (f, angles, roots, pins, dets) in enumerate(plan):
                worker.check_cancel()
                r = pinned_result(fitter, body, dets, f, angles, roots, pins, refit)
                worker.publish([(r, pins)])
                worker.report(k + 1, len(plan))

        return self._run_frames(work, f"interpolate frames {first}–{last}",
                                f"interpolating {len(plan)} frames …")

    def swap_candidate(self, frame: int | None = None) -> bool:
        """Replace the frame's posture by its next candidate posture (the alternatives the
        fit kept: an ``ambiguous`` frame's mirror posture); again cycles through them. The
        result is ``corrected`` (the user chose it). The choice carries to the neighbours
        that took the same wrong branch (:meth:`_carry_choice`); A again on that stretch
        cycles it as one. One undo step restores every frame it changed."""
        if self.busy:
            self.status.emit("wait for the running task to finish (or cancel it) first")
            return False
        frame = self.frame if frame is None else int(frame)
        current = self.results.get(frame)
        if current is None or len(current.candidates) < 2 or self.model is None:
            self.status.emit(f"frame {frame} has no alternative posture")
            return False
        # A again on a stretch the latest A set: the stretch cycles as one (with two
        # candidates, back to where it was)
        stretch = sorted(g for g, r in self._swapped.items() if self.results.get(g) is r)
        try:
            fitter = self._fitter()
            result = self._chosen_result(fitter, frame, current, 1)
            carried = ([self._chosen_result(fitter, g, self.results[g], 1) for g in stretch
                        if g != frame and len(self.results[g].candidates) >= 2]
                       if frame in stretch else
                       self._carry_choice(fitter, frame, current, result))
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        edit = Edit(f"frame {frame}: alternative posture")
        for r in (result, *carried):
            edit.record_result(r.frame, self.results.get(r.frame), r)
        self._freshen(edit, [r.frame for r in (result, *carried)])  # E of today's chain
        self._apply(edit, 1)
        self._push(edit)
        self._swapped = {r.frame: r for r in (result, *carried)
                         if r.status == backend.CORRECTED}
        swapped = sorted(r.frame for r in carried if r.status == backend.CORRECTED)
        flagged = sorted(r.frame for r in carried if r.status != backend.CORRECTED)
        also = "".join([
            f"; carried to frame{'s' if len(swapped) > 1 else ''} "
            f"{', '.join(map(str, swapped))}" if swapped else "",
            f"; frame{'s' if len(flagged) > 1 else ''} {', '.join(map(str, flagged))} still "
            "on the other branch: needs a look" if flagged else ""])
        self.status.emit(f"frame {frame}: alternative posture {len(current.candidates) - 1} "
                         f"of {len(current.candidates)}, error {result.error:.2f} px{also}")
        return True

    def _chosen_result(self, fitter, frame: int, current: backend.FrameResult, k: int
                       ) -> backend.FrameResult:
        """``current`` with its candidate ``k`` chosen: ``corrected``, E of that posture on
        the frame's input, the candidates cycled so that ``k`` is first."""
        cycled = (*current.candidates[k:], *current.candidates[:k])
        chosen = cycled[0]
        error, per_view = backend.posture_error(fitter, chosen.angles_deg,
                                                self.frame_input(frame), chosen.root_positions)
        return replace(backend.manual_result(
            frame, chosen.angles_deg, chosen.root_positions, error, per_view,
            self.params.seed if self.params else 0), candidates=cycled)

    def _carry_choice(self, fitter, frame: int, before: backend.FrameResult,
                      after: backend.FrameResult) -> list[backend.FrameResult]:
        """The neighbours that follow a swap at ``frame``. The fit chose a branch (say the
        mirror posture) for a stretch of frames, not one frame: walking away from ``frame``
        each way, a neighbour swaps too while its posture is nearer the branch given up
        than the one chosen and it kept a candidate clearly nearer the chosen one
        (:data:`CARRY_RATIO`); it stops at a frame set by hand, one without such a
        candidate, or one already on the chosen branch. A frame it stops at that is still
        on the branch given up is flagged ``ambiguous`` (it needs a look)."""
        held, out = self._held(), []
        for step in (1, -1):
            old = np.asarray(before.angles_deg, float)
            new = np.asarray(after.angles_deg, float)
            g = frame + step
            while 0 <= g < self.n_frames and g not in held:
                r = self.results.get(g)
                if r is None:
                    break
                here = np.asarray(r.angles_deg, float)
                to_new = adapters.angle_distance(here, new)
                if not adapters.angle_distance(here, old) < to_new:
                    break  # on the chosen branch already
                dist = np.array([adapters.angle_distance(np.asarray(c.angles_deg, float),
                                                         new) for c in r.candidates] or [np.nan])
                k = int(np.nanargmin(dist)) if np.isfinite(dist).any() else 0
                if k == 0 or not dist[k] < CARRY_RATIO * to_new:
                    # still on the branch given up, and nothing to swap to: a look is
                    # needed (it may be fitted right from its neighbour, F9)
                    if r.status in WITHIN:
                        out.append(backend.with_status(r, "ambiguous"))
                    break
                out.append(self._chosen_result(fitter, g, r, k))
                old, new = here, np.asarray(r.candidates[k].angles_deg, float)
                g += step
        return out

    def drag_marker(self, view: int, marker: int, target_xy, refit: bool = True,
                    frame: int | None = None) -> bool:
        """Correct a frame (the current one by default) so that ``marker`` appears at
        ``target_xy`` in ``view``.

        The one axis that brings the marker nearest the target is found by
        :func:`ui.adapters.solve_marker_drag` and set; then every axis the marker depends on
        is pinned (so the marker stays where it was dropped) and the rest of the chain, the
        axes beyond the marker and other chains, is re-fitted as in :meth:`correct`.
        """
        if self.body is None or not self.cameras:
            return False
        frame = self.frame if frame is None else int(frame)
        angles, roots, _ = self.posture(frame)
        upstream = adapters.marker_axes(self.body, marker)
        # once a drag (or a nudge) pinned every axis above the marker, moving it again
        # may turn any of them: the user is placing this marker
        free = [k for k in upstream if k not in self.pins.get(frame, {})] or upstream
        solution = adapters.solve_marker_drag(self.body, self.cameras[view], angles, roots,
                                              marker, target_xy, axes=free)
        if solution is None:
            self.status.emit("no free axis moves this marker")
            return False
        values = {k: float(angles[k]) for k in upstream}
        values[solution.axis] = solution.value_deg
        return self.correct(values, refit=refit, frame=frame,
                            label=f"drag {self.body.marker_names[marker]} in "
                                  f"{self.view_names[view]}")

    def release_pins(self, frame: int | None = None) -> None:
        """Forget which axes of a frame were set by hand (undoable)."""
        frame = self.frame if frame is None else frame
        if self.pins.get(frame):
            edit = Edit("release pinned axes")
            edit.record_pins(frame, self.pins[frame], None)
            self._apply(edit, 1)
            self._push(edit)
            self.postureChanged.emit()

