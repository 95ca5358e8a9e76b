"""The error function of the posture fit (paper Eq. 5) and its variants, in plain NumPy.

This module is the readable specification and the test oracle of the numba kernels in
:mod:`kinematics._kernels.error2d` and :mod:`kinematics._kernels.error3d` (which the fitter
runs); the tests compare the two on random postures and detections.

Eq. 5 sums, over the views k and the model markers i, the distance from the projected marker
p_i^k to its nearest detected point in that view::

    E = sum_k sum_i min_c |p_i^k - d_c^k|

Variants (:class:`ErrorOptions`):

* ``cap_px`` — each marker term is ``min(distance, cap_px)``, so a marker hidden in a view
  (occlusion) costs at most ``cap_px`` instead of its distance to some unrelated point.
* ``mode="bidirectional"`` — the heuristic proposed in Sect. 4: every detected point that is
  no model marker's nearest detection adds ``penalty_weight`` times its distance to the nearest
  model marker (capped as well). It penalises postures that fuse two markers onto one
  detection and leave another unexplained (Fig. 9), but it also pulls the model toward ghost
  markers, so use it with few ghosts or together with a cap.
* ``mode="bounded"`` — the bidirectional heuristic with every unclaimed detection costing at
  most ``penalty_cap_px`` (default 3 px) whatever ``cap_px`` is: a detection the model cannot
  explain (a ghost) adds a small constant instead of pulling the model toward it, so the term
  still separates fused-marker postures (two markers on one detection leave a real marker
  unclaimed, at a distance the cap clips only when it is large) without exploding on clutter.

* ``one_to_one`` — each detection explains at most one marker (:func:`one_to_one`): where
  several markers of a view have one detection as their nearest, the closest keeps it and
  each other takes its nearest detection that is no marker's nearest, so two limbs cannot
  share a blob. Meant for the 3D points of ``match = "3d"``, where fused blobs are resolved;
  per view two markers that really fuse into one blob pay for it.

Markers marked hidden in a view (``hidden``, e.g. occluded there, as a user says in the
GUI) are left out of that view: they cost nothing and explain no detection.

Conventions shared with the kernels: a view without any detection contributes nothing; ties
in the nearest detection go to the lower index; a marker whose projection is not finite
(behind a pinhole camera) costs ``cap_px``, or :data:`NAN_MARKER_COST` pixels without a cap.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kinematics.errors import KinematicsError
from kinematics.fit.settings import ERROR_MODES, NAN_MARKER_COST, ErrorOptions  # noqa: F401
from kinematics.model.fk import forward_kinematics_reference


def one_to_one(dist) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one matching of markers with points, greedy by distance (the rule of the
    kernels' ``one_to_one``).

    Parameters
    ----------
    dist : (n_markers, n_points) distances, ``inf`` where a point may not be used (claimed,
        padding) or the marker has no finite position.

    Returns
    -------
    point : (n_markers,) int, the point each marker takes, -1 for none: its nearest (ties:
        the lower point), unless another marker is closer to that point (ties: the lower
        marker); then its nearest point that is no winning marker's nearest.
    distance : (n_markers,) the distance to it, ``inf`` for none.
    """
    d = np.asarray(dist, dtype=float)
    n_m, n_p = d.shape
    if n_p == 0:
        return np.full(n_m, -1), np.full(n_m, np.inf)
    first = np.where(np.isfinite(d).any(axis=1), np.argmin(d, axis=1), -1)
    d_first = np.where(first >= 0, d[np.arange(n_m), np.maximum(first, 0)], np.inf)
    lost = np.zeros(n_m, bool)
    for i in np.flatnonzero(first >= 0):
        rivals = np.flatnonzero((first == first[i]) & (np.arange(n_m) != i))
        lost[i] = any(d_first[j] < d_first[i] or (d_first[j] == d_first[i] and j < i)
                      for j in rivals)
    point, distance = first.copy(), d_first.copy()
    won = np.zeros(n_p, bool)
    won[first[(first >= 0) & ~lost]] = True
    for i in np.flatnonzero(lost):
        free = np.where(won, np.inf, d[i])
        point[i] = int(np.argmin(free)) if np.isfinite(free).any() else -1
        distance[i] = free[point[i]] if point[i] >= 0 else np.inf
    return point, distance


