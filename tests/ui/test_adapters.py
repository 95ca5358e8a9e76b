"""The GUI's pure adapters: what is drawn equals the model's projection; table, timeline,
histogram bars and body edits (no Qt involved)."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics.errors import KinematicsError
from kinematics.fit import FrameResult
from kinematics.model import validate_body
from kinematics.model.fk import forward_kinematics
from kinematics.model.histograms import Histogram
from ui import adapters
from videotrack.synth.paper_setup import locust_cameras


@pytest.fixture
def cams():
    return list(locust_cameras().values())


@pytest.fixture
def posture(locust):
    a = locust.mean_posture_deg()
    a[[0, 1, 5, 8]] = (190.0, 12.0, 25.0, 80.0)
    return a


def result(frame, error, status="ok", n_axes=9, angles=None):
    return FrameResult(frame=frame, angles_deg=np.full(n_axes, float(frame)) if angles is None
                       else angles, error=error, error_per_view=np.array([error / 2] * 2),
                       runs=1 + (status == "reanalysed"), iterations=100, seed=0,
                       status=status, root_positions=np.zeros((1, 3)))


def test_overlays_are_the_projected_forward_kinematics(locust, cams, posture):
    overlays = adapters.view_overlays(locust, cams, posture)
    pose = forward_kinematics(locust, posture)
    for cam, ov in zip(cams, overlays, strict=True):
        np.testing.assert_allclose(ov.markers, cam.project(pose.markers))
        # the skeleton runs joint -> distal segment end: J0-coxa, J1-femur, J2-tibia
        starts, ends = ov.lines[0::2], ov.lines[1::2]
        np.testing.assert_allclose(starts, cam.project(pose.joints))
        np.testing.assert_allclose(ends, cam.project(pose.segment_ends))


def test_skeleton_links_translated_child_joints(locust):
    body = adapters.edit_joint(locust, "J1", translation=(0.0, 5.0, 0.0))
    sk = adapters.skeleton(body)
    # joints J0, J1, J2 are rows 0..2, segment ends 3..5: J1 sits 5 units off the coxa end
    assert sk.edges.tolist() == [[0, 3], [3, 1], [1, 4], [2, 5]]
    geo = adapters.posture_geometry(body, body.mean_posture_deg())
    assert np.linalg.norm(geo.points[1] - geo.points[3]) == pytest.approx(5.0)


def test_frame_detections_of_a_record_and_outside():
    class Det:
        n_records = 2

        def points_of(self, r, v):
            return np.array([[r, v]], float)

    got = adapters.frame_detections(Det(), 1, 2)
    assert [g.tolist() for g in got] == [[[1, 0]], [[1, 1]]]
    assert [g.shape for g in adapters.frame_detections(Det(), 5, 2)] == [(0, 2), (0, 2)]
    assert [g.shape for g in adapters.frame_detections(None, 0, 3)] == [(0, 2)] * 3


def test_table_timeline_and_highlight_rule():
    results = {0: result(0, 2.0), 2: result(2, 15.0, "failed"), 3: result(3, 8.0, "corrected")}
    t = adapters.frame_table(results, 4, 2)
    assert t.frame.tolist() == [0, 1, 2, 3]
    np.testing.assert_array_equal(t.error, [2.0, np.nan, 15.0, 8.0])
    assert t.status == ["ok", adapters.NOT_FITTED, "failed", "corrected"]
    assert t.runs.tolist() == [1, 0, 1, 1]
    np.testing.assert_array_equal(t.error_per_view[2], [7.5, 7.5])
    assert adapters.is_bad(t.error, 10.0).tolist() == [False, False, True, False]
    assert adapters.bad_frames(results, 5.0) == [2, 3]
    # an ambiguous frame needs a look although its error is small
    checked = {**results, 1: result(1, 1.0, "ambiguous")}
    assert adapters.frames_to_check(checked, 10.0) == [1, 2]
    line = adapters.timeline(results, 4, 9)
    np.testing.assert_array_equal(line.error, t.error)
    assert np.isnan(line.angles_deg[1]).all() and (line.angles_deg[2] == 2.0).all()
    row = adapters.table_row(results[2], 2)
    assert row[0] == 15.0 and row[2] == 1 and np.isnan(row[3]) and row[4] == "failed"
    assert np.isnan(t.sd).all() and np.isnan(line.sd_deg).all()  # no noise model, no sd


def test_the_table_and_timeline_carry_the_sd():
    """The table's sd is a frame's largest axis sd (sorting by it lists the least sure
    frames first); the timeline keeps every axis' sd for its bands."""
    from dataclasses import replace
    sd = np.linspace(0.1, 0.9, 9)
    results = {0: replace(result(0, 2.0), sd_deg=sd), 1: result(1, 3.0)}
    t = adapters.frame_table(results, 2, 2)
    assert t.sd[0] == pytest.approx(0.9) and np.isnan(t.sd[1])
    line = adapters.timeline(results, 2, 9)
    np.testing.assert_array_equal(line.sd_deg[0], sd)
    assert np.isnan(line.sd_deg[1]).all()


