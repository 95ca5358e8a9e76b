"""Triangulation backends: kernels against their NumPy twins, planted points recovered,
outliers rejected by RANSAC and the spatiotemporal optimiser, bad input named; aniposelib
as the oracle of the linear and RANSAC backends where it is installed."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics._kernels import triangulation as _k
from kinematics.cameras import OrthographicCamera, PinholeCamera, pack_cameras
from kinematics.errors import KinematicsError
from kinematics.model.rotations import euler_yxz
from kinematics.observe.triangulation import (
    LOSSES,
    _dlt_numpy,
    _inputs,
    _linearise_numpy,
    _matrices,
    _mean_errors_numpy,
    _ransac_numpy,
    _residuals_numpy,
    triangulate_linear,
    triangulate_optim,
    triangulate_ransac,
)


def ring_cameras(n=4, dist=(-0.25, 0.08, 0.001, -0.002, 0.0)):
    """Pinhole cameras on a ring 400 mm from the origin, looking at it, with distortion."""
    k = [[900.0, 0, 639.5], [0, 900.0, 511.5], [0, 0, 1]]
    cams = []
    for i in range(n):
        r = euler_yxz(2 * np.pi * i / n + 0.3, 0.35, 0.05 * i).T
        centre = r.T @ np.array([0.0, 0.0, -400.0])
        cams.append(PinholeCamera(f"cam{i}", k, dist, R=r, t=-r @ centre, size=(1280, 1024)))
    return cams


def chain_motion(n_frames=60, n_points=5, seed=0):
    """Points along a wobbling chain of 20 mm segments, (n_frames, n_points, 3)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames)[:, None]
    ang = 0.4 * np.sin(0.15 * t + rng.uniform(0, 6, n_points)) + np.linspace(0, 1.5, n_points)
    seg = np.stack([np.cos(ang), np.sin(ang), 0.3 * np.sin(0.5 * ang)], -1)
    seg *= 20.0 / np.linalg.norm(seg, axis=-1, keepdims=True)
    seg[:, 0] = [-30.0, 0.0, 0.0]
    pts = np.cumsum(seg, axis=1)
    return pts + np.stack([10 * np.sin(0.05 * t[:, 0]), 5 * np.cos(0.07 * t[:, 0]),
                           np.zeros(n_frames)], -1)[:, None]


def project(cams, pts):
    return np.stack([c.project(pts) for c in cams])


def test_linear_recovers_noise_free_points_through_distortion():
    cams, truth = ring_cameras(), chain_motion(10)
    tri = triangulate_linear(cams, project(cams, truth))
    np.testing.assert_allclose(tri.xyz, truth, atol=1e-6)
    assert np.all(tri.error < 1e-5) and np.all(tri.ncams == 4) and np.all(tri.score == 1)


def test_linear_with_orthographic_views_and_missing_cameras():
    cams = [OrthographicCamera.from_axes("side", 3.0, ("x", "-y"), (300, 400)),
            OrthographicCamera.from_axes("top", 2.5, ("x", "z"), (300, 200)),
            ring_cameras(1)[0]]
    truth = chain_motion(4)
    xy = project(cams, truth)
    xy[2, 0, :] = np.nan  # frame 0: only the two orthographic views
    xy[:2, 1, 0] = np.nan  # frame 1, point 0: one camera only -> NaN
    tri = triangulate_linear(cams, xy)
    assert np.isnan(tri.xyz[1, 0]).all() and tri.ncams[1, 0] == 0 and np.isnan(tri.error[1, 0])
    ok = np.isfinite(tri.xyz).all(axis=-1)
    np.testing.assert_allclose(tri.xyz[ok], truth[ok], atol=1e-6)
    assert tri.ncams[0, 0] == 2 and tri.ncams[2, 0] == 3


def test_weights_and_min_score():
    cams, truth = ring_cameras(), chain_motion(3, 3)
    xy = project(cams, truth)
    xy[0] += 15.0  # a bad camera
    score = np.ones(xy.shape[:3])
    score[0] = 0.05
    plain = triangulate_linear(cams, xy, score, weighted=False)
    weighted = triangulate_linear(cams, xy, score)
    dropped = triangulate_linear(cams, xy, score, min_score=0.1)
    e = [np.linalg.norm(t.xyz - truth, axis=-1).max() for t in (plain, weighted, dropped)]
    assert e[1] < 0.25 * e[0] and e[2] < 1e-6
    assert np.all(dropped.ncams == 3) and np.all(weighted.score == 0.05)


