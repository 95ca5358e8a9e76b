"""E against 2D detections (Eq. 5 and its variants): nearest detection per view, the
one-to-one pairing, labelled keypoints, claims of partitions and the counts of unexplained
detections. Twin: :mod:`kinematics.fit.error_function`."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from kinematics._kernels.codes import NAN_MARKER_COST, NO_CLAIMS, UNSEEN
from kinematics._kernels.posture import hidden_in

# -- Eq. 5 -------------------------------------------------------------------------------
#: Views with more detections than this are searched by :func:`nearest_sorted`; with fewer
#: a plain scan is faster (and the paper's few markers per view keep their exact code path).
#: Measured on the fly (bench_scaling): a leg's iteration 3.5 → 2.7 µs at 100 detections per
#: view, slower at 30. The fast path's four-chain scan (:func:`paper_error`) costs a third
#: as much per detection, so it sweeps only from SWEEP_MIN_FAST: whole-body iterations of the
#: fly were 16 → 20 µs at 100 detections with the sweep, 35 → 28 µs at 300.
SWEEP_MIN = 64
SWEEP_MIN_FAST = 192


@njit(cache=True, nogil=True, inline="always")
def nearest_sorted(px, py, points, a, b, claimed):
    """The nearest detection to (px, py) among rows ``a:b``, which are sorted by x, not
    ``claimed`` (an empty ``claimed`` claims nothing): a binary search for px, then outward
    while the x gap alone is no farther than the best so far, so a query costs the detections
    in a band around the marker, not all. Returns (squared distance, row), (inf, -1) for
    none; ties go to the lower row, as a scan's."""
    lo = a
    hi = b
    while lo < hi:
        mid = (lo + hi) // 2
        if points[mid, 0] < px:
            lo = mid + 1
        else:
            hi = mid
    best = np.inf
    arg = -1
    nc = claimed.shape[0]
    # Rightward from the insertion point, then leftward, in two written-out loops: a merged
    # loop with a step was 1.3x slower per query at 1000 detections, and the shared body as
    # an inline helper returning (best, row) 3x slower (156-169 -> 495-507 ns per query).
    c = lo
    gap = 0.0
    while c < b and gap <= best:
        dx = points[c, 0] - px
        gap = dx * dx
        dy = points[c, 1] - py
        d2 = gap + dy * dy
        if (d2 < best or (d2 == best and c < arg)) and not (c < nc and claimed[c]):
            best = d2
            arg = c
        c += 1
    c = lo - 1
    gap = 0.0
    while c >= a and gap <= best:
        dx = px - points[c, 0]
        gap = dx * dx
        dy = points[c, 1] - py
        d2 = gap + dy * dy
        if (d2 < best or (d2 == best and c < arg)) and not (c < nc and claimed[c]):
            best = d2
            arg = c
        c -= 1
    return best, arg


@njit(cache=True, nogil=True, inline="always")
def nearest_in_view(px, py, points, a, b, claimed):
    """The nearest detection to (px, py) among rows ``a:b`` not ``claimed`` (an empty
    ``claimed`` claims nothing): by :func:`nearest_sorted` in a view with many detections,
    else by a scan. Returns (squared distance, row), (inf, -1) for none."""
    if b - a > SWEEP_MIN:
        return nearest_sorted(px, py, points, a, b, claimed)
    best = np.inf
    arg = -1
    nc = claimed.shape[0]
    for c in range(a, b):
        dx = px - points[c, 0]
        dy = py - points[c, 1]
        d2 = dx * dx + dy * dy
        if d2 < best and not (c < nc and claimed[c]):
            best = d2
            arg = c
    return best, arg