def test_learning_angles_follow_the_status_option():
    results = {f: result(f, 1.0, s) for f, s in
               enumerate(["ok", "failed", "reanalysed", "corrected", "no-detections"])}
    results[4] = result(4, np.nan, "no-detections", angles=np.full(9, np.nan))
    good = adapters.learning_angles(results)
    assert good[:, 0].tolist() == [0, 2, 3]
    assert adapters.learning_angles(results, None)[:, 0].tolist() == [0, 1, 2, 3]
    assert adapters.learning_angles({}, None).size == 0


def test_histogram_bars_unwrap_a_range_through_180(locust):
    phi = locust.axis_refs()[0].axis.histogram  # uniform over [120, 220]
    bars = adapters.histogram_bars(phi, value_deg=-170.0)
    assert np.all(np.diff(bars.centres) > 0)
    occupied = bars.centres[bars.heights > 0]
    assert occupied.min() == pytest.approx(120.5) and occupied.max() == pytest.approx(219.5)
    assert bars.value == pytest.approx(190.0)  # -170 shown where it lies in the range
    assert bars.mean == pytest.approx(170.0)
    assert bars.view_range == pytest.approx((110.0, 230.0))
    np.testing.assert_allclose(np.sort(bars.heights), np.sort(phi.values))


def test_free_axes(locust):
    assert adapters.free_axes(locust) == [0, 1, 2, 5, 8]


def test_body_edits_change_the_projection_and_stay_valid(locust, cams, posture):
    before = adapters.view_overlays(locust, cams, posture)[0].markers
    longer = adapters.edit_segment(locust, "femur", length=120.0)
    assert adapters.find_element(longer, "segment", "femur").length == 120.0
    after = adapters.view_overlays(longer, cams, posture)[0].markers
    np.testing.assert_allclose(after[:2], before[:2])  # M0, M1 before the femur stay
    assert np.linalg.norm(after[2] - before[2]) > 5  # M2 at the femur's end moves
    moved = adapters.edit_marker(locust, "M3", offset=(-10.0, 0.0, 0.0))
    assert adapters.find_element(moved, "marker", "M3").offset == (-10.0, 0.0, 0.0)
    rooted = adapters.edit_root(locust, "hindleg", position=(1.0, 2.0, 3.0))
    assert rooted.root_positions().tolist() == [[1.0, 2.0, 3.0]]
    narrow = adapters.edit_axis(locust, 8, min_deg=40.0, max_deg=100.0)
    gamma = narrow.axis_refs()[8].axis
    assert (gamma.min_deg, gamma.max_deg) == (40.0, 100.0)
    assert gamma.histogram == Histogram.uniform(40.0, 100.0)
    locked = adapters.edit_axis(locust, 8, locked_deg=90.0)
    assert locked.axis_refs()[8].axis.locked_deg == 90.0
    assert adapters.edit_axis(locked, 8, locked_deg=None).axis_refs()[8].axis.locked_deg is None
    for b in (longer, moved, rooted, narrow, locked):
        validate_body(b)