def test_undistortion_is_opencvs():
    cams = ring_cameras(2, dist=(-0.3, 0.12, 0.001, -0.002, 0.01, 0.02, -0.01, 0.005))
    rng = np.random.default_rng(6)
    px = rng.uniform([0, 0], [1280, 1024], (2, 500, 2))
    want = _linearise_numpy(cams, px, np.ones((2, 500)))
    packed = pack_cameras(cams)
    x, y = _k.linearise_all(packed.kind, packed.K, packed.dist, px[..., 0].copy(),
                            px[..., 1].copy())
    np.testing.assert_allclose(np.stack([x, y], -1), want, rtol=0, atol=1e-14)


def test_linear_kernel_matches_numpy_twin():
    cams, truth = ring_cameras(5), chain_motion(8)
    rng = np.random.default_rng(1)
    xy = project(cams, truth) + rng.normal(0, 2.0, (5, 8, 5, 2))
    score = rng.uniform(0.2, 1.0, xy.shape[:3])
    xy[rng.random(xy.shape[:3]) < 0.3] = np.nan
    tri = triangulate_linear(cams, xy, score)
    cams, px, _, w = _inputs(cams, xy, score, 0.0, True)
    px, w = px.reshape(5, -1, 2), w.reshape(5, -1)
    mats, lin = _matrices(cams), _linearise_numpy(cams, px, w)
    np.testing.assert_allclose(tri.xyz.reshape(-1, 3), _dlt_numpy(mats, lin, w), atol=1e-9)


def test_linear_result_does_not_depend_on_the_block():
    """A point's solve runs in one SIMD lane of a block of points: its bits must not depend
    on the block, the lane or the other points (nor, then, on how points are split up)."""
    frames = (2 * _k.BLOCK + 100) // 5  # two blocks of points and a rest
    cams, truth = ring_cameras(), chain_motion(frames)
    rng = np.random.default_rng(7)
    xy = project(cams, truth) + rng.normal(0, 3.0, (4, frames, 5, 2))
    xy[rng.random(xy.shape[:3]) < 0.3] = np.nan
    flat = xy.reshape(4, -1, 1, 2)
    whole = triangulate_linear(cams, flat)
    shifted = triangulate_linear(cams, flat[:, 37:])
    np.testing.assert_array_equal(shifted.xyz, whole.xyz[37:])
    np.testing.assert_array_equal(shifted.error, whole.error[37:])
    for n in (0, _k.BLOCK + 3, 5 * frames - 1):
        np.testing.assert_array_equal(triangulate_linear(cams, flat[:, n:n + 1]).xyz,
                                      whole.xyz[n:n + 1])


def solver_lanes(mats):
    """Run the kernels' QR and smallest right singular vector on matrices (lanes, rows, 4);
    returns R (lanes, 4, 4), the vectors (lanes, 4) and the states after 12 plain steps."""
    a = np.ascontiguousarray(np.transpose(mats, (1, 2, 0)))
    lanes = a.shape[2]
    lane, state = np.zeros((13, lanes)), np.zeros(lanes, np.int64)
    _k.qr_lanes(a, a.shape[0], lane, lanes)
    r = np.transpose(a[:4], (2, 0, 1)).copy()
    probe, probe_state = a.copy(), state.copy()
    _k._start(probe, lane, probe_state, lanes)
    for _ in range(12):
        _k._inverse_step(probe, lane, probe_state, lanes)
    _k.smallest_right_singular(a, lane, state, lanes)
    assert np.all(state == _k.DONE)
    return r, lane[:4].T, probe_state


def test_qr_lanes_matches_numpy_with_rows_of_zeros():
    rng = np.random.default_rng(8)
    mats = rng.normal(size=(16, 8, 4)) * [1.0, 1.0, 1.0, 300.0]
    want = np.linalg.qr(mats)[1]
    padded = np.zeros((16, 12, 4))
    padded[:, [0, 1, 4, 5, 6, 7, 10, 11]] = mats  # cameras left out: rows of zeros
    for got in (solver_lanes(mats)[0], solver_lanes(padded)[0]):
        # R is unique up to the signs of its rows
        signs = np.sign(np.diagonal(got, axis1=1, axis2=2) * np.diagonal(want, axis1=1, axis2=2))
        np.testing.assert_allclose(got, want * signs[..., None], rtol=1e-12, atol=1e-9)


