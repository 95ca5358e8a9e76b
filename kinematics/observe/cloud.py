"""Triangulation of unlabelled marker detections into a 3D point cloud per frame.

The markers carry no identity, so which detection in view A is the same marker as which in
view B has to be found from the geometry. :func:`triangulate_unlabelled` does it frame by
frame (many frames at once, vectorised with NumPy):

1. **Candidates.** For every pair of views (a, b), every pair of detections whose symmetric
   epipolar distance (the larger of the two point-to-epipolar-line distances) is at most
   ``match_px``. The detections are first undistorted to ideal pixel coordinates
   (``cv2.undistortPoints(..., P=K)``), in which each camera is linear: ``K [R | t]`` for
   pinhole cameras, ``[P; 0 0 0 1]`` for orthographic (affine) ones. The fundamental matrix
   ``F = [P_b C]_x P_b P_a^+``, with ``C`` the null vector of ``P_a`` (the centre, at
   infinity for an affine camera), holds for both kinds and their mixtures.
2. **Support.** Each candidate is triangulated from its two detections
   (:func:`kinematics.observe.triangulation.triangulate_linear`), reprojected into every view, and
   in each view the nearest detection within ``support_px`` supports it. Hypotheses with
   fewer than ``min_views`` supporting views are dropped.
3. **Refinement.** Each hypothesis is re-triangulated from all its supporting detections,
   its support recomputed around the refined point, and the point triangulated once more
   from that final support; its error is the mean reprojection error over it. Hypotheses
   with the same support are one (every view pair of a marker proposes it).
4. **Duplicates and ghosts.** Hypotheses are ranked (more views first, then lower error)
   and accepted greedily, except that one is rejected
   - when an accepted point projects within ``support_px`` of it in every view where both
     are visible: the same marker proposed with a slightly different support; and
   - when fewer than two of its supporting detections are its own (not claimed by accepted
     points): a *ghost*, an epipolar coincidence among other markers' detections (or one
     clutter detection) that chance confirmed in a third view. In a dense cloud this
     happens a few times per frame; a real marker has its own detections in at least the
     two views it could be triangulated from.
   Two distinct markers may share a detection in some views (their blobs fused into one in
   that image): they stay apart as long as some view separates them by more than
   ``support_px`` and each keeps a detection of its own.
5. **Result.** Points per frame in rank order, NaN-padded to the largest count.

Parameters
----------
match_px
    Epipolar tolerance in pixels: detection noise plus calibration error. Larger finds
    markers under worse calibration but proposes more chance pairs (more work, more
    ghosts to reject).
support_px
    How far a detection may lie from a reprojection and still support it, about a blob
    radius: a fused blob's centroid lies between its markers, so this must cover half
    their separation. Also the distance below which two points are one marker.
min_views
    Views a point must be supported by. 3 suppresses chance matches; with 2 every epipolar
    coincidence between two views becomes a point (unless the ghost rule of step 4
    rejects it).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from kinematics.cameras import Camera, OrthographicCamera, pack_cameras, project_packed
from kinematics.errors import KinematicsError
from kinematics.observe.observations import Observations
from kinematics.observe.triangulation import _camera_list, triangulate_linear

__all__ = ["Cloud", "cloud_observations", "pixels_per_unit", "triangulate_unlabelled"]

#: Sentinel coordinate: padding detections sit at +_FAR, unprojectable points at -_FAR, so
#: neither is ever within any tolerance of anything (and no NaN reaches an argmin).
_FAR = 1e15
#: Default ``support_px``: about a 4-px marker's blob radius plus detection noise.
SUPPORT_PX = 3.0
#: Upper bound on (frames x detections² x view pairs) handled at once: bounds the
#: temporaries of the candidate and support steps to some tens of MB.
_CHUNK_WORK = 1_000_000


@dataclass(frozen=True, eq=False)
class Cloud:
    """Unlabelled 3D points per frame and the detections behind them.

    Attributes
    ----------
    xyz : (n_frames, K, 3) world coordinates, NaN-padded beyond a frame's points
    views : (n_frames, K) int64 number of views supporting each point (0 in padding)
    error : (n_frames, K) mean reprojection error in px over the supporting views
        (NaN in padding)
    support : (n_frames, K, n_views) int64 row into ``points`` of the detection supporting
        the point in each view, -1 where none
    """

    xyz: np.ndarray
    views: np.ndarray
    error: np.ndarray
    support: np.ndarray

    @property
    def counts(self) -> np.ndarray:
        """(n_frames,) number of points in each frame."""
        return (self.views > 0).sum(axis=1)


# --- inputs ---------------------------------------------------------------------------------


def _positive(value, field: str) -> float:
    """A finite tolerance > 0 in pixels."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        out = math.nan
    if isinstance(value, bool) or not (math.isfinite(out) and out > 0.0):
        raise KinematicsError(f"expected a finite number of pixels > 0, got {value!r}",
                              field=field)
    return out


