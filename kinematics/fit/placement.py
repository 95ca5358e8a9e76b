"""Placing a freely moving body: a seed pose of each free root, per frame.

A free root (``Root.mode == "free"``) has no fixed position: each frame, before annealing,
its pose is *seeded* from the detections, and the fit then searches a window around the
seed (translation and rotation offsets in the state, :mod:`kinematics.fit.problem`).

1. **Triangulation** (:func:`triangulate_candidates`). Every pair of detections from two
   views is triangulated by linear least squares (DLT; pinhole points undistorted with
   OpenCV first, orthographic views as affine rows, so a pair of orthographic views works
   too), kept if it reprojects within ``gate_px`` in both views, then supported by every
   other view with a detection within the gate and re-solved over all its views. Duplicates
   (the same detections) are merged. The result is a set of 3D candidates, some of them
   false matches.
2. **Registration** (:func:`register_root`). The root's own markers (those on the segments of
   the root joint) form a rigid constellation. With a prediction (the previous frame's
   seed), each model marker takes the nearest candidate within ``2 tol``; the pose is the
   least-squares rigid fit (Kabsch) when at least three non-collinear markers are matched.
   Without a prediction, or when the predicted match fails (after a gap, a jump), every
   triple of candidates whose distances match the model's widest triangle within ``tol`` is
   tried (re-acquisition); when more than one pose explains three or more root markers, the
   fitter fits the whole body from each and keeps the lowest E (a planar, left-right
   symmetric constellation fits its mirror pose about as well as the true one). With fewer
   than three root markers only the position is seeded (the named root marker, nearest to
   the prediction or to ``Root.position`` at first), and the rotation keeps the previous
   frame's.
3. **Gaps** (:func:`place_roots`). A frame whose root cannot be registered takes the previous
   frame's seed; frames before the first registered one take its seed.
"""

from __future__ import annotations

import itertools

import cv2
import numpy as np

from kinematics.cameras import OrthographicCamera
from kinematics.model import Body
from kinematics.model.fk import forward_kinematics_reference
from kinematics.observe.triangulation import triangulate_linear

#: Default reprojection gate of triangulation, pixels.
DEFAULT_GATE_PX = 4.0


