"""A fitted posture scored and judged: E, marker residuals, the status, and the
re-analysis threshold measured on the video (``threshold_mode`` 'auto').
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from kinematics._kernels import error2d as _error2d
from kinematics._kernels import error3d as _error3d
from kinematics.fit.result import FrameResult, Status
from kinematics.fit.settings import AnnealParams
from kinematics.observe.observations import Observations


class StatusMixin:
    """The :class:`~kinematics.fit.Fitter`'s scoring of a fitted posture."""

    def _video_sample(self, obs: Observations, idx, roots, rots
                      ) -> tuple[np.ndarray, list[FrameResult]]:
        """Up to ``auto_sample`` frames of ``idx`` (evenly spaced) fitted once (one run, one
        candidate): ``(positions, results)``, what the threshold of ``threshold_mode``
        'auto' (:meth:`_threshold_of`) and the noise model are measured on."""
        p = self.params
        pick = np.unique(np.linspace(0, len(idx) - 1, min(p.auto_sample, len(idx))).astype(int))
        once = replace(p, max_runs=1, candidates=1, threshold_mode="absolute")
        res = self._fit_block(obs, idx[pick], idx[pick], np.ascontiguousarray(roots[pick]),
                              np.ascontiguousarray(rots[pick]), self.problem.start,
                              np.arange(len(pick) + 1, dtype=np.int64), once)
        return np.asarray(idx[pick], np.int64), res

    def _threshold_of(self, obs: Observations, frames, errors) -> float:
        """The re-analysis threshold on E measured on the video itself (threshold_mode
        'auto') from the E of these frames' fits (:meth:`_video_sample`): the threshold per
        marker image is median + auto_k · 1.4826 · MAD of their E per marker image (the
        10-90 % range / 2.563 where the MAD collapses below 1 % of the median), at least
        auto_floor_px; times the marker images of a frame seen in every view (a cloud's or
        3D points': one per marker)."""
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
            status = Status.NO_DETECTIONS
        elif err > p.reanalysis_threshold or too_many:
            status = Status.FAILED
        elif ambiguous:
            status = Status.AMBIGUOUS
        else:  # the runs made for candidates, or to confirm a result, are not re-analyses
            status = (Status.OK if runs <= p.candidates or confirmed_only
                      else Status.REANALYSED)
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
            unexplained = int(_error2d.nearest_residuals(proj, pts, view_off, seen, float(gate),
                                                    out))
        if obs.kind == "cloud":
            unexplained = int(_error3d.count_unexplained_cloud(mk, arrays.points3d[0], gate))
        return out, unexplained

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
