"""The readable twin of the annealing kernel: one run written plainly (Sect. 2.3, Eq. 6)
on the kernels' random stream, for tests and benchmarks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from kinematics.fit.error_function import projection_error
from kinematics.fit.settings import AnnealParams
from kinematics.model import Body
from kinematics.model.fk import forward_kinematics_reference

_MASK64 = (1 << 64) - 1


_GOLDEN = 0x9E3779B97F4A7C15


def _mix64(z: int) -> int:
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


class SplitMix64:
    """The kernels' random stream in plain Python: same (seed, frame, run) -> same draws."""

    def __init__(self, seed: int, frame: int = 0, run: int = 0) -> None:
        s = _mix64((seed + _GOLDEN) & _MASK64)
        s = _mix64(s ^ ((frame * 0xD1B54A32D192ED03) & _MASK64))
        self.state = _mix64(s ^ ((run * 0x8CB92BA72F3D8DD7 + _GOLDEN) & _MASK64))

    def uniform(self) -> float:
        """Next draw, uniform in [0, 1) with 53 bits."""
        self.state = (self.state + _GOLDEN) & _MASK64
        return (_mix64(self.state) >> 11) * 2.0**-53


def anneal_reference(body: Body, cameras, detections_frame, params: AnnealParams | None = None,
                     *, frame: int = 0, run: int = 0, start_deg=None, root_positions=None
                     ) -> tuple[np.ndarray, float, int]:
    """One annealing run written plainly (Sect. 2.3, Eq. 6): the specification of
    :func:`kinematics._kernels.anneal.anneal_chain`, on the same random stream, with E from
    :func:`kinematics.fit.error_function.posture_error` (4×4 forward kinematics, NumPy
    projection). Slow (tens of microseconds per iteration); for tests and benchmarks.

    Returns
    -------
    best_deg : ndarray, shape (n_axes,)
        Best posture seen (degrees, not wrapped).
    best_error : float
    iterations : int
    """
    p = params or AnnealParams()
    cams = list(cameras.values()) if isinstance(cameras, Mapping) else list(cameras)
    dets = [np.asarray(d, dtype=float).reshape(-1, 2) for d in detections_frame]
    dets = [d[np.isfinite(d).all(axis=1)] for d in dets]
    hists = body.histograms()
    step_deg = np.array([h.std_deg() for h in hists])
    free = np.flatnonzero(~body.locked_mask())
    th = p.threshold
    rng = SplitMix64(p.seed, frame, run)

    def energy(angles_deg):
        markers = forward_kinematics_reference(body, angles_deg, root_positions).markers
        proj = np.stack([cam.project(markers) for cam in cams])
        return projection_error(proj, dets, p.error)[0]

    cur = body.mean_posture_deg() if start_deg is None else np.asarray(start_deg, float).copy()
    cur[body.locked_mask()] = body.mean_posture_deg()[body.locked_mask()]
    best, e_cur = cur.copy(), energy(cur)
    e_best, tau, length, it = e_cur, p.tau0, p.l0, 0
    while it < p.n_end and not e_best < p.epsilon:
        u = rng.uniform()  # Metropolis draw first, then the step of Eq. 6
        e_accept = e_cur + tau * -math.log(u) if u > 0 else math.inf
        cand = cur.copy()
        for i in free:
            for _ in range(p.max_redraws + 1):  # Eq. 6, redrawn where implausible
                x = cur[i] + length * step_deg[i] * (2.0 * rng.uniform() - 1.0)
                if hists[i].at(x) >= th:
                    cand[i] = x
                    break
        e = energy(cand)
        if e <= e_cur or e < e_accept:  # Metropolis: u < exp(-(e - e_cur) / tau)
            cur, e_cur = cand, e
            if e < e_best:
                best, e_best = cand.copy(), e
        it += 1
        if it % p.n_tau == 0:
            tau *= p.c_tau
        if it % p.n_l == 0:
            length *= p.c_l
    return best, float(e_best), it