def test_smallest_right_singular_matches_lapack_on_every_path():
    rng = np.random.default_rng(9)

    def with_singular_values(s):
        u = np.linalg.qr(rng.normal(size=(8, 4)))[0]
        v = np.linalg.qr(rng.normal(size=(4, 4)))[0]
        return u @ np.diag(s) @ v.T

    # DLT-like: the translation column dominates, a noisy point leaves a small singular value
    mats = [with_singular_values([400.0, 3.0, 1.0, s4])
            for s4 in (1e-4, 1e-3, 0.01, 0.03, 0.05, 0.1)]
    mats.append(with_singular_values([3.0, 2.0, 1.0, 0.999]))  # no gap: Jacobi
    mats.append(with_singular_values([3.0, 2.0, 1.0, 1e-9]))  # a big gap: a step or two
    exact = rng.normal(size=(8, 4))
    exact[:, 2] = 0.0  # an exact null direction (0, 0, 1, 0)
    mats.append(exact)
    mats = np.array(mats)
    _, h, plain = solver_lanes(mats)
    assert plain[6] == _k.ITERATE and plain[8] == _k.NULL  # each path was taken
    assert np.all(plain[:6] == _k.DONE) and plain[7] == _k.DONE
    want = np.linalg.svd(mats)[2][:, -1]
    sign = np.sign(np.sum(h * want, axis=1))[:, None]
    np.testing.assert_allclose(h * sign, want, atol=1e-12)


