"""Unlabelled triangulation: planted markers recovered from shuffled detections, through
distortion, missing and fused detections, clutter and orthographic views; the ragged layout
and bad input named."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics.cameras import OrthographicCamera, PinholeCamera
from kinematics.errors import KinematicsError
from kinematics.model.rotations import euler_yxz
from kinematics.observe.cloud import Cloud, fundamental, linear_matrix, triangulate_unlabelled


def ring_cameras(n=6, f=6000.0, distance=60.0, aim=0.12,
                 dist=(-0.25, 0.08, 0.001, -0.002, 0.0)):
    """Pinhole cameras on a ring ``distance`` mm from the origin (``f`` px: ~100 px/mm
    there), turned ``aim`` rad off it so that the markers lie where distortion shifts
    them by a few px."""
    k = [[f, 0, 639.5], [0, f, 511.5], [0, 0, 1]]
    cams = []
    for i in range(n):
        r = euler_yxz(2 * np.pi * i / n + 0.3, 0.35, 0.05 * i).T
        centre = r.T @ np.array([0.0, 0.0, -distance])
        r = euler_yxz(aim, 0.0, 0.0).T @ r
        cams.append(PinholeCamera(f"cam{i}", k, dist, R=r, t=-r @ centre))
    return cams


def ortho_cameras():
    """Two axis views and one oblique orthographic view, 100 px/mm."""
    oblique = 100.0 * euler_yxz(0.7, 0.4, 0.0)[:2]
    return [OrthographicCamera.from_axes("side", 100.0, ("x", "-y"), (500, 400)),
            OrthographicCamera.from_axes("top", 100.0, ("x", "z"), (500, 300)),
            OrthographicCamera("oblique", np.column_stack([oblique, [450.0, 350.0]]))]


def detect(cams, xyz, rng, noise=0.1, drop=(), fuse=(), clutter=0):
    """Shuffled detections of markers ``xyz`` (m, 3) per view, and (views, m) the index of
    each marker's detection in its view (-1 where dropped). ``drop``: (marker, view)
    pairs; ``fuse``: (marker, marker, view): one detection at their midpoint for both;
    ``clutter``: random detections per view near the markers."""
    dets, where = [], np.full((len(cams), len(xyz)), -1)
    for v, cam in enumerate(cams):
        px = cam.project(xyz) + rng.normal(0.0, noise, (len(xyz), 2))
        owner = [[m] for m in range(len(xyz)) if (m, v) not in drop]
        for a, b, fv in fuse:
            if fv == v:
                px[a] = (px[a] + px[b]) / 2
                owner = [[*o, b] if o == [a] else o for o in owner if o != [b]]
        rows = [px[o[0]] for o in owner]
        if clutter:
            rows += list(rng.uniform(px.min(axis=0), px.max(axis=0), (clutter, 2)))
        order = rng.permutation(len(rows))
        for new, old in enumerate(order):
            for m in owner[old] if old < len(owner) else ():
                where[v, m] = new
        dets.append(np.array(rows).reshape(-1, 2)[order])
    return dets, where


def layout(frames):
    """Frames of per-view detection arrays -> ``points``, ``offsets`` (frame-major)."""
    views = [d for frame in frames for d in frame]
    counts = [len(d) for d in views]
    points = np.concatenate(views) if views else np.zeros((0, 2))
    return points.reshape(-1, 2), np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def match(cloud: Cloud, frame: int, truth: np.ndarray, tol: float):
    """Index of the cloud point within ``tol`` of each planted marker (-1: none), and the
    number of cloud points that are no marker."""
    xyz = cloud.xyz[frame, : cloud.counts[frame]]
    d = np.linalg.norm(truth[:, None] - xyz[None], axis=-1)
    found = np.where(d.min(axis=1, initial=np.inf) <= tol, d.argmin(axis=1)
                     if xyz.size else -1, -1)
    extra = int((d.min(axis=0, initial=np.inf) > tol).sum()) if xyz.size else 0
    return found, extra


def planted(rng, m=30, half=1.5):
    return rng.uniform(-half, half, (m, 3))


def test_planted_points_recovered_through_distortion():
    rng = np.random.default_rng(1)
    cams, truth = ring_cameras(), planted(rng)
    dets, where = detect(cams, truth, rng)
    points, offsets = layout([dets])
    cloud = triangulate_unlabelled(cams, points, offsets)
    found, extra = match(cloud, 0, truth, 0.005)
    assert (found >= 0).all() and extra == 0 and cloud.counts.tolist() == [30]
    assert (cloud.views[0] == 6).all() and (cloud.error[0] < 0.3).all()
    # the support names each marker's own detection, as a row into points
    rows = offsets[np.arange(6)][:, None] + where  # (views, markers)
    np.testing.assert_array_equal(cloud.support[0, found], rows.T)


def test_fundamental_matrix_of_mixed_cameras():
    rng = np.random.default_rng(2)
    cams = [*ring_cameras(2, dist=()), *ortho_cameras()]
    x = np.column_stack([rng.uniform(-1.5, 1.5, (20, 3)), np.ones(20)])
    for a in range(len(cams)):
        for b in range(len(cams)):
            if a != b:
                pa, pb = linear_matrix(cams[a]), linear_matrix(cams[b])
                xa, xb = x @ pa.T, x @ pb.T
                f = fundamental(pa, pb)
                line = xa @ f.T  # epipolar lines in b
                d = np.abs((xb * line).sum(1)) / np.hypot(line[:, 0], line[:, 1]) / xb[:, 2]
                assert d.max() < 1e-6


def test_missing_detections():
    rng = np.random.default_rng(3)
    cams, truth = ring_cameras(), planted(rng)
    drop = {(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (1, 3)}  # marker 1: 2 views
    points, offsets = layout([detect(cams, truth, rng, drop=drop)[0]])
    cloud = triangulate_unlabelled(cams, points, offsets)
    found, extra = match(cloud, 0, truth, 0.005)
    assert extra == 0 and found[1] == -1 and (found[np.arange(30) != 1] >= 0).all()
    assert cloud.views[0, found[0]] == 3
    two = triangulate_unlabelled(cams, points, offsets, min_views=2)
    found2, _ = match(two, 0, truth, 0.005)
    assert (found2 >= 0).all() and two.views[0, found2[1]] == 2


def test_fused_markers_both_recovered():
    rng = np.random.default_rng(4)
    cams, truth = ring_cameras(), planted(rng)
    look = [c.R[2] for c in cams]  # optical axes
    # marker 1 beside marker 0 along view 0's axis (fused there only), marker 3 beside
    # marker 2 on the bisector of views 0 and 3 (fused in both)
    truth[1] = truth[0] + 0.3 * look[0]
    s = look[0] - look[3]
    truth[3] = truth[2] + 0.08 * s / np.linalg.norm(s)
    fuse = [(0, 1, 0), (2, 3, 0), (2, 3, 3)]
    sep = np.array([[np.linalg.norm(c.project(truth[a]) - c.project(truth[b])) for c in cams]
                    for a, b in ((0, 1), (2, 3))])
    assert sep[0, 0] < 4 and sep[1, [0, 3]].max() < 4  # fused views: within support_px
    assert sep[0, 1:].max() > 6 and np.delete(sep[1], [0, 3]).max() > 6
    dets, where = detect(cams, truth, rng, fuse=fuse)
    assert where[0, 0] == where[0, 1] and where[3, 2] == where[3, 3]
    points, offsets = layout([dets])
    cloud = triangulate_unlabelled(cams, points, offsets)
    found, extra = match(cloud, 0, truth, 0.02)
    assert (found >= 0).all() and extra == 0 and cloud.counts[0] == 30
    sup = cloud.support[0]
    assert sup[found[0], 0] == sup[found[1], 0] >= 0  # one detection for both
    assert sup[found[2], 3] == sup[found[3], 3] >= 0


def test_clutter_creates_few_ghosts():
    rng = np.random.default_rng(5)
    cams = ring_cameras()
    truths = [planted(rng, 20) for _ in range(10)]
    frames = [detect(cams, t, rng, clutter=3)[0] for t in truths]
    cloud = triangulate_unlabelled(cams, *layout(frames))
    extras = []
    for f, t in enumerate(truths):
        found, extra = match(cloud, f, t, 0.005)
        assert (found >= 0).all()
        extras.append(extra)
    # one chance coincidence of two clutter detections, confirmed in a third view: a
    # 3-view point ranked after every marker (6 views)
    assert extras == [1] + [0] * 9
    assert cloud.views[0].tolist() == [6] * 20 + [3]
    assert (cloud.views[1:][cloud.views[1:] > 0] == 6).all()


def test_orthographic_views():
    rng = np.random.default_rng(6)
    cams, truth = ortho_cameras(), planted(rng, 10)
    points, offsets = layout([detect(cams, truth, rng)[0]])
    cloud = triangulate_unlabelled(cams, points, offsets)
    found, extra = match(cloud, 0, truth, 0.005)
    assert (found >= 0).all() and extra == 0 and (cloud.views[0] == 3).all()


def test_ragged_frames_empty_frame_and_empty_view():
    rng = np.random.default_rng(7)
    cams = dict(zip("abcdef", ring_cameras(), strict=True))
    views = list(cams.values())
    truths = [planted(rng, 12), planted(rng, 0), planted(rng, 5), planted(rng, 9)]
    frames = [detect(views, t, rng)[0] for t in truths]
    frames[3][2] = np.zeros((0, 2))  # view 2 of frame 3 saw nothing
    points, offsets = layout(frames)
    calls = []
    cloud = triangulate_unlabelled(cams, points, offsets,
                                   progress=lambda done, total: calls.append((done, total)))
    assert calls[-1] == (4, 4)
    assert cloud.counts.tolist() == [12, 0, 5, 9] and cloud.xyz.shape == (4, 12, 3)
    assert cloud.support.shape == (4, 12, 6)
    for f, t in enumerate(truths):
        found, extra = match(cloud, f, t, 0.005)
        assert (found >= 0).all() and extra == 0
    assert (cloud.views[3, :9] == 5).all() and (cloud.support[3, :9, 2] == -1).all()
    pad = cloud.views == 0
    assert np.isnan(cloud.xyz[pad]).all() and np.isnan(cloud.error[pad]).all()
    assert (cloud.support[pad] == -1).all() and pad[1].all()
    none = triangulate_unlabelled(views, np.zeros((0, 2)), np.zeros(1, np.int64))
    assert none.xyz.shape == (0, 0, 3) and none.counts.shape == (0,)


@pytest.mark.parametrize(("change", "field"), [
    ({"min_views": 1}, "min_views"),
    ({"min_views": 7}, "min_views"),
    ({"match_px": -1.0}, "match_px"),
    ({"support_px": float("nan")}, "support_px"),
    ({"cameras": "one"}, "cameras"),
    ({"points": np.zeros((6, 3))}, "points"),
    ({"points": np.full((6, 2), np.nan)}, "points"),
    ({"offsets": np.arange(6)}, "offsets"),
    ({"offsets": np.arange(7.0)}, "offsets"),
    ({"offsets": np.array([0, 1, 2, 3, 4, 6, 5])}, "offsets"),
    ({"progress": 3}, "progress"),
])
def test_bad_input_names_the_field(change, field):
    cams = ring_cameras()
    args = {"cameras": cams, "points": np.zeros((6, 2)), "offsets": np.arange(7)} | change
    if change.get("cameras") == "one":
        args["cameras"] = cams[:1]
        args["offsets"] = np.arange(2)
        args["points"] = np.zeros((1, 2))
    cameras, points, offsets = args.pop("cameras"), args.pop("points"), args.pop("offsets")
    with pytest.raises(KinematicsError) as err:
        triangulate_unlabelled(cameras, points, offsets, **args)
    assert err.value.field == field and "\n" not in str(err.value)
