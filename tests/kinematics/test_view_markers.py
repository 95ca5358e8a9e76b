"""Views that show only some model markers (``Fitter(view_markers=...)``): a camera's image
split by marker colour into one view per colour, each matched to its own markers only."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinematics.errors import KinematicsError
from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.error_function import posture_error
from kinematics.fit.refine import refine, refine_many
from kinematics.fit.settings import ErrorOptions
from kinematics.model.fk import forward_kinematics, forward_kinematics_reference
from tests.fixtures.bodies import three_legs
from tests.fixtures.cameras import ring
from tests.fixtures.planted import marker_errors, planted_postures
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import locust_cameras

RED, GREEN = ("M0", "M1", "M2"), ("M3",)


def colour_views(cams):
    """Each camera twice: one view keeps the red markers, one the green."""
    out, shows = {}, {}
    for name, cam in cams.items():
        for colour, markers in (("red", RED), ("green", GREEN)):
            out[f"{name}_{colour}"] = cam
            shows[f"{name}_{colour}"] = markers
    return out, shows


def coloured_frames(body, cams, truth, seed=0, decoy_px=6.0):
    """Per frame and camera of ``cams``, its two colour views: that colour's markers (0.2 px
    noise) and, 6 px from the tibia tip, a red blob (the next leg's marker): an unlabelled
    fit takes it for the tip."""
    rng = np.random.default_rng(seed)
    names = body.marker_names
    frames = []
    for a in truth:
        markers = forward_kinematics(body, a).markers
        views = []
        for cam in cams.values():
            p = cam.project(markers) + rng.normal(0, 0.2, (len(markers), 2))
            tip = p[names.index("M3")]
            decoy = tip + decoy_px * np.array([0.6, 0.8])
            views.append(np.concatenate([p[[names.index(m) for m in RED]], decoy[None]]))
            views.append(p[[names.index(m) for m in GREEN]])
        frames.append(views)
    return frames


def test_a_view_matches_only_the_markers_it_shows(locust):
    """E equals the twin's with the markers a view does not show hidden there; the red
    decoy near the tip costs the green tip nothing; refine honours the split."""
    cams, shows = colour_views(locust_cameras())
    truth = smooth_random_motion(locust, 4, 4, seed=2)
    frames = coloured_frames(locust, locust_cameras(), truth)
    fitter = Fitter(locust, cams, AnnealParams(), view_markers=shows)
    names = locust.marker_names
    hidden = np.array([[m not in shows[v] for m in names] for v in cams])
    np.testing.assert_array_equal(fitter.unseen, hidden)
    opts = fitter.params.error
    for k in range(len(truth)):
        e, per_view = fitter.error(truth[k], frames[k])
        want, want_views = posture_error(locust, cams, truth[k], frames[k], None, opts, hidden)
        assert e == pytest.approx(want, rel=1e-9)
        np.testing.assert_allclose(per_view, want_views, rtol=1e-9)
    plain = Fitter(locust, cams, AnnealParams())
    # without the split the tip's nearest in a red view is the decoy (6 px), not nothing
    assert plain.error(truth[0], frames[0])[0] > fitter.error(truth[0], frames[0])[0] + 5
    one = refine(fitter, truth[0] + 3.0, frames[0])
    assert one.error == pytest.approx(fitter.error(one.angles_deg, frames[0])[0], rel=1e-9)
    many = refine_many(fitter, truth + 3.0, frames)
    for k, r in enumerate(many):
        assert r.error == pytest.approx(fitter.error(r.angles_deg, frames[k])[0], rel=1e-9)
        assert r.error <= fitter.error(truth[k] + 3.0, frames[k])[0]


def test_colour_views_keep_the_tip_off_another_legs_marker(locust):
    """With the red decoy 6 px from the tip in both cameras, the split fit finds every
    axis within 2 degrees; the fit that cannot tell colours apart is pulled off."""
    cams, shows = colour_views(locust_cameras())
    truth = smooth_random_motion(locust, 12, 12, seed=5)
    frames = coloured_frames(locust, locust_cameras(), truth, seed=5)
    params = replace(AnnealParams(), seed=1)
    split = Fitter(locust, cams, params, view_markers=shows).fit(frames)
    free = ~locust.locked_mask()
    err = np.abs(np.array([r.angles_deg for r in split]) - truth)[:, free]
    assert err.max() < 2.0
    tip = locust.marker_names.index("M3")
    for r in split:  # the tip has no residual in the red views
        assert np.isnan(r.marker_residuals[0, tip]) and np.isfinite(r.marker_residuals[1, tip])
        assert r.unexplained == 2  # the decoy in each red view: no red marker near it
    merged = [[np.concatenate(f[2 * c: 2 * c + 2]) for c in range(2)] for f in frames]
    plain = Fitter(locust, locust_cameras(), params).fit(merged)
    plain_err = np.abs(np.array([r.angles_deg for r in plain]) - truth)[:, free]
    assert plain_err.max() > 2 * err.max()


def test_view_markers_refuse_what_they_cannot_mean(locust):
    cams, shows = colour_views(locust_cameras())
    with pytest.raises(KinematicsError, match="no view named 'front'") as err:
        Fitter(locust, cams, view_markers={"front": ["M0"]})
    assert err.value.field == "view_markers"
    with pytest.raises(KinematicsError, match="'M9' is not a marker"):
        Fitter(locust, cams, view_markers={"side_red": ["M9"]})
    with pytest.raises(KinematicsError, match="list of marker names"):
        Fitter(locust, cams, view_markers={"side_red": "M0"})
    assert Fitter(locust, cams, view_markers={}).unseen is None
    assert Fitter(locust, cams, view_markers={"side_red": list(locust.marker_names)}
                  ).unseen is None
    fitter = Fitter(locust, cams, replace(AnnealParams(), match="3d"), view_markers=shows)
    frames = coloured_frames(locust, locust_cameras(), smooth_random_motion(locust, 2, 2, seed=0))
    with pytest.raises(KinematicsError, match="3 or more views of each colour") as err:
        fitter.fit(frames)
    assert err.value.field == "match"
    assert Fitter(locust, cams, view_markers=shows).match_for(frames) == "views"


def test_legs_of_two_colours_fitted_in_3d_each_colour_triangulated_apart():
    """Three legs, the middle one green, seen by 5 cameras: one view per camera and colour.
    Each colour is triangulated from its own views; the cloud says which markers may take a
    point; the body is fitted in 3D with every leg on its own points."""
    body = three_legs()
    cams = ring()
    names = body.marker_names
    green = [m for m in names if m.startswith("b")]
    angles, _ = planted_postures(body, cams, 6, seed=3)
    rng = np.random.default_rng(0)
    views, shows, split = {}, {}, []
    for name, cam in cams.items():
        for colour, markers in (("red", [m for m in names if m not in green]),
                                ("green", green)):
            views[f"{name}_{colour}"] = cam
            shows[f"{name}_{colour}"] = markers
    for a in angles:
        m = forward_kinematics_reference(body, a).markers
        row = []
        for cam in cams.values():
            p = cam.project(m) + rng.normal(0, 0.05, (len(m), 2))
            row += [p[[names.index(k) for k in shows[f"{cam.name}_{c}"]]]
                    for c in ("red", "green")]
        split.append(row)
    params = AnnealParams(candidates=1, threshold_mode="absolute", reanalysis_threshold=8.0,
                          error=ErrorOptions("bounded", cap_px=10.0)).with_schedule(3000)
    fitter = Fitter(body, views, params, view_markers=shows)
    assert fitter.match_for(split) == "3d"
    obs = fitter.observations(split)
    assert obs.kind == "cloud" and obs.points3d.shape[2] == 4 + len(names)
    used = obs.points3d[..., 3] > 0
    assert used.sum(axis=1).tolist() == [len(names)] * 6
    may = obs.points3d[..., 4:][used]  # each point: one colour's markers
    is_green = np.array([m in green for m in names])
    assert all(row.astype(bool).tolist() in (is_green.tolist(), (~is_green).tolist())
               for row in may)
    res = fitter.fit(split)
    err = marker_errors(body, res, angles)
    assert np.median(err) < 0.05 and err.max() < 0.2, err
    assert all(r.unexplained == 0 for r in res)
    for r in res:  # residuals only where a view shows the marker
        assert np.isnan(r.marker_residuals[np.asarray(fitter.unseen)]).all()


def test_markers_a_view_never_shows_are_kept_per_view_not_per_frame(locust):
    """with_unseen keeps one (views, markers) array however long the video; the kernels get
    it with the user's marks of each frame; keypoints of a marker a view does not show
    count as missing."""
    from kinematics.observe.observations import Observations

    cams, shows = colour_views(locust_cameras())
    fitter = Fitter(locust, cams, view_markers=shows)
    frames = coloured_frames(locust, locust_cameras(), smooth_random_motion(locust, 5, 5))
    obs = fitter.observations(frames)
    assert obs.hidden is None and obs.unseen.shape == (4, 4)
    marks = np.zeros((5, 4, 4), bool)
    marks[2, 1, 3] = True  # the user also hides the tip in side_green, frame 2
    both = obs.with_hidden(marks)
    want = np.broadcast_to(fitter.unseen, (5, 4, 4)) | marks
    np.testing.assert_array_equal(both.marks(np.arange(5)), want)
    p3 = both.arrays(np.array([2]))[4][0]
    np.testing.assert_array_equal(p3 != 0, want[2].T)
    assert both.take([2, 4]).unseen is obs.unseen
    kp = np.ones((2, 4, 4, 3))
    kobs = Observations.keypoints(kp, list(cams), locust.marker_names, locust.marker_names)
    seen = fitter.observations(kobs)
    np.testing.assert_array_equal(seen.conf.reshape(2, 4, 4) == 0,
                                  np.broadcast_to(fitter.unseen, (2, 4, 4)))
    with pytest.raises(KinematicsError, match="unseen markers need a boolean array"):
        obs.with_unseen(np.zeros((3, 4), bool))


def test_a_view_that_shows_no_marker_does_not_count_against_3d():
    body = three_legs()
    cams = ring()
    views = {**cams, "c0_blank": cams["c0"]}
    fitter = Fitter(body, views, view_markers={"c0_blank": []})
    assert fitter._views_3d == 5 and fitter.match_for([[np.zeros((0, 2))] * len(views)]) == "3d"
