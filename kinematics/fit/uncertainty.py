"""How sure each fitted angle is: a standard deviation per axis and frame (a part of
:class:`~kinematics.fit.Fitter`, the step after the noise test).

At the fitted posture the pair residuals (each model marker and its detection within
``noise_gate_k`` σ) have a Jacobian J over the free axes; with the noise model's σ per view
the covariance of the angles is ``(J^T Σ^-1 J)^-1`` (the Cramér-Rao bound, which the least
squares optimum of refinement attains for Gaussian centroid noise). Where a frame is
``ambiguous`` its candidates' spread widens it: ``sd² + (spread / 2)²``. Locked and pinned
axes get 0; frames without a fit or without pairs NaN; so do the axes the matched markers
leave undetermined (:func:`undetermined`). The kernel is
:func:`kinematics._kernels.uncertainty.information_frames`, its twin
:func:`kinematics.fit.refine.cramer_rao_bound`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import replace
from itertools import islice

import numpy as np

from kinematics._kernels import codes as _codes
from kinematics._kernels import uncertainty as _uk
from kinematics.fit.problem import euler_yxz_from_matrix
from kinematics.fit.result import FrameResult, Status
from kinematics.model.rotations import euler_yxz
from kinematics.observe.observations import Observations

#: Results given their sd together (one parallel kernel call).
BATCH = 64

#: Step of the numerical derivative of a free root's absolute Euler angles, radians.
_EULER_STEP = 1e-6


def _euler_derivative(seed: np.ndarray) -> np.ndarray:
    """d(absolute Euler angles) / d(offsets) at zero offsets for a free root whose rotation
    is ``seed · R(offsets)`` (the kernels' layout), by central differences (3, 3)."""
    out = np.empty((3, 3))
    for k in range(3):
        d = np.zeros(3)
        d[k] = _EULER_STEP
        hi = euler_yxz_from_matrix(seed @ euler_yxz(*d))
        lo = euler_yxz_from_matrix(seed @ euler_yxz(*(-d)))
        out[:, k] = ((hi - lo + np.pi) % (2 * np.pi) - np.pi) / (2 * _EULER_STEP)
    return out


def undetermined(info: np.ndarray, rcond: float = 1e-9, share: float = 0.01) -> np.ndarray:
    """(n, n_free) bool: the free entries of each frame's information matrix (n, n_free,
    n_free) that lie in its null space (eigenvalues below ``rcond`` times the largest) by more
    than ``share`` of their weight: more axes than the matched markers determine (a free body
    with two of its markers seen), so any value of them fits alike."""
    w, v = np.linalg.eigh(info)
    null = w < rcond * np.maximum(w[:, -1:], 1e-300)
    return np.einsum("nij,nj->ni", v ** 2, null.astype(float)) > share


class UncertaintyMixin:
    """The :class:`~kinematics.fit.Fitter`'s per-axis standard deviations."""

    def _with_sd(self, obs: Observations, judged: Iterable[tuple[int, FrameResult]]
                 ) -> Iterator[FrameResult]:
        """Each ``(position, result)`` of ``judged`` as its result with ``sd_deg``, in order,
        a batch at a time; unchanged without a noise model or for labelled 3D points."""
        it = iter(judged)
        if self.noise is None or obs.objective == _codes.OBJ_POINTS3D:
            yield from (r for _, r in it)
            return
        while batch := list(islice(it, BATCH)):
            yield from self._batch_sd(obs, batch)

    def _batch_sd(self, obs: Observations, batch: Sequence[tuple[int, FrameResult]]
                  ) -> list[FrameResult]:
        pr = self.problem
        n = len(batch)
        state = np.full((n, pr.n_state), np.nan)
        pos = np.zeros((n, pr.n_chains, 3))
        rot = pr.identity_rotations(n)
        for k, (_, r) in enumerate(batch):
            if r.runs > 0 and np.isfinite(r.angles_deg).all():
                state[k], pos[k], rot[k] = pr.state(r.angles_deg, r.root_positions)
        positions = np.array([p for p, _ in batch], np.int64)
        cams, arrays = self._kernel_inputs(obs.arrays(positions))
        sigma = np.asarray(self.noise.sigma_px, float)
        scale = np.r_[1.0 / sigma[: cams.kind.shape[0]], 1.0 / sigma.mean()]
        gate = float(self.tuning.noise_gate_k * sigma.max())
        nf = pr.free_idx.size
        info = np.zeros((n, nf, nf))
        pairs = np.zeros(n, np.int64)
        _uk.information_frames(state, pos, rot, pr.folded, cams, pr.free_idx, gate, arrays,
                               np.ascontiguousarray(scale), info, pairs)
        cov = np.linalg.pinv(info, hermitian=True)
        loose = undetermined(info)
        fitted = (pairs > 0) & np.isfinite(state[:, 0])
        return [self._given_sd(r, cov[k], rot[k], loose[k]) if fitted[k] else r
                for k, (_, r) in enumerate(batch)]

    def _given_sd(self, r: FrameResult, cov: np.ndarray, rot: np.ndarray, loose: np.ndarray
                  ) -> FrameResult:
        """``r`` with its sd; NaN for the axes the detections leave undetermined (``loose``
        free entries: any value of them fits alike, where a pseudo-inverse would say 0)."""
        sd = self._axis_sd(cov, rot, r)
        if not loose.any():
            return replace(r, sd_deg=sd)
        pr = self.problem
        free = pr.free_idx
        angle = free < pr.n_axes
        sd[free[loose & angle]] = np.nan
        for q in range(len(pr.free_chains)):  # a free root's Euler angles mix its offsets
            ix = pr.root_axes[q]
            if loose[np.isin(free, ix)].any():
                sd[ix] = np.nan
        return replace(r, sd_deg=sd)

    def _axis_sd(self, cov: np.ndarray, rot: np.ndarray, r: FrameResult) -> np.ndarray:
        """Per-axis sd in degrees from the free entries' covariance ``cov`` (radians²)."""
        pr = self.problem
        free = pr.free_idx
        var = np.zeros(pr.n_axes)
        angle = free < pr.n_axes
        var[free[angle]] = np.diag(cov)[angle]
        for q, c in enumerate(pr.free_chains):  # a free root: offsets → absolute angles
            ix = pr.root_axes[q]
            cols = [np.flatnonzero(free == i) for i in ix]
            if all(col.size for col in cols):  # all three free (in ix's order)
                cols = np.concatenate(cols)
                d = _euler_derivative(rot[c])
                var[ix] = np.einsum("ki,ij,kj->k", d, cov[np.ix_(cols, cols)], d)
        sd = np.degrees(np.sqrt(np.clip(var, 0.0, None)))
        if r.status == Status.AMBIGUOUS and len(r.candidates) > 1:
            sd = np.hypot(sd, 0.5 * r.spread_deg)
        return sd
