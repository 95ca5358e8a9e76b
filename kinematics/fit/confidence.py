"""What a fit's statuses rest on: the set-up checks before fitting and the noise model's test
of every frame (a part of :class:`~kinematics.fit.Fitter`).

The detections are checked when a fit is asked for (:func:`setup_check.detection_problems`);
the sample of ``auto_sample`` frames fitted once before the fit (the one that measures the
threshold; with ``start = "track"`` the first frames tracked) measures σ per view and is
checked as a sample of the set-up (:func:`setup_check.fit_problems`); then every frame is
judged by :func:`noise.verdict`. A problem refuses the fit (:class:`SetupError`) unless
``accept_setup``; accepted, it is kept in :attr:`setup_warnings`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import replace
from itertools import chain

import numpy as np

from kinematics.fit import noise, setup_check
from kinematics.fit.result import WITHIN, FrameResult, Status
from kinematics.observe.observations import Observations

#: Statuses the noise test may turn into ``failed``.
JUDGED = WITHIN | {Status.AMBIGUOUS}


class ConfidenceMixin:
    """The :class:`~kinematics.fit.Fitter`'s set-up checks and noise test."""

    def _problem(self, problems: list[str]) -> None:
        """Refuse on ``problems`` unless ``accept_setup``; accepted, keep them."""
        if not problems:
            return
        if not self.params.accept_setup:
            setup_check.refuse(problems)
        self.setup_warnings.extend(f"set-up check (accepted): {p}" for p in problems
                                   if f"set-up check (accepted): {p}" not in
                                   self.setup_warnings)

    def _shown(self, obs: Observations, frames) -> np.ndarray:
        """(len(frames), n_views) markers each view is expected to show (not marked hidden,
        not of another view's colour)."""
        nm = len(self.body.marker_names)
        frames = np.asarray(frames, np.int64)
        shown = np.full((len(frames), obs.n_views), nm, np.int64)
        if self.unseen is not None and self.unseen.shape[0] == obs.n_views:
            shown -= self.unseen.sum(axis=1)[None, :]
        marks = obs.marks(frames) if obs.kind != "cloud" else None
        if marks is not None:
            shown = nm - marks.sum(axis=2)
        return shown

    def check_setup(self, detections) -> None:
        """The set-up checks on ``detections`` (any form :meth:`iter_fit` takes), as
        :meth:`iter_fit` makes them before fitting: raises :class:`SetupError`, or with
        ``accept_setup`` adds to :attr:`setup_warnings`."""
        self._check_detections(self.observations(detections))

    def _check_detections(self, obs: Observations) -> None:
        """The set-up checks on the detections, before any fit."""
        if obs.n_views == 0 or obs.kind not in ("points", "keypoints"):
            return
        shown = np.ones((obs.n_views, len(self.body.marker_names)), bool)
        if self.unseen is not None and self.unseen.shape == shown.shape:
            shown = ~self.unseen
        self._problem(setup_check.detection_problems(obs, self.cameras, self.view_names,
                                                     shown, self.tuning))

    def _noise_judged(self, obs: Observations, idx, results: Iterable[FrameResult]
                      ) -> Iterator[FrameResult]:
        """``results`` (one per frame of ``idx``, in order), each judged by the noise model.
        σ is measured before the fit on the threshold's sample (:meth:`_measure_video`),
        or given (``noise_px``); where it is not (``start = "track"``), the first
        ``auto_sample`` fitted results are held back to measure it and to check the set-up
        on them."""
        p = self.params
        if p.noise_floor_px is None or obs.n_views == 0:
            yield from results
            return
        stream = zip(idx, results, strict=False)  # a cancelled fit yields fewer
        held: list[tuple[int, FrameResult]] = []
        for position, r in stream:  # the first result: the fit has measured σ, if it does
            held.append((int(position), r))
            if self._noise_measured or sum(h.runs > 0 for _, h in held) >= p.auto_sample:
                break
        if not self._noise_measured:
            self._measure_video(obs, held)
        if self.noise is None:  # too few frames to measure a video: E decides alone
            yield from (r for _, r in held)
            yield from (r for _, r in stream)
            return
        extras = self._extras(obs, idx)
        judged = ((int(position), self._judge(obs, int(position), r, extras)[0])
                  for position, r in chain(held, stream))
        yield from self._with_sd(obs, judged)

    def _measure_video(self, obs: Observations, held: list[tuple[int, FrameResult]]) -> None:
        """σ per view from fitted ``(position, result)`` pairs (unless ``noise_px`` gives it)
        and the set-up checked on them (:func:`setup_check.fit_problems`)."""
        p = self.params
        self._noise_measured = True
        if p.noise_floor_px is None or obs.n_views == 0:
            return
        if p.noise_px is not None and not obs.labelled:
            self.noise = noise.NoiseModel(np.full(obs.n_views, float(p.noise_px)), "given")
            return
        counted = [(pos, r) for pos, r in held if r.runs > 0]
        sigma = noise.measure_sigma([r.marker_residuals for _, r in counted],
                                    float(p.noise_floor_px), float(p.claim_gate_px),
                                    quantile=self.tuning.noise_sigma_quantile,
                                    free_axes=int(self.problem.free_idx.size))
        if sigma is None:
            return
        source = "measured"
        if p.noise_px is not None:  # labelled: the outliers are measured all the same
            sigma, source = np.full(obs.n_views, float(p.noise_px)), "given"
        residuals = [r.marker_residuals for _, r in counted]
        scale = (noise.measure_marker_scale(residuals, sigma, float(p.claim_gate_px),
                                            self.tuning.noise_sigma_quantile)
                 if source == "measured" else None)
        model = noise.NoiseModel(sigma, source, None, scale)
        outliers = (noise.usual_outliers(residuals, model.per_image(len(self.body.marker_names)),
                                         self.tuning.noise_gate_k, self.tuning.noise_p,
                                         self.tuning.noise_outlier_share)
                    if obs.labelled else None)
        self.noise = model._replace(outliers=outliers)
        if source == "given":
            return
        positions = np.array([pos for pos, _ in counted], np.int64)
        extras = self._extras(obs, positions)
        verdicts = [self._judge(obs, pos, r, extras)[1] for pos, r in counted]
        # the spacing test reads the residuals' core (their median): a tail of sliding skin
        # markers is no sign of a chain matched to random detections
        core = noise.measure_sigma([r.marker_residuals for _, r in counted],
                                   float(p.noise_floor_px), float(p.claim_gate_px),
                                   quantile=0.5, free_axes=int(self.problem.free_idx.size))
        self._problem(setup_check.fit_problems(
            self.view_names, core, setup_check.detection_spacing(obs, positions), verdicts,
            self.tuning, obs.labelled))

    def _extras(self, obs: Observations, positions) -> np.ndarray:
        """Per view, the extra detections the frames at ``positions`` usually show (ghosts)."""
        if obs.labelled or len(positions) == 0:
            return np.zeros(obs.n_views, np.int64)
        frames = np.asarray(positions, np.int64)
        return noise.usual_extras(obs.view_counts(frames), self._shown(obs, frames))

    def _judge(self, obs: Observations, position: int, r: FrameResult, extras: np.ndarray
               ) -> tuple[FrameResult, noise.Verdict | None]:
        """``r`` made ``failed`` where its residuals fail the noise test (``ambiguous``
        where too few of its markers are on a detection: :meth:`_few_matched`), and the
        verdict (None for a frame without a fit)."""
        if not r.runs or r.marker_residuals is None or r.marker_residuals.shape[0] == 0:
            return r, None
        frames = np.array([position], np.int64)
        res, t = r.marker_residuals, self.tuning
        sigma = self.noise.per_image(res.shape[1])
        counts, shown = obs.view_counts(frames)[0], self._shown(obs, frames)[0]
        args = (res, sigma, counts, shown, extras, len(self.problem.free_idx), t.noise_gate_k,
                t.noise_p, self.noise.outliers, float(self.params.claim_gate_px))
        v = noise.verdict(*args)
        if v.passed and v.excused and not obs.labelled:  # excused by a fused blob's gap?
            gate = noise.gate_px(res, sigma, t.noise_gate_k, t.noise_p)
            v = noise.verdict(*args, fused=self._fused(obs, position, r, gate))
        if not v.passed and r.status in JUDGED:
            r = replace(r, status=Status.FAILED)
        elif r.status in WITHIN and not obs.labelled and self._few_matched(obs, r, frames):
            r = replace(r, status=Status.AMBIGUOUS)
        return r, v

    def _fused(self, obs: Observations, position: int, r: FrameResult, gate: np.ndarray
               ) -> np.ndarray:
        """Per view, the missing detections that fused blobs account for in ``r``'s posture
        (:func:`noise.fused_markers`)."""
        state, pos, rot = self.problem.state(r.angles_deg, r.root_positions)
        proj = self._project_state(state, pos, rot)
        arrays = obs.arrays(np.array([position], np.int64))
        return noise.fused_markers(proj, arrays.points, arrays.offsets, gate,
                                   np.isfinite(r.marker_residuals))

    def _few_matched(self, obs: Observations, r: FrameResult, frames: np.ndarray) -> bool:
        """Whether at most ``Tuning.few_matched_share`` of the markers the views show lie
        on a detection (within the noise gate) in two views (in one, with one view showing
        detections): unlabelled detections that few can be any of the markers, and a
        posture that puts other markers on them fits as well (a free mouse seen by 3 of its
        6 markers; a detection near a marker in one view of three is a coincidence as often
        as not)."""
        res = r.marker_residuals  # the plain gate: a wider one would call more markers on
        gate = self.tuning.noise_gate_k * self.noise.per_image(res.shape[1])
        need = min(2, int((obs.view_counts(frames)[0] > 0).sum()))
        on = int(((np.isfinite(res) & (res <= gate)).sum(axis=0) >= max(need, 1)).sum())
        shown = int(self._shown(obs, frames)[0].max())
        return on <= self.tuning.few_matched_share * shown