@njit(cache=True, nogil=True)
def projection_error(proj, points, view_off, obs3, bidirectional, weight, cap, penalty_cap,
                     one, per_view, nearest):
    """Eq. 5 and its variants for given marker projections; returns E (pixels).

    ``E = sum_v sum_i min(min_c |p_i^v - d_c^v|, cap)`` over views with at least one
    detection (a view without detections contributes nothing). With ``bidirectional``, each
    detection that is no marker's nearest detection adds ``weight * min(min_i |p_i^v -
    d_c^v|, penalty_cap)`` (the heuristic of Sect. 4; bounded, a ghost costs at most
    ``weight * penalty_cap``). ``cap = inf`` is the paper's Eq. 5. With ``one`` (one-to-one)
    each detection explains at most one marker of its view (:func:`one_to_one`). Ties go
    to the lower detection index. A marker without a finite projection costs ``cap``, or
    :data:`NAN_MARKER_COST` without a cap. A marker hidden in a view (:func:`hidden_in`)
    is left out of that view.

    Parameters
    ----------
    proj : (n_views, n_markers, 2)
    points : (n_points, 2); view_off : (n_views + 1,); obs3 : hidden marks (:func:`hidden_in`)
    per_view : (n_views,) out, E of each view; nearest : (n_markers,) int64 scratch.
    """
    nv = proj.shape[0]
    nm = proj.shape[1]
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    for v in range(nv):
        a = view_off[v]
        b = view_off[v + 1]
        ev = 0.0
        if b > a:
            for i in range(nm):
                if hidden_in(obs3, i, v):
                    nearest[i] = UNSEEN
                    continue
                best, arg = nearest_in_view(proj[v, i, 0], proj[v, i, 1], points, a, b,
                                            NO_CLAIMS)
                nearest[i] = arg
                d = math.sqrt(best) if arg >= 0 else missing
                ev += min(d, cap)
            if one:
                ev = one_to_one(proj[v], points, a, b, 0, nm, False, NO_CLAIMS, cap, nearest)
            if bidirectional:
                for c in range(a, b):
                    matched = False
                    best = np.inf
                    for i in range(nm):
                        matched = matched or takes(nearest[i], c)
                        dx = proj[v, i, 0] - points[c, 0]
                        dy = proj[v, i, 1] - points[c, 1]
                        seen = nearest[i] != UNSEEN
                        best = min(best, dx * dx + dy * dy) if seen else best
                    if not matched:
                        d = math.sqrt(best) if best < np.inf else missing
                        ev += weight * min(d, penalty_cap)
        per_view[v] = ev
        total += ev
    return total


@njit(cache=True, nogil=True, inline="always")
def takes(n, c):
    """Whether a marker's ``nearest`` entry ``n`` takes point ``c``: its nearest point, or
    the point :func:`one_to_one` gave it instead, written ``-(c + 2)``."""
    return n == c or n == -c - 2


@njit(cache=True, nogil=True, inline="always")
def point_of(n):
    """The point a marker's ``nearest`` entry ``n`` takes: ``n``, or for a marker that lost
    its nearest point the one :func:`one_to_one` gave it instead (``-(c + 2)``); -1 none."""
    return n if n >= -1 else -n - 2


@njit(cache=True, nogil=True, inline="always")
def may_take(cloud, c, i):
    """Whether model marker ``i`` may take cloud point ``c``. A cloud of markers of several
    colours (each colour triangulated on its own) has one column per model marker after x,
    y, z, s: nonzero where the marker has the point's colour; a cloud of 4 columns lets
    every marker take every point."""
    return cloud.shape[1] <= 4 or cloud[c, 4 + i] != 0.0


@njit(cache=True, nogil=True, inline="always")
def _dist2(X, i, Y, c, scaled):
    """Squared distance of marker ``X[i]`` to point ``Y[c]``: 2D, or with ``scaled`` 3D times
    the point's px per length unit ``Y[c, 3]`` squared (a cloud; infinite where the marker
    may not take the point, :func:`may_take`)."""
    dx = X[i, 0] - Y[c, 0]
    dy = X[i, 1] - Y[c, 1]
    d2 = dx * dx + dy * dy
    if scaled:
        dz = X[i, 2] - Y[c, 2]
        d2 = (d2 + dz * dz) * (Y[c, 3] * Y[c, 3]) if may_take(Y, c, i) else np.inf
    return d2