def _layout(points, offsets, n_views: int) -> tuple[np.ndarray, np.ndarray]:
    """Validate the ragged frame-major layout of :mod:`kinematics.observe.observations`."""
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise KinematicsError("points must be numbers", field="points") from None
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise KinematicsError(f"expected points of shape (n, 2), got {pts.shape}",
                              field="points")
    if not np.isfinite(pts).all():
        raise KinematicsError("points must be finite (drop missing detections)",
                              field="points")
    off = np.asarray(offsets)
    if off.ndim != 1 or off.size == 0 or (off.size - 1) % n_views:
        raise KinematicsError(f"expected offsets of shape (n_frames * {n_views} views + 1,), "
                              f"got {off.shape}", field="offsets")
    if not np.issubdtype(off.dtype, np.integer):
        raise KinematicsError(f"offsets must be integers, got {off.dtype}", field="offsets")
    off = off.astype(np.int64)
    if off[0] != 0 or off[-1] != len(pts) or (np.diff(off) < 0).any():
        raise KinematicsError(f"offsets must rise from 0 to the number of points "
                              f"({len(pts)})", field="offsets")
    return np.ascontiguousarray(pts), off


def _min_views(value, n_views: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise KinematicsError(f"expected an integer, got {value!r}", field="min_views")
    if not 2 <= value <= n_views:
        raise KinematicsError(f"expected 2 <= min_views <= {n_views} (the number of views), "
                              f"got {value}", field="min_views")
    return int(value)


# --- geometry -------------------------------------------------------------------------------


def linear_matrix(cam: Camera) -> np.ndarray:
    """3x4 matrix mapping world points to undistorted pixels (homogeneous)."""
    if isinstance(cam, OrthographicCamera):
        return np.vstack([cam.P, [0.0, 0.0, 0.0, 1.0]])
    return cam.K @ np.hstack([cam.R, cam.t[:, None]])


def ideal_pixels(cam: Camera, pts: np.ndarray) -> np.ndarray:
    """(n, 2) ideal (undistorted) pixel coordinates of ``pts``, in which ``cam`` is linear
    (:func:`linear_matrix`); an orthographic camera's are its own."""
    if isinstance(cam, OrthographicCamera) or len(pts) == 0:
        return np.asarray(pts, float)
    src = np.ascontiguousarray(np.asarray(pts, float).reshape(-1, 1, 2))
    return cv2.undistortPoints(src, cam.K, cam.dist, P=cam.K).reshape(-1, 2)


def fundamental(pa: np.ndarray, pb: np.ndarray) -> np.ndarray:
    """F with ``x_b^T F x_a = 0`` for the linear cameras ``pa``, ``pb``: ``[P_b C]_x P_b
    P_a^+``. ``C`` spans the null space of ``P_a`` (a point at infinity for an affine
    camera), so the form holds for pinhole, orthographic and mixed pairs. Scaled to unit
    norm; zero when the two cameras share a centre (no epipolar geometry)."""
    c = np.linalg.svd(pa)[2][-1]
    e = pb @ c
    ex = np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])
    f = ex @ pb @ np.linalg.pinv(pa)
    norm = np.linalg.norm(f)
    return f / norm if norm > 1e-12 * np.linalg.norm(pb) else np.zeros((3, 3))