def projection_error(
    projections, detections: Sequence, options: ErrorOptions | None = None, hidden=None
) -> tuple[float, np.ndarray]:
    """Eq. 5 (or a variant) for given marker projections.

    Parameters
    ----------
    projections : array_like, shape (n_views, n_markers, 2)
        Model markers projected into each view, pixels.
    detections : sequence of array_like, each shape (n_c, 2)
        Detected points of each view, pixels (finite).
    options : ErrorOptions, optional
        Defaults to the paper's Eq. 5.
    hidden : array_like of bool, shape (n_views, n_markers), optional
        Markers the user marked hidden in a view (occluded there): such a marker is left out
        of that view, as if the body had no such marker in it. It costs nothing, takes no
        detection, and is no detection's nearest marker in the bidirectional term.

    Returns
    -------
    error : float
        E in pixels.
    error_per_view : ndarray, shape (n_views,)
        The part of E from each view.
    """
    opts = options or ErrorOptions()
    proj = np.asarray(projections, dtype=float)
    if proj.ndim != 3 or proj.shape[2] != 2:
        raise KinematicsError(f"projections must have shape (views, markers, 2), got "
                              f"{proj.shape}")
    if len(detections) != proj.shape[0]:
        raise KinematicsError(f"{proj.shape[0]} views projected but detections for "
                              f"{len(detections)}")
    cap = opts.cap
    missing = cap if np.isfinite(cap) else NAN_MARKER_COST
    per_view = np.zeros(proj.shape[0])
    seen = np.ones(proj.shape[:2], bool)
    if hidden is not None:
        if np.shape(hidden) != proj.shape[:2]:
            raise KinematicsError(f"hidden marks must have shape {proj.shape[:2]} (views, "
                                  f"markers), got {np.shape(hidden)}", field="hidden")
        seen = ~np.asarray(hidden, bool)
    for v, det in enumerate(detections):
        d = np.asarray(det, dtype=float).reshape(-1, 2)
        if len(d) == 0:
            continue
        # dist[i, c]: model marker i to detection c, as the kernel: sqrt(dx*dx + dy*dy).
        diff = proj[v][seen[v]][:, None, :] - d[None, :, :]
        dist = np.sqrt(diff[..., 0] * diff[..., 0] + diff[..., 1] * diff[..., 1])
        finite = np.isfinite(proj[v][seen[v]]).all(axis=1)
        nearest = np.where(finite, np.argmin(np.where(finite[:, None], dist, 0.0), axis=1), -1)
        marker_cost = np.where(finite, dist.min(axis=1, initial=np.inf, where=finite[:, None]),
                               missing)
        if opts.one_to_one:
            nearest, taken = one_to_one(np.where(finite[:, None], dist, np.inf))
            marker_cost = np.where(nearest >= 0, taken, missing)
        per_view[v] = np.minimum(marker_cost, cap).sum()
        if opts.bidirectional:
            claimed = np.zeros(len(d), dtype=bool)
            claimed[nearest[nearest >= 0]] = True
            to_model = dist[finite].min(axis=0) if finite.any() else np.full(len(d), missing)
            unclaimed = np.minimum(to_model[~claimed], opts.penalty_cap)
            per_view[v] += opts.penalty_weight * unclaimed.sum()
    return float(per_view.sum()), per_view


def posture_error(
    body, cameras, angles_deg, detections: Sequence, root_positions=None,
    options: ErrorOptions | None = None, hidden=None,
) -> tuple[float, np.ndarray]:
    """Eq. 5 (or a variant) of one posture, computed literally: forward kinematics by 4×4
    matrices (:func:`kinematics.model.fk.forward_kinematics_reference`), projection by each
    camera's NumPy ``project``, then :func:`projection_error`.

    Parameters
    ----------
    body : Body
    cameras : sequence of Camera, or mapping name -> Camera, one per view in order
    angles_deg : array_like, shape (n_axes,)
    detections : sequence of array_like (n_c, 2), one per view
    root_positions : array_like, shape (n_chains, 3), optional
        Defaults to the chains' configured positions.
    options : ErrorOptions, optional
    hidden : array_like of bool, shape (n_views, n_markers), optional
        Markers hidden in a view (:func:`projection_error`).

    Returns
    -------
    error : float
    error_per_view : ndarray, shape (n_views,)
    """
    cams = list(cameras.values()) if hasattr(cameras, "values") else list(cameras)
    markers = forward_kinematics_reference(body, angles_deg, root_positions).markers
    proj = np.stack([cam.project(markers) for cam in cams])
    return projection_error(proj, detections, options, hidden)


def labelled_error(projections, keypoints, options: ErrorOptions | None = None
                   ) -> tuple[float, np.ndarray]:
    """Labelled reprojection error (the objective of labelled 2D keypoints)::

        E = sum_v sum_i w_i^v · min(|p_i^v - k_i^v|, cap)

    Each model marker is compared with its own keypoint, never with another marker's; a
    keypoint with NaN coordinates or weight 0 is missing and costs nothing; the cap bounds
    what one mislabelled keypoint can cost (a robust loss).

    Parameters
    ----------
    projections : array_like, shape (n_views, n_markers, 2)
    keypoints : array_like, shape (n_views, n_markers, 3)
        x, y, weight (confidence) of each marker's keypoint in each view.
    options : ErrorOptions, optional
        Only ``cap_px`` is used.

    Returns
    -------
    error : float
    error_per_view : ndarray, shape (n_views,)
    """
    opts = options or ErrorOptions()
    proj = np.asarray(projections, dtype=float)
    kp = np.asarray(keypoints, dtype=float)
    w = np.nan_to_num(kp[..., 2])
    present = np.isfinite(kp[..., :2]).all(axis=-1) & (w > 0)
    d = np.linalg.norm(proj - kp[..., :2], axis=-1)
    d = np.where(np.isfinite(d), d, opts.cap if np.isfinite(opts.cap) else NAN_MARKER_COST)
    per_view = np.where(present, w * np.minimum(d, opts.cap), 0.0).sum(axis=1)
    return float(per_view.sum()), per_view