@njit(cache=True, nogil=True)
def one_to_one(X, Y, a, b, m0, m1, scaled, claimed, cap, nearest):
    """One-to-one matching of the markers ``m0:m1`` (``X``) with the points ``a:b`` (``Y``;
    with ``scaled`` a cloud, :func:`_dist2`), greedy by distance: a point several markers
    have as their nearest stays with the closest (ties: the lower marker); each other marker
    takes its nearest point that is no marker's nearest and not ``claimed``, or costs
    ``cap`` (:data:`NAN_MARKER_COST` without one) where none is left. On entry ``nearest``
    holds each marker's nearest point (-1: none; :data:`UNSEEN`: hidden, left out); on
    return a marker that lost its point holds ``-(c + 2)`` for the point ``c`` it took
    instead (:func:`takes`). Returns
    ``sum_i min(distance_i, cap)``. So two limbs cannot share a blob: the second marker
    pays for its next point, and the marker it leaves out pays the bidirectional term."""
    missing = cap if cap < np.inf else NAN_MARKER_COST
    for i in range(m0, m1):  # losers: nearest = -(their point + 2)
        c = nearest[i]
        if c >= 0:
            di = _dist2(X, i, Y, c, scaled)
            lost = False
            for j in range(m0, m1):
                cj = point_of(nearest[j])
                if j != i and cj == c:
                    dj = _dist2(X, j, Y, c, scaled)
                    lost = lost or dj < di or (dj == di and j < i)
            if lost:
                nearest[i] = -c - 2
    total = 0.0
    for i in range(m0, m1):
        c = nearest[i]
        if c >= 0:
            total += min(math.sqrt(_dist2(X, i, Y, c, scaled)), cap)
        elif c == -1:
            total += min(missing, cap)
        elif c != UNSEEN:  # lost its point: the nearest one no marker has as its nearest
            best = np.inf
            arg = -1
            for c2 in range(a, b):
                free = not (c2 < claimed.shape[0] and claimed[c2])
                free = free and (not scaled or Y[c2, 3] > 0.0)
                for j in range(m0, m1):
                    free = free and nearest[j] != c2
                if free:
                    d2 = _dist2(X, i, Y, c2, scaled)
                    if d2 < best:
                        best = d2
                        arg = c2
            nearest[i] = -arg - 2 if arg >= 0 else -1
            total += min(math.sqrt(best) if arg >= 0 else missing, cap)
    return total


@njit(cache=True, nogil=True, inline="always")
def paper_error(proj, points, view_off, cap):
    """:func:`projection_error` without the bidirectional term and per-view output: the
    annealing loop's fast path. The minimum over detections runs in four independent
    chains (a single chain of dependent minimums was latency-bound); min is exact, so the
    result equals :func:`projection_error`'s."""
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    for v in range(proj.shape[0]):
        a = view_off[v]
        b = view_off[v + 1]
        ev = 0.0
        if b - a > SWEEP_MIN_FAST:
            for i in range(proj.shape[1]):
                best, _ = nearest_sorted(proj[v, i, 0], proj[v, i, 1], points, a, b,
                                         NO_CLAIMS)
                d = math.sqrt(best) if best < np.inf else missing
                ev += min(d, cap)
        elif b > a:
            for i in range(proj.shape[1]):
                px = proj[v, i, 0]
                py = proj[v, i, 1]
                m0 = np.inf
                m1 = np.inf
                m2 = np.inf
                m3 = np.inf
                c = a
                while c + 3 < b:
                    dx = px - points[c, 0]
                    dy = py - points[c, 1]
                    m0 = min(m0, dx * dx + dy * dy)
                    dx = px - points[c + 1, 0]
                    dy = py - points[c + 1, 1]
                    m1 = min(m1, dx * dx + dy * dy)
                    dx = px - points[c + 2, 0]
                    dy = py - points[c + 2, 1]
                    m2 = min(m2, dx * dx + dy * dy)
                    dx = px - points[c + 3, 0]
                    dy = py - points[c + 3, 1]
                    m3 = min(m3, dx * dx + dy * dy)
                    c += 4
                while c < b:
                    dx = px - points[c, 0]
                    dy = py - points[c, 1]
                    m0 = min(m0, dx * dx + dy * dy)
                    c += 1
                best = min(min(m0, m1), min(m2, m3))
                d = math.sqrt(best) if best < np.inf else missing
                ev += min(d, cap)
        total += ev
    return total