def test_mean_errors_kernel_matches_numpy_twin():
    cams = [*ring_cameras(3), OrthographicCamera.from_axes("o", 2.0, ("x", "z"), (300, 200))]
    rng = np.random.default_rng(10)
    pts = chain_motion(4).reshape(-1, 3)
    pts[5] = np.nan
    px = project(cams, pts + rng.normal(0, 0.5, pts.shape))
    w = (rng.random((4, len(pts))) < 0.7).astype(float)
    w[:, 7] = 0.0  # seen by none: NaN
    px[w == 0] = np.nan
    pts[3] = -cams[0].R.T @ cams[0].t - 50.0 * cams[0].R[2]  # behind camera 0: NaN
    px[:, 3], w[:, 3] = [600.0, 500.0], 1.0
    err, ncams = np.empty(len(pts)), np.empty(len(pts), np.int64)
    _k.mean_errors(*pack_cameras(cams), np.ascontiguousarray(pts.T), px[..., 0].copy(),
                   px[..., 1].copy(), w, err, ncams)
    want, want_n = _mean_errors_numpy(cams, pts, px, w)
    np.testing.assert_array_equal(ncams, want_n)
    np.testing.assert_array_equal(np.isnan(err), np.isnan(want))
    assert np.isnan(err[[3, 5, 7]]).all() and np.isfinite(err).sum() > len(pts) // 2
    np.testing.assert_allclose(err, want, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("inlier_px", [0.0, 6.0])
def test_ransac_kernel_matches_numpy_twin(inlier_px):
    cams, truth = ring_cameras(5), chain_motion(6)
    rng = np.random.default_rng(2)
    xy = project(cams, truth) + rng.normal(0, 1.0, (5, 6, 5, 2))
    xy[rng.random(xy.shape[:3]) < 0.15] += 60.0
    xy[rng.random(xy.shape[:3]) < 0.15] = np.nan
    tri = triangulate_ransac(cams, xy, min_cams=2, good_px=0.7, inlier_px=inlier_px)
    cams, px, _, w = _inputs(cams, xy, None, 0.0, True)
    px, w = px.reshape(5, -1, 2), w.reshape(5, -1)
    mats, lin = _matrices(cams), _linearise_numpy(cams, px, w)
    xyz, err, used = _ransac_numpy(cams, mats, lin, w, px, 2, 0.7, 200.0, inlier_px)
    np.testing.assert_allclose(tri.xyz.reshape(-1, 3), xyz, atol=1e-8)
    np.testing.assert_allclose(tri.error.ravel(), err, atol=1e-8)
    np.testing.assert_array_equal(tri.used.reshape(5, -1), used)


def test_ransac_rejects_a_swapped_keypoint():
    cams, truth = ring_cameras(), chain_motion(20)
    rng = np.random.default_rng(3)
    xy = project(cams, truth) + rng.normal(0, 0.5, (4, 20, 5, 2))
    xy[1, :, 2] = xy[1, :, 3]  # camera 1 mixes up points 2 and 3
    lin = triangulate_linear(cams, xy)
    ran = triangulate_ransac(cams, xy, good_px=0.0, inlier_px=8.0)
    e_lin = np.linalg.norm(lin.xyz[:, 2] - truth[:, 2], axis=-1)
    e_ran = np.linalg.norm(ran.xyz[:, 2] - truth[:, 2], axis=-1)
    assert np.median(e_ran) < 1.0 < np.median(e_lin)
    assert not ran.used[1, :, 2].any() and np.all(ran.ncams[:, 2] == 3)


@pytest.mark.parametrize("loss", list(LOSSES))
def test_residual_kernel_matches_numpy_twin(loss):
    cams = [*ring_cameras(3), OrthographicCamera.from_axes("o", 2.0, ("x", "z"), (300, 200))]
    rng = np.random.default_rng(4)
    xyz = chain_motion(2).reshape(-1, 3)
    m = 12
    cam, point = rng.integers(0, 4, m), rng.integers(0, len(xyz), m)
    uv = np.array([cams[c].project(xyz[p]) for c, p in zip(cam, point, strict=True)])
    uv += rng.normal(0, 30.0, uv.shape)
    weight = rng.uniform(0.3, 1.0, m)
    res, jac = np.empty(2 * m), np.empty((2 * m, 3))
    _k.reprojection_residuals(*pack_cameras(cams), cam, point, uv, weight, xyz, 10.0,
                              LOSSES[loss], res, jac)
    res_np, jac_np = _residuals_numpy(cams, cam, point, uv, weight, xyz, 10.0, loss)
    np.testing.assert_allclose(res, res_np, atol=1e-9)
    np.testing.assert_allclose(jac, jac_np, rtol=1e-5, atol=1e-6)


def test_triangulate_labelled_uses_the_linear_backend():
    from kinematics.fit.placement import triangulate_labelled

    cams, truth = ring_cameras(3), chain_motion(1)[0]
    views = [c.project(truth) for c in cams]
    conf = [np.ones(5), np.ones(5), np.ones(5)]
    conf[0][1] = 0.0  # point 1: two views left
    views[1][1] = np.nan  # ... and then one
    views[2] = np.empty((0, 2))  # a view without keypoints
    got = triangulate_labelled(cams, views, conf, 5)
    want = triangulate_linear(cams[:2], np.stack(views[:2])[:, None],
                              np.stack(conf[:2])[:, None]).xyz[0]
    np.testing.assert_array_equal(got, want)
    assert np.isnan(got[1]).all() and np.isfinite(np.delete(got, 1, 0)).all()
    one = triangulate_labelled(cams[:1], views[:1], conf[:1], 5)
    assert one.shape == (5, 3) and np.isnan(one).all()


def noisy_trial(n_frames=80, seed=5):
    """4 cameras, 2 px noise, 10 % of keypoints swapped with a neighbour or missing."""
    cams, truth = ring_cameras(), chain_motion(n_frames)
    rng = np.random.default_rng(seed)
    xy = project(cams, truth) + rng.normal(0, 2.0, (4, n_frames, 5, 2))
    bad = rng.random(xy.shape[:3]) < 0.10
    swap = bad & (rng.random(xy.shape[:3]) < 0.5)
    c, f, j = np.nonzero(swap)
    xy[c, f, j] = xy[c, f, (j + 1) % 5]
    xy[bad & ~swap] = np.nan
    return cams, truth, xy


def test_optimisation_improves_on_linear_with_outliers():
    cams, truth, xy = noisy_trial()
    limbs = [(i, i + 1) for i in range(4)]
    lin = triangulate_linear(cams, xy)
    opt = triangulate_optim(cams, xy, limbs=limbs, chunk=50, overlap=10)
    given = triangulate_optim(cams, xy, limbs=limbs, limb_lengths=[20.0] * 4, init="ransac",
                              chunk=50, overlap=10)
    err = [np.nanmean(np.linalg.norm(t.xyz - truth, axis=-1)) for t in (lin, opt, given)]
    assert err[1] < 0.7 * err[0] and err[2] < 0.7 * err[0]
    seg = np.linalg.norm(np.diff(given.xyz, axis=1), axis=-1)
    assert np.abs(seg - 20.0).max() < np.abs(np.linalg.norm(np.diff(lin.xyz, axis=1),
                                                            axis=-1) - 20.0).max()
    assert np.all(opt.ncams == (np.isfinite(xy[..., 0])).sum(axis=0))
    # mean_errors against NumPy: mean pixel distance over the cameras that see a point
    dist = np.linalg.norm(project(cams, opt.xyz) - xy, axis=-1)
    np.testing.assert_allclose(opt.error, np.nanmean(dist, axis=0), rtol=1e-9)


def test_optimisation_chunks_agree_with_one_chunk():
    cams, _, xy = noisy_trial(40)
    one = triangulate_optim(cams, xy, limbs=[(0, 1)], chunk=40, ftol=1e-8)
    calls = []
    parts = triangulate_optim(cams, xy, limbs=[(0, 1)], chunk=15, overlap=10, ftol=1e-8,
                              progress=lambda d, n: calls.append((d, n)))
    assert calls == [(15, 40), (30, 40), (40, 40)]
    assert np.nanmax(np.abs(one.xyz - parts.xyz)) < 0.5


@pytest.mark.parametrize("call, field", [
    (lambda c, xy: triangulate_linear(c[:1], xy[:1]), "cameras"),
    (lambda c, xy: triangulate_linear(c, xy[:, 0]), "xy"),
    (lambda c, xy: triangulate_linear(c, xy, np.ones(3)), "score"),
    (lambda c, xy: triangulate_ransac(c, xy, min_cams=1), "min_cams"),
    (lambda c, xy: triangulate_ransac(c, xy, good_px=np.nan), "good_px"),
    (lambda c, xy: triangulate_optim(c, xy, limbs=[(0, 9)]), "limbs"),
    (lambda c, xy: triangulate_optim(c, xy, limbs=[(0, 1)], limb_lengths=[-1]),
     "limb_lengths"),
    (lambda c, xy: triangulate_optim(c, xy, loss="cauchy"), "loss"),
    (lambda c, xy: triangulate_optim(c, xy, init="dlt"), "init"),
    (lambda c, xy: triangulate_optim(c, xy, n_deriv=0), "n_deriv"),
])
def test_bad_input_is_named(call, field):
    cams = ring_cameras()
    xy = project(cams, chain_motion(3))
    with pytest.raises(KinematicsError) as err:
        call(cams, xy)
    assert err.value.field == field


def anipose_group(cams):
    pytest.importorskip("jax")
    aniposelib = pytest.importorskip("aniposelib.cameras")
    return aniposelib.CameraGroup([aniposelib.Camera(
        name=c.name, size=c.image_size, matrix=c.K, dist=c.dist[:5], rvec=c.rvec, tvec=c.t)
        for c in cams])


def rodrigues_cameras():
    import cv2

    return [PinholeCamera(c.name, c.K, c.dist[:5], t=c.t, size=c.image_size,
                          rvec=cv2.Rodrigues(c.R)[0].ravel()) for c in ring_cameras()]


def test_linear_agrees_with_aniposelib():
    cams = rodrigues_cameras()
    group = anipose_group(cams)
    _, _, xy = noisy_trial(30)
    ours = triangulate_linear(cams, xy, weighted=False).xyz.reshape(-1, 3)
    theirs = group.triangulate(xy.reshape(4, -1, 2))
    np.testing.assert_allclose(ours, theirs, atol=1e-6)
    assert np.isfinite(ours).sum() > 0.9 * ours.size


def test_ransac_agrees_with_aniposelib():
    cams = rodrigues_cameras()
    group = anipose_group(cams)
    _, _, xy = noisy_trial(2)
    flat = xy.reshape(4, -1, 2)
    keep = np.isfinite(flat[..., 0]).sum(axis=0) >= 1  # aniposelib fails on unseen points
    theirs, _, _, errors = group.triangulate_ransac(flat[:, keep])
    ours = triangulate_ransac(cams, flat[:, keep][:, None], weighted=False)
    np.testing.assert_allclose(ours.xyz[0], theirs, atol=1e-6)
    np.testing.assert_allclose(np.nan_to_num(ours.error[0]), errors, atol=1e-6)