def points3d_error(markers, points, options: ErrorOptions | None = None) -> float:
    """3D point error (the objective of labelled 3D points), in length units::

        E = sum_i w_i · min(|X_i - Y_i|, cap)

    ``markers`` (n_markers, 3) model markers; ``points`` (n_markers, 4) x, y, z, weight of
    each marker's point (NaN or weight 0: missing). Only ``cap_px`` of ``options`` is used
    (read in length units here).
    """
    opts = options or ErrorOptions()
    y = np.asarray(points, dtype=float)
    w = np.nan_to_num(y[:, 3])
    present = np.isfinite(y[:, :3]).all(axis=1) & (w > 0)
    d = np.linalg.norm(np.asarray(markers, float) - y[:, :3], axis=1)
    return float(np.where(present, w * np.minimum(d, opts.cap), 0.0).sum())


def cloud_error(markers, cloud, options: ErrorOptions | None = None, claimed=None) -> float:
    """Unlabelled 3D points (the objective of ``match = "3d"``), Eq. 5 in 3D::

        E = sum_i min(s_c · |X_i - Y_c|, cap)

    ``Y_c`` is model marker i's nearest cloud point by ``s_c · distance`` (ties: the lower
    row), ``s_c`` the pixels per length unit at that point, so E reads in pixels. With the
    bidirectional modes every point that is no marker's nearest adds ``penalty_weight ·
    min(s_c · its distance to the nearest marker, penalty_cap)``. With ``one_to_one`` a point
    explains at most one marker (:func:`one_to_one`).

    Parameters
    ----------
    markers : (n_markers, 3) model markers
    cloud : (k, 4) x, y, z, s of each point; s <= 0 marks padding; or (k, 4 + n_markers):
        then column 4 + i is nonzero where marker i may take the point (markers of several
        colours, each colour triangulated on its own)
    options : ErrorOptions, optional (default: the paper's Eq. 5)
    claimed : (k,) bool, optional: points another partition took, left out entirely
    """
    opts = options or ErrorOptions()
    mk = np.asarray(markers, dtype=float)
    c = np.asarray(cloud, dtype=float)
    c = c.reshape(-1, c.shape[-1] if c.ndim > 1 else 4)
    use = c[:, 3] > 0
    if claimed is not None:
        use &= ~np.asarray(claimed, bool)
    missing = opts.cap if np.isfinite(opts.cap) else NAN_MARKER_COST
    if not use.any():
        return float(len(mk) * min(missing, opts.cap))
    diff = mk[:, None, :] - c[None, use, :3]
    dist = c[use, 3] * np.sqrt((diff * diff).sum(axis=2))  # (markers, used points)
    if c.shape[1] > 4:  # a marker only takes points of its colour
        dist = np.where(c[use, 4:4 + len(mk)].T != 0, dist, np.inf)
    nearest, cost = np.argmin(dist, axis=1), dist.min(axis=1)
    nearest = np.where(np.isfinite(cost), nearest, -1)
    if opts.one_to_one:
        nearest, cost = one_to_one(dist)
    cost = np.where(nearest >= 0, cost, missing)
    e = float(np.minimum(cost, opts.cap).sum())
    if opts.bidirectional:
        taken = np.zeros(dist.shape[1], bool)
        taken[nearest[nearest >= 0]] = True
        left = dist.min(axis=0)[~taken]
        e += opts.penalty_weight * float(np.minimum(left[np.isfinite(left)],
                                                    opts.penalty_cap).sum())
    return e


def nearest_residuals(proj, points, view_off, seen, gate: float) -> tuple[np.ndarray, int]:
    """NumPy twin of the kernel ``_kernels.error2d.nearest_residuals``: (n_views, n_markers)
    distance of each seen model marker (``seen``, bool) to the nearest detection of its view
    (NaN where a view has none or the marker is not seen), and how many detections lie
    farther than ``gate`` from every seen marker of their view (all of a view that sees
    none)."""
    proj, points = np.asarray(proj, float), np.asarray(points, float)
    out = np.full(proj.shape[:2], np.nan)
    unexplained = 0
    for v in range(proj.shape[0]):
        d = points[view_off[v]: view_off[v + 1]]
        if len(d) and seen[v].any():
            dist = np.linalg.norm(proj[v][seen[v]][:, None] - d[None], axis=2)
            out[v, seen[v]] = dist.min(axis=1)
            unexplained += int((dist.min(axis=0) > gate).sum())
        elif len(d):
            unexplained += len(d)
    return out, unexplained