@njit(cache=True, nogil=True)
def labelled_error(proj, points, conf, view_off, cap, per_view):
    """Labelled reprojection error: ``E = sum_v sum_i w_i^v min(|p_i^v - k_i^v|, cap)``.

    View ``v`` owns rows ``view_off[v]:view_off[v + 1]``, which are the model markers in
    order (``n_markers`` rows) or none; a keypoint that is not finite or has weight
    ``conf <= 0`` is missing and costs nothing; a marker whose projection is not finite costs
    ``cap`` (:data:`NAN_MARKER_COST` without a cap), times its weight.
    """
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    for v in range(proj.shape[0]):
        a = view_off[v]
        ev = 0.0
        if view_off[v + 1] - a == proj.shape[1]:
            for i in range(proj.shape[1]):
                w = conf[a + i]
                kx = points[a + i, 0]
                ky = points[a + i, 1]
                if w > 0.0 and math.isfinite(kx) and math.isfinite(ky):
                    dx = proj[v, i, 0] - kx
                    dy = proj[v, i, 1] - ky
                    d = math.sqrt(dx * dx + dy * dy)
                    ev += w * min(d if math.isfinite(d) else missing, cap)
        per_view[v] = ev
        total += ev
    return total


@njit(cache=True, nogil=True, inline="always")
def _nan_min(a, b):
    """``min`` as NumPy's ``min`` reduces: a NaN on either side wins."""
    return a if math.isnan(a) or not (b < a or math.isnan(b)) else b


@njit(cache=True, nogil=True)
def nearest_residuals(proj, points, view_off, seen, gate, out):
    """Each seen model marker's distance to the nearest detection of its view into ``out``
    (n_views, n_markers; left as it is for a view without detections or a marker not
    seen); returns the detections farther than ``gate`` (finite) from every seen marker of
    their view (all of a view that sees none). NaN propagates as in NumPy (a marker behind a
    camera). Twin: :func:`kinematics.fit.error_function.nearest_residuals`."""
    unexplained = 0
    nm = proj.shape[1]
    for v in range(proj.shape[0]):
        a, b = view_off[v], view_off[v + 1]
        near = np.full(b - a, np.inf)  # per detection, its nearest seen marker (none: inf)
        for m in range(nm):
            if seen[v, m] and b > a:
                best = np.inf
                for c in range(a, b):
                    dx = proj[v, m, 0] - points[c, 0]
                    dy = proj[v, m, 1] - points[c, 1]
                    d = math.sqrt(dx * dx + dy * dy)
                    best = _nan_min(best, d)
                    near[c - a] = _nan_min(near[c - a], d)
                out[v, m] = best
        for c in range(b - a):
            unexplained += 1 if near[c] > gate else 0
    return unexplained


@njit(cache=True, nogil=True)
def count_unexplained(proj, points, view_off, obs3, gate):
    """Detections farther than ``gate`` pixels from every projected model marker not hidden
    in their view (:func:`hidden_in`)."""
    g2 = gate * gate
    n = 0
    for v in range(proj.shape[0]):
        for c in range(view_off[v], view_off[v + 1]):
            near = False
            for i in range(proj.shape[1]):
                dx = proj[v, i, 0] - points[c, 0]
                dy = proj[v, i, 1] - points[c, 1]
                near = near or (dx * dx + dy * dy <= g2 and not hidden_in(obs3, i, v))
            n += 0 if near else 1
    return n


@njit(cache=True, nogil=True)
def claim_detections(proj, points, view_off, obs3, claimers, gate, claimed):
    """Mark the detections that the markers flagged in ``claimers`` (n_markers,) explain:
    each such marker's nearest detection in each view, if within ``gate`` pixels (a marker
    far from every detection, e.g. occluded, or hidden in the view, claims nothing)."""
    claimed[:] = False
    g2 = gate * gate
    for v in range(proj.shape[0]):
        a = view_off[v]
        b = view_off[v + 1]
        for i in range(proj.shape[1]):
            if not claimers[i] or hidden_in(obs3, i, v):
                continue
            best = g2
            arg = -1
            for c in range(a, b):
                dx = proj[v, i, 0] - points[c, 0]
                dy = proj[v, i, 1] - points[c, 1]
                d2 = dx * dx + dy * dy
                if d2 <= best:
                    best = d2
                    arg = c
            if arg >= 0:
                claimed[arg] = True
