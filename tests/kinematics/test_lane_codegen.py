"""The lane kernels generated per body (kinematics/_kernels/lane_codegen.py): the same E as the
scalar kernel to the last bit, literal folding, kernels shared and cached."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinematics._kernels import codes as _codes
from kinematics._kernels import error2d as _error2d
from kinematics._kernels import error3d as _error3d
from kinematics._kernels import fastmath as _fastmath
from kinematics._kernels import lane_codegen as cg
from kinematics._kernels import lane_iterations as _li
from kinematics._kernels import lanes as _lk
from kinematics._kernels import objective as _objective
from kinematics._kernels import posture as _posture
from kinematics._kernels.lanes import PAD
from kinematics._kernels.records import FrameObs
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.problem import ErrorArgs
from kinematics.model.chain_xml import load_body
from kinematics.model.rotations import euler_yxz
from tests.fixtures.bodies import mouse_like
from tests.fixtures.cameras import three_pinholes
from tests.fixtures.planted import planted_detections
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import bundled_chain, locust_cameras


def _problem(kind):
    if kind == "free root, distorted pinholes":
        body = mouse_like(translation_window=4.0, rotation_window_deg=30.0)
        return Fitter(body, three_pinholes(), AnnealParams()).problem
    with bundled_chain("locust_hindleg.xml") as p:
        pr = Fitter(load_body(p), locust_cameras(), AnnealParams()).problem
    if kind == "locust, offsets after the joints":
        # no shipped chain has them: a constant rotation before joint 1 and offsets after
        # the joints (the kernels' G_j and h_j), so those paths are compared too
        f = pr.folded
        pre_rot, post_trans, flags = f.pre_rot.copy(), f.post_trans.copy(), f.joint_flags.copy()
        pre_rot[1] = euler_yxz(0.3, -0.2, 0.1)
        post_trans[1:] = [[2.0, -1.5, 0.7], [0.3, 4.0, -2.0]]
        flags[1:] &= ~(_codes.G_IDENTITY | _codes.H_ZERO)
        pr = replace(pr, folded=f._replace(pre_rot=pre_rot, post_trans=post_trans,
                                           joint_flags=flags))
    return pr


def _lanes(pr, n_lanes, c_cap, rng):
    """Random postures, roots and detections (0 to c_cap per view, some near the markers)
    of n_lanes lanes: the generated kernel's inputs and each lane's scalar inputs."""
    folded, cams = pr.folded, pr.cams
    nj, nv, nc = folded.parent.shape[0], len(cams.kind), int(folded.chain.max()) + 1
    n_det = cg.padded_detections(c_cap)
    free = pr.dofs.free_idx
    cand = np.repeat(pr.start[:, None], n_lanes, axis=1)
    cand[free] += rng.normal(0.0, 0.3, (free.size, n_lanes))
    rot = np.zeros((nj + nc, 9, n_lanes))
    pos = np.zeros((nj + nc, 3, n_lanes))
    dx = np.full((nv, n_det, n_lanes), PAD)
    dy = np.full((nv, n_det, n_lanes), PAD)
    ndet = np.zeros((nv, n_lanes), np.int64)
    scalar = []
    for ln in range(n_lanes):
        root_pos = rng.normal(0.0, 5.0, (nc, 3))
        if ln % 9 == 4 and cams.kind[0] != 0:  # a root at camera 0: markers behind it
            root_pos[0] = -cams.R[0].T @ cams.t[0]
        root_rot = np.stack([euler_yxz(*rng.uniform(-0.5, 0.5, 3)) for _ in range(nc)])
        rot[nj:, :, ln] = root_rot.reshape(nc, 9)
        pos[nj:, :, ln] = root_pos
        mk = np.empty((folded.marker_joint.size, 3))
        proj = np.empty((nv, folded.marker_joint.size, 2))
        _posture.project_posture(cand[:, ln].copy(), root_pos, root_rot, folded, cams,
                            np.empty(cand.shape[0]), np.empty(cand.shape[0]),
                            np.empty((nj, 3, 3)), np.empty((nj, 3)), mk, proj)
        points, off = [], [0]
        for v in range(nv):
            k = int(rng.integers(0, c_cap + 1))
            near = proj[v][rng.integers(0, proj.shape[1], k)] + rng.normal(0.0, 3.0, (k, 2))
            pts = np.where(rng.random((k, 1)) < 0.7, near, rng.uniform(-200, 800, (k, 2)))
            pts = pts[np.isfinite(pts).all(axis=1)]
            if ln % 3 == 0 and 0 < len(pts) < c_cap:  # two detections in one place: ties
                pts = np.concatenate([pts, pts[-1:]])
            ndet[v, ln] = len(pts)
            dx[v, :len(pts), ln], dy[v, :len(pts), ln] = pts[:, 0], pts[:, 1]
            points.append(pts)
            off.append(off[-1] + len(pts))
        scalar.append((root_pos, root_rot, np.concatenate(points).reshape(-1, 2),
                       np.asarray(off, np.int64)))
    dx32, dy32 = dx.astype(np.float32), dy.astype(np.float32)
    no_points = np.zeros((0, 4, n_lanes))
    return (cand, rot, pos, dx, dy, dx32, dy32, np.zeros_like(dx), no_points, ndet), scalar


@pytest.mark.parametrize(("kind", "error", "c_cap"), [
    ("locust", (False, 0.0, np.inf, np.inf), 9),  # the paper's Eq. 5
    ("locust, offsets after the joints", (True, 0.5, 10.0, 10.0), 9),  # the defaults' error
    ("locust", (True, 0.5, 10.0, 10.0), 21),  # 24 detections: scans of 16 and 8
    ("free root, distorted pinholes", (True, 1.0, np.inf, 20.0), 9),
    ("free root, distorted pinholes", (False, 0.0, 10.0, 10.0), 9)])
def test_generated_error_equals_the_scalar_kernel(kind, error, c_cap):
    """c_cap 9 is padded to 12: padding and lanes with fewer (or no) detections."""
    pr = _problem(kind)
    rng = np.random.default_rng(3)
    args, scalar = _lanes(pr, 37, c_cap, rng)
    e = np.empty(37)
    _lk.call_fused(cg.fused_kernel(pr.folded, pr.cams, c_cap, error), *args, e)
    bidirectional, weight, cap, penalty_cap = error
    for ln, (root_pos, root_rot, points, off) in enumerate(scalar):
        ref = _objective.posture_error(
            args[0][:, ln].copy(), root_pos, root_rot, pr.folded, pr.cams,
            FrameObs(_codes.OBJ_NEAREST, points, np.empty(0), off, _codes.NO_HIDDEN),
            ErrorArgs(bidirectional, weight, cap, penalty_cap, False),
            np.empty(len(pr.cams.kind)))
        assert e[ln] == ref, f"lane {ln}"


@pytest.mark.parametrize(("kind", "cap"), [("locust", 10.0), ("locust", np.inf),
                                           ("free root, distorted pinholes", 20.0)])
def test_generated_labelled_error_equals_the_scalar_kernel(kind, cap):
    """Labelled keypoints: weights, keypoints not found (NaN) or of weight 0, views without
    rows, markers behind a camera (lane 4 of the pinholes)."""
    pr = _problem(kind)
    rng = np.random.default_rng(5)
    n_lanes, nm, nv = 37, pr.folded.marker_joint.size, len(pr.cams.kind)
    args, scalar = _lanes(pr, n_lanes, 9, rng)
    cand, rot, pos = args[:3]
    dx, dy = np.full((nv, nm, n_lanes), PAD), np.full((nv, nm, n_lanes), PAD)
    dw, ndet = np.zeros((nv, nm, n_lanes)), np.zeros((nv, n_lanes), np.int64)
    refs = []
    for ln, (root_pos, root_rot, _, _) in enumerate(scalar):
        mk, proj = np.empty((nm, 3)), np.empty((nv, nm, 2))
        _posture.project_posture(cand[:, ln].copy(), root_pos, root_rot, pr.folded, pr.cams,
                            np.empty(cand.shape[0]), np.empty(cand.shape[0]),
                            np.empty((pr.folded.parent.size, 3, 3)),
                            np.empty((pr.folded.parent.size, 3)), mk, proj)
        # keypoints also where the marker is behind the camera (its cost is the cap's)
        kp = np.where(np.isfinite(proj), proj, 300.0) + rng.normal(0.0, 4.0, proj.shape)
        w = rng.uniform(0.2, 1.0, (nv, nm))
        kp[rng.random((nv, nm)) < 0.15] = np.nan
        kp[rng.random((nv, nm)) < 0.1, 0] = np.nan  # x only
        w[rng.random((nv, nm)) < 0.1] = 0.0
        # rows per view: the markers', none, or (never from a reader) one too few or many
        counts = rng.choice([nm, nm, nm, 0, nm - 1, nm + 2], nv)
        for v in range(nv):
            k = min(counts[v], nm)
            dx[v, :k, ln], dy[v, :k, ln], dw[v, :k, ln] = kp[v, :k, 0], kp[v, :k, 1], w[v, :k]
            ndet[v, ln] = counts[v]
        rows = [np.r_[kp[v], np.full((2, 2), 5.0)][:counts[v]] for v in range(nv)]
        points = np.concatenate(rows).reshape(-1, 2)
        off = np.cumsum(np.r_[0, counts]).astype(np.int64)
        conf = np.concatenate([np.r_[w[v], 1.0, 1.0][:counts[v]] for v in range(nv)])
        refs.append(_error2d.labelled_error(proj, points, conf, off, cap, np.empty(nv)))
    e = np.empty(n_lanes)
    fused = cg.fused_kernel(pr.folded, pr.cams, 0, (False, 0.0, cap, np.inf), labelled=True)
    _lk.call_fused(fused, cand, rot, pos, dx, dy, dx.astype(np.float32),
                   dy.astype(np.float32), dw, np.zeros((0, 4, n_lanes)), ndet, e)
    np.testing.assert_array_equal(e, refs)
    assert np.isfinite(e).all() and (e > 0).sum() > n_lanes // 2


def test_generated_3d_point_error_equals_the_scalar_kernel():
    """3D points (no cameras), a free root: weights, points not found (one coordinate NaN)
    or of weight 0, distances beyond the cap."""
    cap = 5.0
    body = mouse_like(translation_window=4.0, rotation_window_deg=30.0)
    pr = Fitter(body, {}, AnnealParams()).problem
    rng = np.random.default_rng(6)
    n_lanes, nm = 29, pr.folded.marker_joint.size
    nj, nc = pr.folded.parent.shape[0], int(pr.folded.chain.max()) + 1
    cand = np.repeat(pr.start[:, None], n_lanes, axis=1)
    cand[pr.dofs.free_idx] += rng.normal(0.0, 0.3, (pr.dofs.free_idx.size, n_lanes))
    rot, pos = np.zeros((nj + nc, 9, n_lanes)), np.zeros((nj + nc, 3, n_lanes))
    o3 = np.zeros((nm, 4, n_lanes))
    refs = []
    for ln in range(n_lanes):
        root_pos = rng.normal(0.0, 5.0, (nc, 3))
        root_rot = np.stack([euler_yxz(*rng.uniform(-0.5, 0.5, 3)) for _ in range(nc)])
        rot[nj:, :, ln], pos[nj:, :, ln] = root_rot.reshape(nc, 9), root_pos
        mk = np.empty((nm, 3))
        _posture.project_posture(cand[:, ln].copy(), root_pos, root_rot, pr.folded, pr.cams,
                            np.empty(cand.shape[0]), np.empty(cand.shape[0]),
                            np.empty((nj, 3, 3)), np.empty((nj, 3)), mk,
                            np.empty((0, nm, 2)))
        pts = np.c_[mk + rng.normal(0.0, 3.0, mk.shape), rng.uniform(0.2, 1.0, nm)]
        pts[rng.random(nm) < 0.15, rng.integers(0, 3)] = np.nan
        pts[rng.random(nm) < 0.1, 3] = 0.0
        o3[:, :, ln] = pts
        refs.append(_error3d.points3d_error(mk, pts, cap))
    dx = np.zeros((0, 1, n_lanes))
    e = np.empty(n_lanes)
    fused = cg.fused_kernel(pr.folded, pr.cams, 0, (False, 0.0, cap, np.inf), points3d=True)
    _lk.call_fused(fused, cand, rot, pos, dx, dx, dx.astype(np.float32),
                   dx.astype(np.float32), dx, o3, np.zeros((0, n_lanes), np.int64), e)
    np.testing.assert_array_equal(e, refs)
    assert (e > 0).all()


@pytest.mark.parametrize(("kind", "error"), [
    ("locust", (False, 0.0, np.inf, np.inf)),
    ("locust, offsets after the joints", (True, 0.5, 10.0, 10.0)),
    ("free root, distorted pinholes", (True, 1.0, np.inf, 20.0))])
def test_float32_error_is_within_float32_rounding(kind, error):
    pr = _problem(kind)
    args = _lanes(pr, 37, 9, np.random.default_rng(4))[0]
    e32, e64 = np.empty(37), np.empty(37)
    _lk.call_fused(cg.fused_kernel(pr.folded, pr.cams, 9, error, single=True), *args, e32)
    _lk.call_fused(cg.fused_kernel(pr.folded, pr.cams, 9, error), *args, e64)
    # lanes whose root sits at a camera's centre put markers at its plane (z = 0), where
    # float32 and float64 may disagree on the side: every other lane is compared
    compared = [ln for ln in range(37) if not (ln % 9 == 4 and pr.cams.kind[0] != 0)]
    np.testing.assert_allclose(e32[compared], e64[compared], rtol=2e-5, atol=2e-3)
    assert np.any(e32 != e64)  # it is float32
    # the kernel computes in float32 throughout: no float64 vector code for its arithmetic
    src = cg.fused_source(pr.folded, pr.cams, 9, error, single=True)
    assert "sincos32(" in src and "dx32[" in src and "np.inf" not in src.split("for ln")[1]


def test_literals_are_folded_exactly():
    code = cg._Code()
    assert code.mul("a", 0.0) == 0.0 and code.mul(1.0, "a") == "a" and code.add(0.0, "a") == "a"
    assert code.sub("a", 0.0) == "a" and code.mul(2.0, 3.0) == 6.0 and code.div("a", 1.0) == "a"
    t = code.mul(-1.0, "a")
    assert code.lines[-1] == f"{t} = -a"
    # the scalar kernel's left-to-right sums, zero terms left out
    s = code.dot([("p", 0.0), ("q", 2.0), ("r", 1.0)], "s0")
    assert code.lines[-3:] == ["t2 = q * 2.0", "t3 = s0 + t2", "t4 = t3 + r"] and s == "t4"
    assert code.lit(0.1) == "0.1" and code.lit(np.inf) == "np.inf"
    # float32: literals are named float32 constants, folded in float32
    single = cg._Code(single=True)
    assert single.mul(0.1, 3.0) == float(np.float32(0.1) * np.float32(3.0)) != 0.1 * 3.0
    t = single.mul("a", 0.5)
    assert single.lines[-1] == f"{t} = a * k0" and single.lit(0.5) == "k0"
    assert single.constants() == ["k0 = np.float32(0.5)"]


def test_detections_are_padded_to_few_counts():
    assert [cg.padded_detections(c) for c in (0, 1, 5, 8, 9, 12, 13, 16)] == \
        [1, 1, 5, 8, 12, 12, 16, 16]
    pr = _problem("locust")
    assert cg.fits(pr.folded, pr.cams, cg.MAX_DETECTIONS)
    assert not cg.fits(pr.folded, pr.cams, cg.MAX_DETECTIONS + 1)


def test_kernels_are_shared_and_a_damaged_source_is_rewritten(monkeypatch, tmp_path):
    monkeypatch.setattr(cg, "generated_dir", lambda: tmp_path)
    monkeypatch.setattr(cg, "_loaded", {})
    pr = _problem("locust")
    error = (True, 0.5, 10.0, 10.0)
    first = cg.fused_kernel(pr.folded, pr.cams, 6, error)
    assert cg.fused_kernel(pr.folded, pr.cams, 6, error) is first
    path = cg.source_path(cg.fused_source(pr.folded, pr.cams, 6, error))
    path.write_text("torn")  # e.g. a process killed while writing, by an older version
    monkeypatch.setattr(cg, "_loaded", {})
    again = cg.fused_kernel(pr.folded, pr.cams, 6, error)
    assert "do not edit" in path.read_text() and again is not first
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")]


def test_an_unwritable_cache_falls_back_to_the_general_loops(monkeypatch, tmp_path):
    with bundled_chain("locust_hindleg.xml") as p:
        body = load_body(p)
    blocked = tmp_path / "file"
    blocked.write_text("")  # a file where the folder should be: mkdir fails
    monkeypatch.setattr(cg, "generated_dir", lambda: blocked / "lanes")
    monkeypatch.setattr(cg, "_loaded", {})
    fitter = Fitter(body, locust_cameras(), AnnealParams(backend="lanes").with_schedule(300))
    views = planted_detections(body, locust_cameras(), smooth_random_motion(body, 4, 1, seed=1))
    with pytest.warns(UserWarning, match="general loops"):
        assert fitter._fused_kernel(fitter.observations(views).arrays(np.arange(4)),
                                    fitter._error_args(fitter.params, 0)) == (_lk.no_fused, 0)
        lanes = fitter.fit(views)
    scalar = Fitter(body, locust_cameras(), replace(fitter.params, backend="scalar")).fit(views)
    assert [r.angles_deg.tolist() for r in lanes] == [r.angles_deg.tolist() for r in scalar]


def test_log_of_a_draw_is_within_one_ulp_of_libm():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.integers(1, 2**53, 20000) * 2.0**-53,
                        [2.0**-53, 0.5, 1 - 2.0**-53, np.sqrt(0.5), np.nextafter(np.sqrt(0.5), 1)]])
    got = np.array([_fastmath.log_unit(v) for v in x])
    assert np.all(np.abs(got - np.log(x)) <= np.spacing(np.abs(np.log(x))))
    assert _fastmath.log_unit(0.0) == -np.inf


def test_allowed_runs_of_a_histogram():
    hist = np.zeros((3, 10))
    hist[0, [0, 1, 5, 9]] = 1.0  # runs [0, 2), [5, 6), [9, 10): the last touches the end
    hist[1, ::2] = 1.0  # five runs: too many, the kernel looks bins up instead
    runs, n_runs = _li.allowed_runs(hist, np.array([10, 10, 10]), 0.5)
    assert n_runs.tolist() == [3, -1, 0]
    assert runs[0, :3].tolist() == [[0, 2], [5, 6], [9, 10]]
