"""Local refinement of a fitted posture, and the accuracy a set-up allows.

After annealing, a posture is within a pixel or so of the detections, but annealing on the
sum of distances (Eq. 5) with random steps does not pin the last fraction of a degree: on the
locust leg the short coxa (13 px) turns a 0.3-px centroid error into degrees of α and β (the
paper's Table 2: 4.7° and 4.9°). Refinement pairs every model marker with its nearest
detection in each view, drops pairs farther apart than a gate (ghosts, occlusions), and runs
a few Levenberg-Marquardt steps on the squared pair distances, within the axis ranges and
never moving locked axes. For Gaussian centroid noise that is the maximum-likelihood
posture, whose accuracy :func:`cramer_rao_bound` predicts.

:func:`refine` runs the numba kernel (microseconds per frame; the fitter calls the same
kernel when ``AnnealParams.refine`` is set); :func:`refine_reference` solves the same problem
with :func:`scipy.optimize.least_squares` (the twin, and the speed comparison of the
benchmark).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from kinematics._kernels import codes as _codes
from kinematics._kernels import refine as _rk
from kinematics._kernels.records import FrameObs
from kinematics.errors import KinematicsError
from kinematics.fit import Fitter
from kinematics.fit.inputs import as_ragged
from kinematics.observe.observations import ObservationArrays


@dataclass(frozen=True, eq=False)
class RefineResult:
    """A refined posture.

    angles_deg : (n_axes,) the refined posture.
    root_positions : (n_chains, 3) the roots (free roots move with the refinement).
    sse : sum of squared pair distances at the end, pixels².
    n_pairs : marker/detection pairs used (within the gate) at the end.
    error : E (Eq. 5 or the fitter's variant) of the refined posture; error_per_view (n_views,).
    """

    angles_deg: np.ndarray
    sse: float
    n_pairs: int
    error: float
    error_per_view: np.ndarray
    root_positions: np.ndarray | None = None


def _inputs(fitter: Fitter, angles_deg, detections_frame, root_positions):
    """Start angles (radians, locked axes at their value), ragged detections, roots."""
    angles, roots = fitter.problem.posture(*fitter.state(angles_deg, root_positions))
    return angles, fitter._frame_ragged(detections_frame), roots


def _free_angles(fitter: Fitter) -> np.ndarray:
    """Free joint-angle entries (translations of free roots excluded)."""
    free = fitter.problem.free_idx
    return free[free < fitter.problem.n_axes]


def _gate_steps(fitter: Fitter, steps, gate_px) -> tuple[int, float]:
    steps = fitter.params.refine_steps if steps is None else steps
    gate = fitter.params.refine_gate_px if gate_px is None else gate_px
    if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 0:
        raise KinematicsError(f"must be an integer >= 0, got {steps!r}", field="refine_steps")
    if not (np.isfinite(gate) and gate > 0):
        raise KinematicsError(f"must be a finite number > 0, got {gate!r}",
                              field="refine_gate_px")
    return int(steps), float(gate)


def refine(fitter: Fitter, angles_deg, detections_frame, root_positions=None, *,
           steps: int | None = None, gate_px: float | None = None) -> RefineResult:
    """Levenberg-Marquardt refinement of one posture (numba kernel).

    Parameters
    ----------
    fitter : Fitter
        Body, cameras and error options.
    angles_deg : array_like, shape (n_axes,)
        Start posture, e.g. an annealing result.
    detections_frame : sequence of array_like (n_c, 2), one per view
    root_positions : array_like, shape (n_chains, 3), optional
    steps, gate_px : optional
        Accepted steps at most and the pairing gate in pixels; default from
        ``fitter.params`` (``refine_steps``, ``refine_gate_px``).
    """
    steps, gate = _gate_steps(fitter, steps, gate_px)
    pr = fitter.problem
    rag = fitter._frame_ragged(detections_frame)

    def run(n_steps: int, start_deg, start_roots):
        state, pos, rot = fitter.state(start_deg, start_roots)
        obs = FrameObs(_codes.OBJ_NEAREST, rag.points, np.ones(len(rag.points)), rag.offsets,
                       fitter.unseen_marks)
        sse, n_pairs = _rk.refine_posture(state, pr.free_idx, pr.dofs, n_steps, gate, pos, rot,
                                          pr.folded, pr.cams, pr.cams.kind, obs)
        angles, roots = pr.posture(state, pos, rot)
        out = fitter._to_range_deg(angles)
        error, per_view = fitter.error(out, detections_frame, roots)
        return RefineResult(out, float(sse), int(n_pairs), error, per_view, roots)

    start = run(0, angles_deg, root_positions)  # the start as it is scored (locked axes set)
    refined = run(steps, angles_deg, root_positions)
    # Refinement minimises squared pair residuals, not E: never hand back a worse E.
    return refined if refined.error <= start.error else start


def refine_many(fitter: Fitter, angles_deg, detections, root_positions=None, *,
                steps: int | None = None, gate_px: float | None = None) -> list[RefineResult]:
    """:func:`refine` for many frames at once, in parallel (e.g. after manual corrections).

    Parameters
    ----------
    angles_deg : array_like, shape (n_frames, n_axes)
        Start postures; rows with NaN (frames without a fit) are returned unchanged.
    detections : Detections-like or sequence of frames
        As :meth:`Fitter.iter_fit`, one frame per row of ``angles_deg``.
    root_positions : array_like, shape (n_frames, n_chains, 3), optional
        Default the configured positions.
    """
    steps, gate = _gate_steps(fitter, steps, gate_px)
    rag = as_ragged(detections, fitter.view_names)
    start = np.asarray(angles_deg, dtype=float)
    n = rag.n_frames
    if start.shape != (n, fitter.body.n_axes):
        raise KinematicsError(f"angles need shape ({n}, {fitter.body.n_axes}), got "
                              f"{start.shape}", field="angles_deg")
    rows = np.isfinite(start).all(axis=1)
    pr = fitter.problem
    base = fitter._roots
    if root_positions is None:
        roots = np.ascontiguousarray(np.broadcast_to(base, (n, *base.shape)))
    else:
        roots = np.ascontiguousarray(np.asarray(root_positions, dtype=float))
        if roots.shape != (n, *base.shape) or not np.isfinite(roots).all():
            raise KinematicsError(f"root positions need finite shape {(n, *base.shape)}"
                                  f", got {roots.shape}", field="root_positions")
    state = np.full((n, pr.n_state), np.nan)
    pos = roots.copy()
    rot = pr.identity_rotations(n)
    for k in np.flatnonzero(rows):
        state[k], pos[k], rot[k] = fitter.state(start[k], roots[k])
    sse = np.empty(n)
    pairs = np.empty(n, np.int64)
    marks = fitter.unseen_marks
    obs = ObservationArrays(_codes.OBJ_NEAREST, rag.points, np.ones(len(rag.points)),
                            rag.offsets, np.ascontiguousarray(np.broadcast_to(
                                marks, (n, *marks.shape))))
    _rk.refine_frames(state, pos, rot, pr.folded, pr.cams, pr.dofs, steps, gate, obs, sse,
                      pairs)
    out = []
    nv = rag.n_views
    for k in range(n):
        if not rows[k]:
            out.append(RefineResult(start[k].copy(), np.nan, 0, np.nan,
                                    np.full(fitter.n_views, np.nan), roots[k].copy()))
            continue
        angles, fitted_roots = pr.posture(state[k], pos[k], rot[k])
        a = fitter._to_range_deg(angles)
        frame = [rag.points[rag.offsets[k * nv + v]: rag.offsets[k * nv + v + 1]]
                 for v in range(nv)]
        error, per_view = fitter.error(a, frame, fitted_roots)
        result = RefineResult(a, float(sse[k]), int(pairs[k]), error, per_view, fitted_roots)
        start_e = fitter.error(start[k], frame, roots[k])[0]
        if error > start_e:  # never a worse E than the start (as refine)
            result = refine(fitter, start[k], frame, roots[k], steps=0, gate_px=gate)
        out.append(result)
    return out


def refine_reference(fitter: Fitter, angles_deg, detections_frame, root_positions=None, *,
                     gate_px: float | None = None) -> RefineResult:
    """The same problem solved by :func:`scipy.optimize.least_squares` (trust-region
    reflective, bounded by the axis ranges, free axes only), with the pairs assigned once at
    the start posture. The twin of :func:`refine`, and its speed reference.
    """
    _, gate = _gate_steps(fitter, 0, gate_px)
    angles, rag, roots = _inputs(fitter, angles_deg, detections_frame, root_positions)
    nv, nm = fitter.n_views, len(fitter.body.marker_names)
    proj0 = fitter.project(np.rad2deg(angles), roots)
    pair = np.empty(nv * nm, np.int64)
    n_pairs = _rk.assign_pairs(_codes.OBJ_NEAREST, proj0, np.zeros((nm, 3)), rag.points,
                               np.ones(len(rag.points)), rag.offsets, fitter.unseen_marks, gate,
                               pair)
    free = _free_angles(fitter)
    ranges = np.deg2rad(fitter.body.ranges_deg())
    lo, hi = ranges[free, 0], ranges[free, 1]
    x0 = angles[free].copy()
    # Express the start within the bounds (ranges wrap by whole turns).
    x0 = x0 + 2 * np.pi * np.round((0.5 * (lo + hi) - x0) / (2 * np.pi))
    x0 = np.clip(x0, lo, hi)
    on = pair >= 0
    target = rag.points[pair[on]]

    def residuals(x):
        a = angles.copy()
        a[free] = x
        p = fitter.project(np.rad2deg(a), roots).reshape(-1, 2)
        return (p[on] - target).ravel()

    if n_pairs == 0:
        a = angles
        sse = 0.0
    else:
        sol = least_squares(residuals, x0, bounds=(lo, hi), method="trf", x_scale="jac")
        a = angles.copy()
        a[free] = sol.x
        sse = float(2.0 * sol.cost)
    out = fitter._to_range_deg(a)
    error, per_view = fitter.error(out, detections_frame, root_positions)
    return RefineResult(out, sse, int(n_pairs), error, per_view)


def projection_jacobian(fitter: Fitter, angles_deg, root_positions=None,
                        step_deg: float = 1e-5) -> np.ndarray:
    """d(projections)/d(free angles) by central differences.

    Returns
    -------
    ndarray, shape (n_views * n_markers * 2, n_free)
        Pixels per degree; rows in (view, marker, u/v) order, columns the free axes in
        posture order.
    """
    angles = np.asarray(angles_deg, dtype=float)
    cols = []
    for i in _free_angles(fitter):
        up, dn = angles.copy(), angles.copy()
        up[i] += step_deg
        dn[i] -= step_deg
        diff = fitter.project(up, root_positions) - fitter.project(dn, root_positions)
        cols.append(diff.ravel() / (2 * step_deg))
    return np.stack(cols, axis=1)


def cramer_rao_bound(fitter: Fitter, angles_deg, noise, root_positions=None, visible=None,
                     combos=None) -> np.ndarray:
    """Cramér-Rao lower bound on the standard deviation of the free angles, degrees.

    For Gaussian centroid noise of covariance Σ, the Fisher information of the free angles
    is ``J^T Σ^-1 J`` with J from :func:`projection_jacobian`; no unbiased estimator from
    these detections does better than ``sqrt(diag((J^T Σ^-1 J)^-1))``. Correlated noise
    matters: two orthographic views that share an image axis at the same pixel phase (the
    paper's side and top views both map x to u) see the same centroid bias along it.

    Parameters
    ----------
    noise : float or array_like, shape (n_rows, n_rows)
        Standard deviation σ in pixels of each image coordinate (independent), or the
        covariance Σ in pixels² with rows in :func:`projection_jacobian` order.
    visible : array_like of bool, shape (n_views, n_markers), optional
        Which marker images exist (occluded ones carry no information); default all.
    combos : array_like, shape (k, n_free), optional
        Linear combinations to bound as well (e.g. α + β), appended to the output.

    Returns
    -------
    ndarray, shape (n_free,) or (n_free + k,)
        Lower bounds of the standard deviation, degrees.
    """
    jac = projection_jacobian(fitter, angles_deg, root_positions)
    n = jac.shape[0]
    cov = np.asarray(noise, dtype=float)
    cov = cov**2 * np.eye(n) if cov.ndim == 0 else cov
    if cov.shape != (n, n):
        raise KinematicsError(f"noise must be a number or a ({n}, {n}) covariance, got shape "
                              f"{cov.shape}", field="noise")
    if visible is not None:
        rows = np.repeat(np.asarray(visible, dtype=bool).ravel(), 2)
        jac, cov = jac[rows], cov[np.ix_(rows, rows)]
    info = jac.T @ np.linalg.solve(cov, jac)
    bound_cov = np.linalg.pinv(info)
    out = np.sqrt(np.clip(np.diag(bound_cov), 0, None))
    if combos is not None:
        w = np.atleast_2d(np.asarray(combos, dtype=float))
        out = np.concatenate([out, np.sqrt(np.clip(np.einsum("ki,ij,kj->k", w, bound_cov, w),
                                                   0, None))])
    return out


__all__ = ["RefineResult", "cramer_rao_bound", "projection_jacobian", "refine", "refine_many",
           "refine_reference"]