def test_root_settings_choose_mode_marker_and_windows(locust):
    assert adapters.chain_marker_names(locust, "hindleg") == ["M0", "M1", "M2", "M3"]
    assert adapters.root_markers(locust, "hindleg") == ["M0", "M1"]  # on the coxa
    follow = adapters.edit_root_settings(locust, "hindleg", mode="marker", position=(1, 2, 3),
                                         marker="M0")
    root = follow.chains[0].root
    assert (root.mode, root.marker, root.position) == ("marker", "M0", (1.0, 2.0, 3.0))
    free = adapters.edit_root_settings(locust, "hindleg", mode="free", position=(0, 0, 0),
                                       marker=None, translation_text=" 2.5 ",
                                       rotation_text="")
    root = free.chains[0].root
    assert (root.mode, root.translation_window, root.rotation_window_deg) == ("free", 2.5, None)
    for b in (follow, free):
        validate_body(b)
    # empty windows take the defaults of kinematics.fit.placement.root_windows
    from kinematics.fit.placement import root_windows

    assert adapters.default_root_windows(locust, "hindleg") == tuple(
        root_windows(adapters.edit_root(locust, "hindleg", mode="free"))[0])
    # what the typed values cannot express is a located error, the rest validate_body's
    with pytest.raises(KinematicsError, match="chain 'hindleg' root: a marker root follows"):
        adapters.edit_root_settings(locust, "hindleg", mode="marker", position=(0, 0, 0),
                                    marker=None)
    with pytest.raises(KinematicsError, match=r"rotation window must be a number > 0.*'abc'"):
        adapters.edit_root_settings(locust, "hindleg", mode="free", position=(0, 0, 0),
                                    marker=None, rotation_text="abc")
    negative = adapters.edit_root_settings(locust, "hindleg", mode="free", position=(0, 0, 0),
                                           marker=None, translation_text="-1")
    with pytest.raises(KinematicsError, match="translation_window must be a number > 0"):
        validate_body(negative)
    # a free root turns about all three axes of its joint: not with a locked one
    locked = adapters.edit_axis(free, 1, locked_deg=0.0)
    with pytest.raises(KinematicsError, match=r"free root .* 'psi' is locked"):
        validate_body(locked)
    # and it needs markers on the root joint's segments
    bare = adapters.edit_segment(free, "coxa", markers=())
    assert adapters.default_root_windows(bare, "hindleg") is None
    with pytest.raises(KinematicsError, match="needs markers on the segments"):
        validate_body(bare)


def test_marker_axes_follow_the_chain_to_the_root(locust):
    assert adapters.marker_axes(locust, 0) == [0, 1, 2]  # M0 on the coxa: J0 only
    assert adapters.marker_axes(locust, 2) == [0, 1, 2, 5]  # M2: J0 and J1.beta
    assert adapters.marker_axes(locust, 3) == [0, 1, 2, 5, 8]


def test_marker_drag_finds_the_axis_that_puts_it_there(locust, cams, posture):
    moved = posture.copy()
    moved[8] += 20.0  # gamma
    target = cams[0].project(forward_kinematics(locust, moved).markers[3])
    sol = adapters.solve_marker_drag(locust, cams[0], posture, None, 3, target)
    assert sol.axis == 8
    assert sol.value_deg == pytest.approx(moved[8], abs=0.25)
    assert sol.residual_px < 0.5
    assert adapters.solve_marker_drag(locust, cams[0], posture, None, 3, target, axes=[]) is None


def test_body_tree_and_reach(locust):
    rows = adapters.body_tree(locust)
    assert rows[0] == (0, "chain", "hindleg", None)
    assert rows[1] == (1, "joint", "J0", None)
    assert [r for r in rows if r[1] == "axis"][-1] == (6, "axis", "gamma", 8)
    assert [r[2] for r in rows if r[1] == "marker"] == ["M0", "M1", "M2", "M3"]
    assert adapters.body_reach(locust) == pytest.approx(13 + 91 + 77 + 13)


def test_clamp_to_range(locust):
    a = adapters.clamp_to_range(locust, np.full(9, 500.0))
    assert a.tolist() == [220, 40, 10, 0, 0, 60, 0, 0, 160]


def test_relative_path(tmp_path):
    assert adapters.relative_path(tmp_path / "a" / "b.xml", tmp_path) == "a/b.xml"
    assert adapters.relative_path("/elsewhere/c.xml", tmp_path) == "/elsewhere/c.xml"


def test_detection_preview_matches_the_detections_file(synth_project):
    from videotrack.detect.detections import load_detections
    from videotrack.detect.run import FrameDetector, settings_from_config, video_paths
    from videotrack.detect.video import open_videos
    from videotrack.project.config import load_config

    config = load_config(synth_project / "project.toml")
    settings = settings_from_config(config)
    det = load_detections(synth_project / "detections.npz")
    with open_videos(video_paths(config)) as videos:
        detector = FrameDetector(videos, settings)
        views = adapters.detection_preview(detector, videos.read(5))
    assert len(views) == 2
    with open_videos(video_paths(config)) as videos:
        frame = videos.read(5)[0]
    for v, view in enumerate(views):
        assert view.mask.shape == (288, 360)
        np.testing.assert_array_equal(view.image, frame[:, 360 * v: 360 * (v + 1)])
        np.testing.assert_allclose(view.points, det.points_of(5, v))
        ix = np.rint(view.points).astype(int)
        assert np.all(view.mask[ix[:, 1], ix[:, 0]] > 0)  # every centroid lies in the mask
        rgb = view.overlay()
        assert rgb.shape == (288, 360, 3)
        assert (rgb[view.mask > 0] == (255, 40, 220)).all()