class _Chunk:
    """The detections of some frames, padded to ``(n_views, n_frames, D + 1)`` arrays.

    Column ``D`` is always padding, so support index -1 selects it: ``pix`` is NaN there
    (a missing keypoint for the DLT), ``far_x``/``far_y`` (float32) are +_FAR (never near
    a reprojection) and
    ``rows`` is -1.
    """

    def __init__(self, pts, off, n_views: int, f0: int, f1: int, cams: Sequence[Camera]):
        nf = f1 - f0
        bounds = off[f0 * n_views: f1 * n_views + 1]
        counts = np.diff(bounds)
        self.d = d = int(counts.max()) if counts.size else 0
        n = int(counts.sum())
        seg = np.repeat(np.arange(nf * n_views), counts)
        within = np.arange(n) - np.repeat(bounds[:-1] - bounds[0], counts)
        self.rows = rows = np.full((n_views, nf, d + 1), -1, np.int64)
        rows[seg % n_views, seg // n_views, within] = bounds[0] + np.arange(n)
        valid = rows >= 0
        safe = pts[np.maximum(rows, 0)] if len(pts) else np.zeros((*rows.shape, 2))
        self.pix = np.where(valid[..., None], safe, np.nan)
        far = np.where(valid[..., None], safe, _FAR).astype(np.float32)
        self.far_x, self.far_y = far[..., 0].copy(), far[..., 1].copy()
        self.lin = self._undistort(cams, valid)

    def _undistort(self, cams, valid) -> np.ndarray:
        """Ideal (undistorted) pixel coordinates, in which the cameras are linear."""
        lin = self.pix.copy()
        for v, cam in enumerate(cams):
            if valid[v].any():
                lin[v][valid[v]] = ideal_pixels(cam, self.pix[v][valid[v]])
        return lin


def _candidates(chunk: _Chunk, a: int, b: int, fmat: np.ndarray, match_px: float):
    """(frame, detection in a, detection in b) of every pair within ``match_px`` of each
    other's epipolar line. NaN padding compares False and drops out."""
    xa, ya = chunk.lin[a, ..., 0], chunk.lin[a, ..., 1]
    xb, yb = chunk.lin[b, ..., 0], chunk.lin[b, ..., 1]
    lb = [fmat[k, 0] * xa + fmat[k, 1] * ya + fmat[k, 2] for k in range(3)]  # lines in b
    la = [fmat[0, k] * xb + fmat[1, k] * yb + fmat[2, k] for k in range(2)]  # lines in a
    num = np.abs(lb[0][:, :, None] * xb[:, None, :] + lb[1][:, :, None] * yb[:, None, :]
                 + lb[2][:, :, None])
    norm = np.minimum(np.hypot(lb[0], lb[1])[:, :, None], np.hypot(la[0], la[1])[:, None, :])
    ok = (num <= match_px * norm) & (norm > 0.0)  # norm 0: a detection at the epipole
    return np.nonzero(ok)


def _triangulate(cams, chunk: _Chunk, fr: np.ndarray, sup: np.ndarray):
    """DLT of each hypothesis from its detections ``sup`` (n, n_views), -1 = none:
    (n, 3) points and (n,) mean reprojection errors in px."""
    n_views = sup.shape[1]
    xy = np.empty((n_views, len(fr), 1, 2))
    for v in range(n_views):
        xy[v, :, 0] = chunk.pix[v, fr, sup[:, v]]
    tri = triangulate_linear(cams, xy)
    return tri.xyz[:, 0], tri.error[:, 0]


def _project(packed, xyz: np.ndarray) -> np.ndarray:
    """(n_views, n, 2) pixels of ``xyz`` (n, 3); NaN where not visible."""
    flat = np.ascontiguousarray(xyz)
    return np.stack([project_packed(packed, v, flat) for v in range(len(packed.kind))])


def _support(chunk: _Chunk, fr: np.ndarray, proj: np.ndarray, support_px: float):
    """Nearest detection to each reprojection, per view, if within ``support_px``:
    (n, n_views) indices, -1 where none. Dense over the frame's detections (there are tens),
    in float32 with in-place arithmetic: this is the hot loop, and memory-bound."""
    n_views, n = proj.shape[:2]
    sup = np.full((n, n_views), -1, np.int64)
    at = np.arange(n)
    limit = np.float32(support_px * support_px)
    for v in range(n_views):
        p = np.nan_to_num(proj[v], nan=-_FAR).astype(np.float32)
        dx = chunk.far_x[v][fr]  # (n, D + 1) copies
        dy = chunk.far_y[v][fr]
        dx -= p[:, 0, None]
        dy -= p[:, 1, None]
        dx *= dx
        dy *= dy
        dx += dy
        j = dx.argmin(axis=1)
        ok = dx[at, j] <= limit
        sup[ok, v] = j[ok]
    return sup


def _first_unique(fr: np.ndarray, sup: np.ndarray, base: int) -> np.ndarray:
    """Indices of the first hypothesis of each distinct (frame, support), in order: every
    view pair of a marker proposes the same hypothesis."""
    n_frames = int(fr.max()) + 1 if fr.size else 1
    if sup.shape[1] * math.log2(base) + math.log2(n_frames) < 62:  # one int64 key each
        key = fr.astype(np.int64)
        for v in range(sup.shape[1]):
            key = key * base + (sup[:, v] + 1)
        first = np.unique(key, return_index=True)[1]
    else:
        first = np.unique(np.column_stack([fr, sup]), axis=0, return_index=True)[1]
    return np.sort(first)


# --- duplicates -----------------------------------------------------------------------------


def _frame_pairs(fr: np.ndarray, n_frames: int):
    """All (i, j), i < j, of hypotheses in the same frame; ``fr`` sorted."""
    c = np.bincount(fr, minlength=n_frames)
    start = np.cumsum(c) - c
    sq = c * c
    grp = np.repeat(np.arange(n_frames), sq)
    local = np.arange(int(sq.sum())) - np.repeat(np.cumsum(sq) - sq, sq)
    i = start[grp] + local // c[grp]
    j = start[grp] + local % c[grp]
    keep = i < j
    return i[keep], j[keep]


def _greedy(n: int, i, j, same, share, sup) -> np.ndarray:
    """Accept hypotheses in rank order, rejecting one when an earlier accepted one is
    ``same`` marker, or when earlier accepted ones claim all but one of its detections (a
    ghost: nothing in it that another point does not already explain, bar one detection).

    Sequential greedy, run in rounds so that it vectorises: a hypothesis is decided once
    every earlier one it is related to (pairs ``i`` < ``j``) is decided, which holds for the
    first undecided one of each frame each round. ``share`` (pairs, n_views) says in which
    views a pair uses the same detection; ``sup`` (n, n_views) is -1 where no support.
    """
    state = np.zeros(n, np.int8)  # 0 open, 1 accepted, 2 rejected
    needed = (sup >= 0).sum(axis=1)
    while (state == 0).any():
        live = state[j] == 0
        i, j, same, share = i[live], j[live], same[live], share[live]
        acc, opn = state[i] == 1, state[i] == 0
        dup = np.zeros(n, bool)
        dup[j[acc & same]] = True
        claimed = np.zeros(sup.shape, bool)
        np.logical_or.at(claimed, j[acc], share[acc])
        ghost = needed - claimed.sum(axis=1) < 2
        wait = np.zeros(n, bool)
        wait[j[opn]] = True
        undecided = state == 0
        state[undecided & (dup | ghost)] = 2
        state[(state == 0) & ~wait] = 1
    return state == 1


def _deduplicate(packed, fr, xyz, err, sup, n_frames: int, support_px: float):
    """Rank hypotheses (frame, more views, lower error) and keep the accepted ones: the
    indices, in order."""
    views = (sup >= 0).sum(axis=1)
    order = np.lexsort((err, -views, fr))
    fr_s, sup_s = fr[order], sup[order]
    i, j = _frame_pairs(fr_s, n_frames)
    proj = _project(packed, xyz[order])
    d = np.hypot(*np.moveaxis(proj[:, i] - proj[:, j], -1, 0))  # (n_views, pairs)
    same = ((d <= support_px) | np.isnan(d)).all(axis=0)
    share = (sup_s[i] == sup_s[j]) & (sup_s[j] >= 0)
    related = same | share.any(axis=1)
    keep = _greedy(len(order), i[related], j[related], same[related], share[related], sup_s)
    return order[keep]


# --- driver ---------------------------------------------------------------------------------


def _solve_chunk(cams, packed, fmats, chunk: _Chunk, match_px, support_px, min_views):
    """Steps 1-4 for the frames of one chunk: (frame, xyz, views, error, rows) of the
    accepted points, in frame then rank order."""
    nf = chunk.rows.shape[1]
    n_views = len(cams)
    found = [(_candidates(chunk, a, b, f, match_px), a, b) for (a, b), f in fmats.items()]
    fr = np.concatenate([c[0] for c, _, _ in found]).astype(np.int64)
    if fr.size == 0:
        return None
    sup = np.full((fr.size, n_views), -1, np.int64)
    at = 0
    for (_, ia, ib), a, b in found:
        sup[at: at + ia.size, a], sup[at: at + ia.size, b] = ia, ib
        at += ia.size
    base = chunk.d + 1
    for _ in range(2):  # two-view points, then refined ones
        xyz, _ = _triangulate(cams, chunk, fr, sup)
        sup = _support(chunk, fr, _project(packed, xyz), support_px)
        keep = (sup >= 0).sum(axis=1) >= min_views
        fr, sup = fr[keep], sup[keep]
        first = _first_unique(fr, sup, base)
        fr, sup = fr[first], sup[first]
        if fr.size == 0:
            return None
    xyz, err = _triangulate(cams, chunk, fr, sup)
    ok = np.isfinite(err)
    fr, sup, xyz, err = fr[ok], sup[ok], xyz[ok], err[ok]
    keep = _deduplicate(packed, fr, xyz, err, sup, nf, support_px)
    fr, sup = fr[keep], sup[keep]
    rows = np.stack([chunk.rows[v, fr, sup[:, v]] for v in range(n_views)], axis=1)
    return fr, xyz[keep], (sup >= 0).sum(axis=1), err[keep], rows


def _assemble(parts, n_frames: int, n_views: int) -> Cloud:
    """Pad the accepted points of every frame into a :class:`Cloud`."""
    fr = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
    counts = np.bincount(fr, minlength=n_frames)
    k = int(counts.max()) if n_frames else 0
    slot = np.arange(fr.size) - np.repeat(np.cumsum(counts) - counts, counts)
    xyz = np.full((n_frames, k, 3), np.nan)
    views = np.zeros((n_frames, k), np.int64)
    error = np.full((n_frames, k), np.nan)
    support = np.full((n_frames, k, n_views), -1, np.int64)
    if parts:
        xyz[fr, slot] = np.concatenate([p[1] for p in parts])
        views[fr, slot] = np.concatenate([p[2] for p in parts])
        error[fr, slot] = np.concatenate([p[3] for p in parts])
        support[fr, slot] = np.concatenate([p[4] for p in parts])
    return Cloud(xyz, views, error, support)


def triangulate_unlabelled(cameras, points, offsets, *, match_px: float = 2.0,
                           support_px: float = SUPPORT_PX, min_views: int = 3,
                           progress: Callable[[int, int], object] | None = None) -> Cloud:
    """Triangulate unlabelled detections of several calibrated views into 3D points.

    Parameters
    ----------
    cameras : sequence or mapping of Camera, one per view (a mapping's values in order)
    points : (n, 2) detections in pixels
    offsets : (n_frames * n_views + 1,) int; view ``v`` of frame ``f`` owns rows
        ``offsets[f * n_views + v]:offsets[f * n_views + v + 1]`` of ``points`` (the layout
        of :class:`kinematics.observe.observations.Observations`)
    match_px : epipolar tolerance of a candidate pair, px
    support_px : distance from a reprojection within which a detection supports it, px
    min_views : views a point must be supported by (>= 2)
    progress : callable(done_frames, total_frames), optional, called after each batch

    Returns
    -------
    Cloud

    Raises
    ------
    KinematicsError
        Bad cameras, layout or parameters; the error's field names the argument.
    """
    cams = _camera_list(cameras)
    n_views = len(cams)
    pts, off = _layout(points, offsets, n_views)
    match_px = _positive(match_px, "match_px")
    support_px = _positive(support_px, "support_px")
    min_views = _min_views(min_views, n_views)
    if progress is not None and not callable(progress):
        raise KinematicsError(f"expected a callable, got {progress!r}", field="progress")
    n_frames = (off.size - 1) // n_views
    packed = pack_cameras(cams)
    mats = [linear_matrix(c) for c in cams]
    fmats = {(a, b): fundamental(mats[a], mats[b])
             for a, b in itertools.combinations(range(n_views), 2)}
    d = int(np.diff(off).max()) if off.size > 1 else 0
    step = max(1, _CHUNK_WORK // max(1, (d + 1) ** 2 * len(fmats)))
    parts = []
    for f0 in range(0, n_frames, step):
        f1 = min(n_frames, f0 + step)
        chunk = _Chunk(pts, off, n_views, f0, f1, cams)
        part = _solve_chunk(cams, packed, fmats, chunk, match_px, support_px, min_views)
        if part is not None:
            parts.append((part[0] + f0, *part[1:]))
        if progress is not None:
            progress(f1, n_frames)
    return _assemble(parts, n_frames, n_views)


#: Step of the numerical derivative of a projection (length units, relative to the scale).
_DERIV_STEP = 1e-4


def pixels_per_unit(cameras, xyz: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """Pixels per length unit at each point: the mean over the views that see it of the
    projection's local scale (the Frobenius norm of its 2×3 Jacobian / √2, i.e. f / depth
    for a pinhole camera), so a 3D distance times it reads like a distance in the images.

    xyz (n, 3); seen (n_views, n) bool; returns (n,) (0 where no view sees a point)."""
    cams = _camera_list(cameras)
    n = len(xyz)
    total = np.zeros(n)
    for v, cam in enumerate(cams):
        if not seen[v].any():
            continue
        p = xyz[seen[v]]
        # a step per point, so a point's scale does not depend on the others
        h = _DERIV_STEP * np.maximum(1.0, np.abs(p).max(axis=1))
        base = cam.project(p)
        norm2 = np.zeros(len(p))
        for k in range(3):
            step = p.copy()
            step[:, k] += h
            norm2 += ((cam.project(step) - base) ** 2).sum(axis=1)
        total[seen[v]] += np.sqrt(norm2 / 2.0) / h
    count = seen.sum(axis=0)
    return np.where(count > 0, total / np.maximum(count, 1), 0.0)


def cloud_observations(cameras, obs: Observations, unseen=None, **options) -> Observations:
    """Unlabelled observations ``obs`` with their cloud (:func:`triangulate_unlabelled`,
    ``options`` passed on) in the layout of :meth:`Observations.with_cloud`: x, y, z and
    :func:`pixels_per_unit` of each point.

    ``unseen`` (n_views, n_markers) bool, optional: markers each view does not show (views
    of one colour of markers, ``Fitter(view_markers=...)``). The views that show the same
    markers (one colour, seen by several cameras) are triangulated together, apart from the
    others, and each point gets a column per marker after x, y, z, s: 1 where the marker
    may take it (:func:`kinematics._kernels.error2d.may_take`).
    """
    cams = _camera_list(cameras)
    if unseen is None or not np.any(unseen):
        return obs.with_cloud(_cloud_rows(cams, obs.points, obs.offsets, options))
    unseen = np.asarray(unseen, bool)
    parts = []
    for views in view_groups(unseen):
        pts, off = _views_of(obs, views)
        rows = _cloud_rows([cams[v] for v in views], pts, off, options)
        may = np.where(rows[..., 3:4] > 0, ~unseen[views[0]], False).astype(float)
        parts.append(np.concatenate([rows, may], axis=2))
    return obs.with_cloud(np.concatenate(parts, axis=1))


def view_groups(unseen: np.ndarray) -> list[list[int]]:
    """The views that show the same markers (one colour, seen by several cameras), grouped,
    from ``unseen`` (n_views, n_markers); a view that shows no marker is in no group."""
    groups: dict[bytes, list[int]] = {}
    for v, row in enumerate(np.asarray(unseen, bool)):
        if not row.all():
            groups.setdefault(row.tobytes(), []).append(v)
    return list(groups.values())


def _cloud_rows(cams, points, offsets, options) -> np.ndarray:
    """(n_frames, k, 4) x, y, z, px per unit of the triangulated points (zeros: padding)."""
    cloud = triangulate_unlabelled(cams, points, offsets, **options)
    f, k = cloud.xyz.shape[:2]
    out = np.zeros((f, k, 4))
    ok = cloud.views > 0
    out[..., :3] = np.where(ok[..., None], cloud.xyz, 0.0)
    seen = np.moveaxis(cloud.support >= 0, 2, 0)[:, ok]  # (n_views, points)
    out[ok, 3] = pixels_per_unit(cams, cloud.xyz[ok], seen)
    return out


def _views_of(obs: Observations, views: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """``points, offsets`` of some views of every frame (the ragged layout)."""
    nv = obs.n_views
    starts = obs.offsets[:-1].reshape(obs.n_frames, nv)[:, views].ravel()
    counts = np.diff(obs.offsets).reshape(obs.n_frames, nv)[:, views].ravel()
    off = np.zeros(counts.size + 1, np.int64)
    np.cumsum(counts, out=off[1:])
    rows = np.repeat(starts - off[:-1], counts) + np.arange(off[-1])
    return np.ascontiguousarray(obs.points[rows].reshape(-1, 2)), off