def _linear_rows(cam, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two linear equations ``A X = b`` per image point: A (n, 2, 3), b (n, 2)."""
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    if isinstance(cam, OrthographicCamera):
        a = np.broadcast_to(cam.P[:, :3], (len(uv), 2, 3)).copy()
        return a, uv - cam.P[:, 3]
    norm = cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.K, cam.dist).reshape(-1, 2)
    r, t = cam.R, cam.t
    a = np.empty((len(uv), 2, 3))
    b = np.empty((len(uv), 2))
    for k in range(2):
        a[:, k] = r[k] - norm[:, k, None] * r[2]
        b[:, k] = norm[:, k] * t[2] - t[k]
    return a, b


def _solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least-squares X of stacked rows: a (n, m, 3), b (n, m) -> (n, 3)."""
    ata = np.einsum("nmi,nmj->nij", a, a)
    atb = np.einsum("nmi,nm->ni", a, b)
    ok = np.abs(np.linalg.det(ata)) > 1e-12
    out = np.full((len(a), 3), np.nan)
    if ok.any():
        out[ok] = np.linalg.solve(ata[ok], atb[ok][..., None])[..., 0]
    return out


def triangulate_candidates(cameras, views: list[np.ndarray], gate_px: float = DEFAULT_GATE_PX
                           ) -> tuple[np.ndarray, np.ndarray]:
    """3D candidate points of one frame from unlabelled detections in several views.

    Parameters
    ----------
    cameras : sequence of Camera, one per view
    views : list of (n_v, 2) arrays, the detections of each view (finite)
    gate_px : reprojection gate, pixels

    Returns
    -------
    points : (k, 3) candidates
    support : (k,) int, views supporting each candidate (>= 2)
    """
    nv = len(cameras)
    rows = [_linear_rows(cameras[v], views[v]) if len(views[v]) else None for v in range(nv)]
    found: dict[tuple, np.ndarray] = {}
    for va, vb in itertools.combinations(range(nv), 2):
        if rows[va] is None or rows[vb] is None:
            continue
        na, nb = len(views[va]), len(views[vb])
        ia, ib = np.meshgrid(np.arange(na), np.arange(nb), indexing="ij")
        ia, ib = ia.ravel(), ib.ravel()
        a = np.concatenate([rows[va][0][ia], rows[vb][0][ib]], axis=1)
        b = np.concatenate([rows[va][1][ia], rows[vb][1][ib]], axis=1)
        x = _solve(a, b)
        good = np.isfinite(x).all(axis=1)
        for v, idx in ((va, ia), (vb, ib)):
            err = np.linalg.norm(cameras[v].project(x) - views[v][idx], axis=1)
            good &= err < gate_px
        for k in np.flatnonzero(good):
            members = {va: int(ia[k]), vb: int(ib[k])}
            for v in range(nv):
                if v in members or rows[v] is None:
                    continue
                d = np.linalg.norm(views[v] - cameras[v].project(x[k]), axis=1)
                j = int(np.argmin(d))
                if d[j] < gate_px:
                    members[v] = j
            key = tuple(sorted(members.items()))
            if key in found:
                continue
            aa = np.concatenate([rows[v][0][[i]] for v, i in key], axis=1)
            bb = np.concatenate([rows[v][1][[i]] for v, i in key], axis=1)
            found[key] = _solve(aa, bb)[0]
    if not found:
        return np.empty((0, 3)), np.empty(0, np.int64)
    keys = list(found)
    pts = np.array([found[k] for k in keys])
    support = np.array([len(k) for k in keys], np.int64)
    keep = np.isfinite(pts).all(axis=1)
    return pts[keep], support[keep]


def kabsch(model: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Rotation R, translation t minimising ``sum |R m + t - x|²``; and the RMS residual."""
    mc, tc = model.mean(axis=0), target.mean(axis=0)
    h = (model - mc).T @ (target - tc)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    t = tc - r @ mc
    res = model @ r.T + t - target
    return r, t, float(np.sqrt((res ** 2).sum(axis=1).mean()))


class RootModel:
    """The rigid marker constellation of one free root, in the root joint's frame at the
    start posture (offsets zero), and the tolerances derived from it.

    ``local`` (k, 3) marker positions with the root at the origin and no root rotation;
    ``anchor`` the marker used when only a position can be seeded; ``tol`` the match
    tolerance in length units.
    """

    def __init__(self, body: Body, chain: int, translation_window: float) -> None:
        ch = body.chains[chain]
        names = [m.name for s in ch.root_joint.segments for m in s.markers]
        mean = body.mean_posture_deg()
        refs = body.axis_refs()
        root_ix = [r.index for r in refs if r.joint == ch.root_joint.name]
        mean[root_ix] = 0.0
        roots = np.zeros((len(body.chains), 3))
        fk = forward_kinematics_reference(body, mean, roots)
        all_names = body.marker_names
        self.names = names
        self.local = np.array([fk.markers[all_names.index(n)] for n in names]).reshape(-1, 3)
        self.anchor = names.index(ch.root.marker) if ch.root.marker in names else 0
        self.hint = np.asarray(ch.root.position, float)
        d = np.linalg.norm(self.local[:, None] - self.local[None], axis=2)
        self.rigid = len(names) >= 3 and _spread(self.local) > 1e-6
        pair = d[np.triu_indices(len(names), 1)]
        self.tol = (0.25 * float(pair.min()) if self.rigid and pair.min() > 0
                    else float(translation_window))
        self.triangle = _widest_triangle(self.local) if self.rigid else None


def _spread(points: np.ndarray) -> float:
    """Second singular value of the centred points: zero when they are collinear."""
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return float(s[1]) if s.size > 1 else 0.0


def _widest_triangle(points: np.ndarray) -> tuple[int, int, int]:
    best, area = (0, 1, 2), -1.0
    for tri in itertools.combinations(range(len(points)), 3):
        a, b, c = points[list(tri)]
        s = np.linalg.norm(np.cross(b - a, c - a))
        if s > area:
            best, area = tri, s
    return best


def root_windows(body: Body) -> np.ndarray:
    """Default search windows of each free root, (n_free_chains, 2): translation (length
    units) and rotation (degrees). A root with a rigid constellation (>= 3 non-collinear
    markers) is seeded in full: a translation window of half its smallest marker distance
    (skin markers move by a millimetre or two against each other, and the seed with them)
    and 20°. Otherwise only its position is seeded: a quarter of the chain's
    longest segment and the full turn (180°)."""
    out = []
    for chain in body.chains:
        if not chain.root.free:
            continue
        segs = [s.length for _, s in Body(body.name, (chain,), body.units).segments()]
        reach = 0.25 * max(segs, default=1.0) or 1.0
        tmp = RootModel(body, body.chains.index(chain), reach)
        w_t, w_r = (2.0 * tmp.tol, 20.0) if tmp.rigid else (reach, 180.0)
        if chain.root.translation_window is not None:
            w_t = chain.root.translation_window
        if chain.root.rotation_window_deg is not None:
            w_r = chain.root.rotation_window_deg
        out.append((w_t, min(w_r, 180.0)))
    return np.array(out, dtype=float).reshape(-1, 2)


def register_root(model: RootModel, candidates: np.ndarray, prediction=None, resolve=None
                  ) -> tuple[np.ndarray, np.ndarray, int] | None:
    """Seed pose of one root from a frame's 3D candidates.

    Parameters
    ----------
    model : RootModel
    candidates : (k, 3)
    prediction : (R (3, 3), t (3,)) or None
        The previous frame's seed.
    resolve : callable(poses) -> index, optional
        Picks among several poses that explain the constellation (:func:`ambiguous`);
        without it, the best residual wins.

    Returns
    -------
    (R, t, n_matched) or None when the root cannot be placed in this frame.
    """
    if candidates is None or len(candidates) == 0:
        return None
    seed = _predicted(model, candidates, prediction)
    if seed is not None:
        return seed
    if model.rigid:
        poses = search_poses(model, candidates)
        if not poses:
            return None
        pick = resolve(poses) if resolve is not None and ambiguous(model, poses) else 0
        return poses[pick][:3]
    r = np.eye(3) if prediction is None else prediction[0]
    ref = model.hint if prediction is None else prediction[1] + r @ model.local[model.anchor]
    k = int(np.argmin(np.linalg.norm(candidates - ref, axis=1)))
    return r, candidates[k] - r @ model.local[model.anchor], 1


def _predicted(model: RootModel, candidates: np.ndarray, prediction):
    """The pose matched near the prediction (the previous frame's seed), or None."""
    if prediction is None or len(candidates) == 0:
        return None
    r, t = prediction
    hit = _match(model.local @ r.T + t, candidates, 2.0 * model.tol)
    if model.rigid:
        ok = hit >= 0
        if ok.sum() >= 3 and _spread(model.local[ok]) > 1e-6:
            r2, t2, rms = kabsch(model.local[ok], candidates[hit[ok]])
            if rms < model.tol:
                return r2, t2, int(ok.sum())
        return None
    if hit[model.anchor] >= 0:
        return r, candidates[hit[model.anchor]] - r @ model.local[model.anchor], 1
    return None


def _match(predicted: np.ndarray, candidates: np.ndarray, tol: float) -> np.ndarray:
    """Nearest candidate of each predicted marker within ``tol`` (-1: none); a candidate
    claimed twice goes to the nearer marker."""
    d = np.linalg.norm(predicted[:, None] - candidates[None], axis=2)
    hit = np.argmin(d, axis=1)
    near = d[np.arange(len(predicted)), hit]
    hit = np.where(near < tol, hit, -1)
    for c in set(hit[hit >= 0].tolist()):
        who = np.flatnonzero(hit == c)
        if len(who) > 1:
            keep = who[np.argmin(near[who])]
            hit[who[who != keep]] = -1
    return hit


def search_poses(model: RootModel, candidates: np.ndarray, keep: int = 8) -> list:
    """Distinct poses ``(R, t, n_matched, rms)`` that explain >= 3 root markers, best first
    (most markers, then lowest residual); at most ``keep``. Several of them fit about
    equally well when the constellation is nearly symmetric (two hips and two pelvis
    markers: the left-right mirror), which only the rest of the body can tell apart."""
    a, b, c = model.triangle
    m = model.local
    d = np.linalg.norm(candidates[:, None] - candidates[None], axis=2)
    tol = model.tol
    ab = np.abs(d - np.linalg.norm(m[a] - m[b])) < tol
    ac = np.abs(d - np.linalg.norm(m[a] - m[c])) < tol
    bc = np.abs(d - np.linalg.norm(m[b] - m[c])) < tol
    found = []
    for i, j in zip(*np.nonzero(ab), strict=True):
        for k in np.flatnonzero(ac[i] & bc[j]):
            if k in (i, j) or i == j:
                continue
            r, t, _ = kabsch(m[[a, b, c]], candidates[[i, j, k]])
            # Skin markers are not rigid: a marker a little off the triangle's pose still
            # belongs to it (the residual over all matched markers decides below).
            hit = _match(m @ r.T + t, candidates, 2.0 * tol)
            ok = hit >= 0
            if ok.sum() < 3:
                continue
            r, t, rms = kabsch(m[ok], candidates[hit[ok]])
            if rms < tol:
                found.append((r, t, int(ok.sum()), rms))
    found.sort(key=lambda p: (-p[2], p[3]))
    distinct: list = []
    for pose in found:
        same = any(np.linalg.norm(pose[1] - q[1]) < tol and _angle(pose[0], q[0]) < 5.0
                   for q in distinct)
        if not same:
            distinct.append(pose)
    return distinct[:keep]


def _angle(r1: np.ndarray, r2: np.ndarray) -> float:
    """Angle between two rotations, degrees."""
    c = (np.trace(r1.T @ r2) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def ambiguous(model: RootModel, poses: list) -> bool:
    """Whether the constellation alone cannot decide: more than one pose explains at least
    three root markers within the tolerance. Measured on real pelvis markers (skin moves by
    a millimetre), the true pose sometimes matches fewer markers or a larger residual than
    its left-right mirror, so any alternative is worth a fit of the whole body."""
    return len(poses) > 1


def place_roots(body: Body, cameras, frames_views, windows: np.ndarray,
                gate_px: float = DEFAULT_GATE_PX, resolve=None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Seed poses of every free root for a sequence of frames, in order.

    When a root is (re-)acquired and its constellation fits several poses about equally well
    (:func:`ambiguous`), ``resolve(frame, chain_number, poses)`` picks one (the fitter
    fits the whole body from each and keeps the lowest E); without it, the best residual.

    Parameters
    ----------
    body : Body
    cameras : sequence of Camera, one per view
    frames_views : iterable of frames, each a list of (n_v, 2) detection arrays per view
    windows : (n_free_chains, 2) from :func:`root_windows` (translation window bounds the
        tolerance of position-only seeding)
    gate_px : triangulation gate

    Returns
    -------
    positions : (n, n_free_chains, 3); rotations : (n, n_free_chains, 3, 3)
    placed : (n, n_free_chains) bool, False where the seed was carried over from a
        neighbouring frame (or the chain's configured position when never placed).
    """
    free = [k for k, c in enumerate(body.chains) if c.root.free]
    models = [RootModel(body, c, float(windows[q, 0])) for q, c in enumerate(free)]
    frames = list(frames_views)
    n, nq = len(frames), len(free)
    pos = np.zeros((n, nq, 3))
    rot = np.tile(np.eye(3), (n, nq, 1, 1))
    placed = np.zeros((n, nq), bool)
    prediction: list = [None] * nq
    for f, views in enumerate(frames):
        cands, _ = triangulate_candidates(cameras, views, gate_px) if nq else (None, None)
        for q, model in enumerate(models):
            pick = None if resolve is None else (
                lambda poses, f=f, q=q: resolve(f, q, poses))
            seed = register_root(model, cands, prediction[q], pick)
            if seed is not None:
                rot[f, q], pos[f, q] = seed[0], seed[1]
                placed[f, q] = True
                prediction[q] = (seed[0], seed[1])
    _fill_gaps(body, free, pos, rot, placed)
    return pos, rot, placed


def triangulate_labelled(cameras, views: list[np.ndarray], conf: list[np.ndarray],
                         n_markers: int) -> np.ndarray:
    """3D position of every labelled marker of one frame by the confidence-weighted linear
    triangulation of :func:`kinematics.observe.triangulation.triangulate_linear` over the
    views where
    its keypoint is present, shape (n_markers, 3), NaN where fewer than two views (one for
    orthographic pairs is not enough either) see it.

    ``views[v]`` is (n_markers, 2) keypoints in body-marker order, or empty; ``conf[v]`` the
    matching weights (a keypoint with weight 0 or NaN coordinates is missing).
    """
    xy = np.full((len(views), 1, n_markers, 2), np.nan)
    weight = np.zeros((len(views), 1, n_markers))
    for v, (uv, w) in enumerate(zip(views, conf, strict=True)):
        if len(uv) == n_markers:
            xy[v, 0] = uv
            weight[v, 0] = w
    if len(views) < 2:  # one view cannot place anything; not an error here
        return np.full((n_markers, 3), np.nan)
    return triangulate_linear(cameras, xy, weight).xyz[0]


def place_roots_from_points(body: Body, points3d: np.ndarray, windows: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`place_roots` for labelled markers whose 3D positions are known per frame
    (triangulated keypoints or 3D points), shape (n, n_markers, 3), NaN where missing: the
    root markers are registered by their names (Kabsch over >= 3 present ones; with fewer,
    or a constellation that is not rigid, only the anchor marker's position is used and the
    rotation is kept). Gaps are filled as in :func:`place_roots`."""
    free = [k for k, c in enumerate(body.chains) if c.root.free]
    names = body.marker_names
    n, nq = len(points3d), len(free)
    pos = np.zeros((n, nq, 3))
    rot = np.tile(np.eye(3), (n, nq, 1, 1))
    placed = np.zeros((n, nq), bool)
    for q, c in enumerate(free):
        model = RootModel(body, c, float(windows[q, 0]))
        cols = [names.index(m) for m in model.names]
        r_prev = np.eye(3)
        for f in range(n):
            pts = points3d[f, cols]
            ok = np.isfinite(pts).all(axis=1)
            if model.rigid and ok.sum() >= 3 and _spread(model.local[ok]) > 1e-6:
                r, t, _ = kabsch(model.local[ok], pts[ok])
            elif ok[model.anchor]:
                r = r_prev
                t = pts[model.anchor] - r @ model.local[model.anchor]
            else:
                continue
            rot[f, q], pos[f, q], placed[f, q], r_prev = r, t, True, r
    _fill_gaps(body, free, pos, rot, placed)
    return pos, rot, placed


def _fill_gaps(body: Body, free: list[int], pos, rot, placed) -> None:
    """Carry each seed forward over gaps, and the first one back to the start."""
    n = len(pos)
    for q in range(len(free)):
        got = np.flatnonzero(placed[:, q])
        if got.size == 0:
            pos[:, q] = body.chains[free[q]].root.position
            continue
        src = np.maximum.accumulate(np.where(placed[:, q], np.arange(n), -1))
        src[src < 0] = got[0]
        pos[:, q], rot[:, q] = pos[src, q], rot[src, q]
