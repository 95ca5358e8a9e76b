"""The spatial lookup of detections: views with many detections are kept sorted by x and
searched by a sweep along x (``_kernels.error2d.nearest_sorted``); it must give exactly
the nearest detection of a scan, and a fit must not depend on the order of detections."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics._kernels import codes as _codes
from kinematics._kernels import error2d as _error2d
from kinematics._kernels import objective as _objective
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.error_function import projection_error
from kinematics.fit.inputs import as_ragged
from kinematics.fit.settings import ErrorOptions
from kinematics.observe.observations import Observations
from tests.fixtures.bodies import three_legs
from tests.fixtures.cameras import ring
from tests.fixtures.planted import planted_postures

VARIANTS = [ErrorOptions(), ErrorOptions("bounded", cap_px=10.0),
            ErrorOptions("bounded", cap_px=10.0, one_to_one=True)]


def random_views(rng, nv, nm, counts):
    proj = rng.uniform(0, 200, (nv, nm, 2))
    proj[0, 0] = np.nan  # a marker behind a pinhole camera
    dets = []
    for n in counts:
        d = rng.uniform(0, 200, (n, 2))
        d[: n // 4, 0] = np.round(d[: n // 4, 0])  # equal x values
        if n > 1:
            d[1] = d[0]  # a duplicate: the tie goes to the lower row
        dets.append(d[np.argsort(d[:, 0], kind="stable")])
    pts = np.concatenate(dets)
    off = np.r_[0, np.cumsum(counts)].astype(np.int64)
    return proj, dets, pts, off


def test_sweep_finds_the_scans_nearest():
    rng = np.random.default_rng(4)
    for _ in range(300):
        n = int(rng.integers(_error2d.SWEEP_MIN + 1, 300))
        pts = rng.uniform(0, 100, (n, 2))
        pts[: n // 3, 0] = np.round(pts[: n // 3, 0])
        pts = pts[np.argsort(pts[:, 0], kind="stable")]
        claimed = rng.random(n) < 0.2
        px, py = rng.uniform(-20, 120, 2)
        d2 = ((pts - [px, py]) ** 2).sum(axis=1)
        d2[claimed] = np.inf
        best, arg = _error2d.nearest_sorted(px, py, pts, 0, n, claimed)
        assert arg == int(np.argmin(d2)) and best == pytest.approx(d2.min(), rel=1e-12)
        _, arg_all = _error2d.nearest_sorted(px, py, pts, 0, n, _codes.NO_CLAIMS)
        assert arg_all == int(np.argmin(((pts - [px, py]) ** 2).sum(axis=1)))
    assert _error2d.nearest_sorted(np.nan, 0.0, pts, 0, len(pts), _codes.NO_CLAIMS) == (np.inf, -1)


@pytest.mark.parametrize("hide", [False, True], ids=["all-seen", "hidden-marks"])
@pytest.mark.parametrize("opts", VARIANTS, ids=["paper", "bounded", "one-to-one"])
def test_kernels_equal_the_twin_on_many_detections(opts, hide):
    rng = np.random.default_rng(9)
    for _ in range(40):
        nv, nm = 3, int(rng.integers(2, 12))
        counts = [int(rng.integers(_error2d.SWEEP_MIN_FAST + 1, _error2d.SWEEP_MIN_FAST + 80)),
                  int(rng.integers(0, 5)),
                  int(rng.integers(_error2d.SWEEP_MIN + 1, _error2d.SWEEP_MIN + 40))]
        proj, dets, pts, off = random_views(rng, nv, nm, counts)
        hidden = rng.random((nv, nm)) < (0.3 if hide else 0.0)
        marks = hidden.T.astype(float) if hide else _codes.NO_HIDDEN  # the kernels' (nm, nv)
        want, want_views = projection_error(proj, dets, opts, hidden)
        per_view = np.empty(nv)
        nearest = np.empty(nm, np.int64)
        got = _error2d.projection_error(proj, pts, off, marks, opts.bidirectional,
                                  opts.penalty_weight, opts.cap, opts.penalty_cap,
                                  opts.one_to_one, per_view, nearest)
        assert got == pytest.approx(want, rel=1e-12)
        np.testing.assert_allclose(per_view, want_views, rtol=1e-12)
        whole = _objective.partition_error(_codes.OBJ_NEAREST, proj, np.zeros((nm, 3)), pts,
                                   np.ones(len(pts)), off, marks, opts.cap, 0, nm,
                                   np.zeros(len(pts), np.bool_), opts.penalty_weight
                                   if opts.bidirectional else 0.0, opts.penalty_cap,
                                   opts.one_to_one, nearest)
        assert whole == pytest.approx(want, rel=1e-12)
        if not (opts.bidirectional or opts.one_to_one or hide):
            assert _error2d.paper_error(proj, pts, off, opts.cap) == pytest.approx(want, rel=1e-12)


def test_ragged_detections_are_sorted_by_x_in_each_view():
    frames = [[np.array([[5.0, 1.0], [1.0, 2.0], [3.0, 0.0]]), np.array([[2.0, 2.0]])],
              [np.array([[9.0, 9.0], [np.nan, 1.0], [0.0, 1.0]]), np.empty((0, 2))]]
    rag = as_ragged(frames, ["a", "b"])
    assert rag.offsets.tolist() == [0, 3, 4, 6, 6]
    assert rag.points[:, 0].tolist() == [1.0, 3.0, 5.0, 2.0, 0.0, 9.0]
    assert rag.dropped.tolist() == [0, 1]


def test_fit_does_not_depend_on_the_order_of_detections():
    body = three_legs()
    cams = ring(3)
    _, frames = planted_postures(body, cams, 3, seed=2, shuffle=False)
    rng = np.random.default_rng(0)
    ghosts = [[np.r_[d, rng.uniform(0, 640, (70, 2))] for d in f] for f in frames]  # swept
    shuffled = [[d[rng.permutation(len(d))] for d in f] for f in ghosts]
    params = AnnealParams(match="views", candidates=1, threshold_mode="absolute",
                          reanalysis_threshold=1e9).with_schedule(800)
    a = Fitter(body, cams, params).fit(ghosts)
    b = Fitter(body, cams, params).fit(shuffled)
    # Observations built directly from unsorted rows are sorted too (the sweep needs it)
    pts = np.concatenate([d for f in shuffled for d in f])
    off = np.r_[0, np.cumsum([len(d) for f in shuffled for d in f])]
    c = Fitter(body, cams, params).fit(Observations.unlabelled(pts, off, list(cams)))
    for ra, rb, rc in zip(a, b, c, strict=True):
        np.testing.assert_array_equal(ra.angles_deg, rb.angles_deg)
        np.testing.assert_array_equal(ra.angles_deg, rc.angles_deg)
        assert ra.error == rb.error == rc.error
