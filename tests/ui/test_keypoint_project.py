"""Keypoint projects (issue 13 item 4) in the window: DeepLabCut files of three cameras, a
calibration and a project file, fitted by the same Fitter as `videotrack fit` with the same
statuses, corrections, results files and views (labelled keypoints on a blank canvas when
there is no video)."""

from __future__ import annotations

import shutil
from dataclasses import replace

import numpy as np
import pytest
from PySide6.QtCore import Qt

from kinematics.fit.error_function import labelled_error
from kinematics.model.fk import forward_kinematics
from ui import adapters
from ui.state import Session, backend
from ui.state.fitting import FIT_CONTEXT
from videotrack.cli import main
from videotrack.project.config import load_config
from videotrack.results.files import read_results, read_sidecar
from videotrack.synth.keypoints import write_session
from videotrack.workflow import plan_project

N_FRAMES = 8
#: The markerless tests' seed with the GUI tests' short schedule (a fit takes a second).
ANNEAL = "[anneal]\nseed = 1\nn_end = 3000\nn_l = 300\nn_tau = 130\n"
TRIANGULATED = ('route = "3d"\ntriangulation = "ransac"\n' + ANNEAL
                + "tau0 = 5.0\nreanalysis_threshold = 3.0\ncap_px = 30.0\n")
RESULTS = "cam0DLC.results.csv"


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """Route 2d and 3d sessions (``kp2d``, ``kp3d``), each also fitted by `videotrack fit`
    in a copy (``cli2d``, ``cli3d``)."""
    root = tmp_path_factory.mktemp("keypoint-gui")
    sessions = {}
    for route, text in (("2d", ANNEAL), ("3d", TRIANGULATED)):
        sessions[route] = write_session(root / f"kp{route}", N_FRAMES, n_cameras=3,
                                        noise_px=1.0, bad_share=0.1, project_text=text)
        shutil.copytree(root / f"kp{route}", root / f"cli{route}")
        assert main(["fit", str(root / f"cli{route}" / "project.toml")]) == 0
    return root, sessions


def copy_of(made, tmp_path, route: str = "2d"):
    root, sessions = made
    shutil.copytree(root / f"kp{route}", tmp_path / route)
    return tmp_path / route / "project.toml", sessions[route]


def open_session(project) -> Session:
    s = Session()
    s.messages = []
    s.error.connect(s.messages.append)
    s.notes = []
    s.status.connect(s.notes.append)
    assert s.open_project(project)
    return s


@pytest.fixture
def kp_window(window_on, made, tmp_path):
    project, truth = copy_of(made, tmp_path)
    w = window_on(project)
    w.truth = truth
    yield w
    w.session.close()


def test_opens_with_labelled_keypoints_on_a_blank_canvas(kp_window, qtbot):
    w = kp_window
    s, truth = w.session, w.truth
    assert w.errors == [] and s.n_frames == N_FRAMES
    assert s.view_names == ["cam0", "cam1", "cam2"] == s.error_views
    assert "no video" in w.statusBar().currentMessage() and "blank canvas" in s.notice
    assert s.frame_detections(0) == [] or all(len(d) == 0 for d in s.frame_detections(0))
    # keypoint files have no markers to detect and no views or filters to set
    assert not w.act_detect.isEnabled() and not w.act_settings.isEnabled()
    assert w.act_fit_all.isEnabled() and w.act_fit_current.isEnabled()
    s.set_frame(5)
    names = s.body.marker_names
    for k, (view, cam) in enumerate(zip(w.video_views, truth.camera_list, strict=True)):
        # the canvas has the calibrated image size
        assert view.image.image.shape == (cam.image_size[1], cam.image_size[0])
        drawn = view.drawn()
        written = truth.keypoints[k, 5]  # as the DLC file holds them (NaN: missing)
        present = np.flatnonzero(np.isfinite(written).all(axis=1))
        np.testing.assert_array_equal(drawn["keypoints"][:, 2], present)  # missing: absent
        np.testing.assert_allclose(drawn["keypoints"][:, :2], written[present], atol=1e-3)
        # one colour per marker, the same as its model marker's fill, faded by the score
        for spot in view.keypoints.points():
            m = int(spot.data())
            assert spot.pen().color().name() == view.markers.points()[m].brush().color().name()
            score = s.frame_keypoints(5)[k][m, 2]
            assert spot.pen().color().alphaF() == pytest.approx(0.25 + 0.75 * score, abs=0.01)
        # the model's markers projected through the view's camera
        angles, roots, _ = s.posture()
        pose = forward_kinematics(s.body, angles, roots)
        np.testing.assert_allclose(drawn["markers"], cam.project(pose.markers), atol=1e-9)
        assert len(drawn["markers"]) == len(names)
        assert f"{len(present)} keypoints" in view.info.textItem.toPlainText()
    # the residual table measures each marker against its own keypoint
    kp = s.frame_keypoints(5)
    expected = np.linalg.norm(s.overlays()[1].markers - kp[1][:, :2], axis=1)
    for m in range(len(names)):
        text = w.marker_table.text(m, 1)
        assert text == "–" if not np.isfinite(expected[m]) else float(text) == pytest.approx(
            expected[m], abs=0.006)


def test_fit_all_and_save_is_what_videotrack_fit_writes(made, tmp_path, qtbot, wait_idle):
    project, _ = copy_of(made, tmp_path)
    cli = read_results(made[0] / "cli2d" / RESULTS)
    s = open_session(project)
    assert s.fit()
    assert s.busy  # in the worker: the window stays free
    wait_idle(s)
    assert s.messages == []
    # same Fitter, seed and frames: the same statuses and errors, exactly
    assert [s.results[f].status for f in range(N_FRAMES)] == list(cli.status)
    np.testing.assert_array_equal([s.results[f].error for f in range(N_FRAMES)], cli.error)
    np.testing.assert_array_equal([s.results[f].angles_deg for f in range(N_FRAMES)],
                                  cli.angles_deg)
    np.testing.assert_array_equal(
        [s.results[f].error_per_view for f in range(N_FRAMES)], cli.error_per_view)
    assert s.save()
    saved = read_results(project.parent / RESULTS)
    assert saved.view_names == cli.view_names
    np.testing.assert_array_equal(saved.error, cli.error)
    np.testing.assert_array_equal(saved.video_frames, cli.video_frames)
    side = read_sidecar(project.parent / RESULTS)
    assert side["source"] == "videotrack gui" and len(side["keypoints_sha256"]) == 3
    # the command line takes the window's results as its own: nothing to fit
    assert plan_project(load_config(project)) == ("up to date", "")
    s.close()
    again = open_session(project)  # and the window reads them back
    assert again.messages == [] and len(again.results) == N_FRAMES
    assert [again.results[f].status for f in range(N_FRAMES)] == list(cli.status)
    again.close()


def test_fit_a_frame_and_the_corrections(made, tmp_path, qtbot, wait_idle):
    project, _ = copy_of(made, tmp_path)
    s = open_session(project)
    fitter = s._fitter()
    obs = s.keypoints.observations
    # F6: one frame, as the fitter fits it with FIT_CONTEXT frames on either side (the
    # path through time's context), only that frame kept
    assert s.fit([2], "fit frame")
    wait_idle(s)
    with_context = fitter.fit(obs, list(range(0, 2 + FIT_CONTEXT + 1)))[2]
    assert with_context.frame == 2 and sorted(s.results) == [2]
    assert s.results[2].error == with_context.error
    assert s.results[2].status == with_context.status
    assert s.fit()
    wait_idle(s)
    # a pinned axis is held while the rest is re-fitted
    axis = s.body.axis_labels.index("stifle.flex")
    value = float(s.results[3].angles_deg[axis]) + 6.0
    assert s.correct({axis: value}, frame=3)
    wait_idle(s)
    r = s.results[3]
    assert r.status == "corrected" and r.angles_deg[axis] == pytest.approx(value)
    assert s.pins[3] == {axis: value}
    # without a re-fit E is the labelled objective of the posture as set (its NumPy twin)
    assert s.correct({axis: value + 3.0}, refit=False, frame=4)
    r = s.results[4]
    proj = fitter.project(r.angles_deg, r.root_positions)
    kp = np.stack(s.frame_keypoints(4))
    kp[..., 2] = np.where(np.isfinite(kp[..., 2]), kp[..., 2], 0.0)
    e, per_view = labelled_error(proj, kp, s.params.error)
    assert r.error == pytest.approx(e, rel=1e-9)
    np.testing.assert_allclose(r.error_per_view, per_view, rtol=1e-9)
    s.undo()
    assert s.results[4].status != "corrected"
    # dragging a model marker onto its keypoint pins the axes above it
    knee = s.body.marker_names.index("knee")
    s.set_frame(1)
    target = s.frame_keypoints(1)[0][knee, :2]
    assert s.drag_marker(0, knee, target)
    wait_idle(s)
    assert s.results[1].status == "corrected" and set(s.pins[1]) == set(
        adapters.marker_axes(s.body, knee))
    # spread: forward from the corrected frame 3 to the accepted frame 6
    s.set_params(replace(s.params, reanalysis_threshold=1e9))
    assert s.accept([6]) == 1
    before = dict(s.results)
    assert s.refit_from(1, frame=3)
    wait_idle(s)
    assert sorted(f for f in s.results if s.results[f] is not before[f]) == [4, 5]
    for f in (4, 5):  # each from the frame before, as the fitter does it
        again = fitter.fit_frame(backend.frame_input(obs, f, 3), f,
                                 start_deg=s.results[f - 1].angles_deg,
                                 root_positions=before[f].root_positions)
        np.testing.assert_allclose(again.angles_deg, s.results[f].angles_deg, atol=1e-5)
    # interpolate between the corrected frames 3 and 6
    assert s.correct({axis: value}, frame=6)
    wait_idle(s)
    assert s.interpolate(3, 6)
    wait_idle(s)
    assert all(s.results[f].status == "corrected" for f in (4, 5))
    assert s.results[4].angles_deg[axis] == pytest.approx(value)
    # an alternative posture, where the fit kept one, with E recomputed for it
    f = 7  # ambiguous
    assert len(s.results[f].candidates) > 1 and s.swap_candidate(f)
    r = s.results[f]
    e, _ = backend.posture_error(fitter, r.angles_deg, s.frame_input(f), r.root_positions)
    assert r.status == "corrected" and r.error == pytest.approx(e, rel=1e-12)
    assert s.messages == []
    s.close()


def test_keypoints_are_not_edited_as_detections(kp_window, qtbot):
    w = kp_window
    s = w.session
    before = dict(s.results)
    view = w.video_views[0]
    x, y = np.nanmean(s.frame_keypoints()[0][:, :2], axis=0)
    pos = view.mapFromScene(view.scene_pos(x, y))
    qtbot.mouseClick(view.viewport(), Qt.MouseButton.LeftButton,
                     Qt.KeyboardModifier.ControlModifier, pos)
    assert "keypoints are not edited here" in w.statusBar().currentMessage()
    assert s.detection_edits == {} and s.results == before and not s.dirty
    assert not s.edit_detection(0, remove=(x, y))


def test_a_keypoint_hidden_in_a_view_counts_as_missing(made, tmp_path, wait_idle):
    """H in a keypoint project: the marker's keypoint in that view is a missing label for E
    and the fit (a tracker's label on the wrong spot), saved and back on reopening; the
    triangulated route, which has no views to hide in, refuses."""
    project, _ = copy_of(made, tmp_path)
    s = open_session(project)
    assert s.fit([2], "fit frame")
    wait_idle(s)
    knee = s.body.marker_names.index("knee")
    s.set_frame(2)
    assert s.toggle_hidden(0, knee)
    obs = s.fit_detections
    marks = np.zeros((3, len(s.body.marker_names)), bool)
    marks[0, knee] = True
    one = s.keypoints.observations.take([2]).with_hidden(marks[None])
    r = s.results[2]
    assert r.error == s._fitter().error(r.angles_deg, one, r.root_positions)[0]
    lost = s.keypoints.observations.take([2]).conf.sum() - one.conf.sum()  # knee in cam0
    assert lost > 0 and obs.conf.sum() == pytest.approx(
        s.keypoints.observations.conf.sum() - lost)
    assert s.fit([2], "fit frame")
    wait_idle(s)
    assert np.isnan(s.results[2].marker_residuals[0, knee])
    assert np.isfinite(s.results[2].marker_residuals[1, knee])
    assert s.save()
    s.close()
    s = open_session(project)
    assert s.hidden_in_frame(2)[0, knee] and s.hidden_in_frame(2).sum() == 1
    assert s.messages == []
    s.close()
    project3d, _ = copy_of(made, tmp_path, "3d")
    s = open_session(project3d)
    assert not s.toggle_hidden(0, knee)
    assert "triangulated 3D points" in s.messages[-1] and not s.can_undo
    s.close()


def test_triangulated_route_fits_3d_points_and_draws_2d_keypoints(made, tmp_path, qtbot,
                                                                   wait_idle):
    from ui.views.main_window import MainWindow

    project, truth = copy_of(made, tmp_path, "3d")
    cli = read_results(made[0] / "cli3d" / RESULTS)
    w = MainWindow(use_opengl=False)
    qtbot.addWidget(w)
    s = w.session
    s.messages = []
    s.error.connect(s.messages.append)
    assert w.open_project(project)
    # no per-view error columns; the threshold is a distance in the chain's units
    assert w.table.source.headers == ["frame", "error", "runs", "sd", "status"]
    assert w.threshold.suffix() == " mm" and len(w.video_views) == 3
    assert len(w.video_views[2].drawn()["keypoints"]) > 0
    assert s.keypoints.observations.kind == "points3d"
    assert s.error_views == [] and s.view_names == ["cam0", "cam1", "cam2"]
    # the views show the 2D keypoints the points were triangulated from
    kp = s.frame_keypoints(2)
    for k in range(3):
        written = truth.keypoints[k, 2]
        ok = np.isfinite(written).all(axis=1)
        np.testing.assert_allclose(kp[k][ok, :2], written[ok], atol=1e-3)
        assert not np.isfinite(kp[k][~ok]).any()
    assert s.fit()
    wait_idle(s)
    assert [s.results[f].status for f in range(N_FRAMES)] == list(cli.status)
    np.testing.assert_array_equal([s.results[f].error for f in range(N_FRAMES)], cli.error)
    # a correction's E is the 3D objective (chain units)
    assert s.correct({0: float(s.results[1].angles_deg[0]) + 2.0}, refit=False, frame=1)
    r = s.results[1]
    e, per_view = backend.posture_error(s._fitter(), r.angles_deg, s.frame_input(1),
                                        r.root_positions)
    assert r.error == pytest.approx(e) and per_view.size == 0 == r.error_per_view.size
    assert s.save()
    assert read_results(project.parent / RESULTS).view_names == ()
    assert s.messages == []
    s.close()


def test_blank_canvas_from_the_keypoints_without_a_calibrated_size(made, tmp_path, qtbot):
    project, _ = copy_of(made, tmp_path)
    text = project.read_text().replace("[anneal]", '[video]\npath = "elsewhere/cam0.mp4"\n'
                                       "[anneal]")
    project.write_text(text)
    s = open_session(project)
    assert s.messages == []  # a video that is not there is a notice, not an error
    assert s.notice.startswith("video not shown (") and "blank canvas" in s.notice
    assert "blank canvas" in s.notes[0] and len(s.view_images()) == 3
    s.close()
    xy = np.array([[[100.0, 50.0], [np.nan, np.nan]], [[300.0, 200.0], [20.0, 10.0]]])
    w, h = adapters.canvas_size(None, xy)
    assert w >= 301 and h >= 201 and w < 340 and h < 230  # the extent and a margin
    assert adapters.canvas_size((1280, 1024), xy) == (1280, 1024)
    assert adapters.canvas_size(None, np.full((3, 2), np.nan)) == adapters.CANVAS_DEFAULT


def test_with_a_video_per_camera_the_views_are_its_frames(made, tmp_path, qtbot):
    from videotrack.synth.project import VideoSink

    project, truth = copy_of(made, tmp_path)
    for c, cam in enumerate(truth.camera_list):  # grey level 20 * camera + video frame
        w, h = cam.image_size
        with VideoSink(project.parent / f"{cam.name}.avi", 25.0) as sink:
            for f in range(N_FRAMES + 2):
                sink.write(np.full((h, w, 3), 20 * c + f, np.uint8))
            sink.commit()
    # the tracker ran from video frame 2 on: record r is video frame r + 2
    project.write_text(project.read_text().replace(
        "[anneal]", 'frame_offsets = [2]\n[video]\npath = ["cam0.avi", "cam1.avi", '
        '"cam2.avi"]\n[anneal]'))
    s = open_session(project)
    assert s.messages == [] and s.notice == "" and s.canvas is None
    assert s.video_frame(3) == 5 and s.time_of(3) == pytest.approx(5 / 25)
    images = s.view_images(3)
    assert [int(np.median(im)) for im in images] == [5, 25, 45]
    assert images[0].shape[:2] == (1024, 1280)
    np.testing.assert_allclose(s.frame_keypoints(3)[1][:, :2], truth.keypoints[1, 3],
                               atol=1e-3)
    s.close()


def test_a_bad_keypoint_file_is_one_line_and_the_window_opens(made, tmp_path, qtbot):
    project, truth = copy_of(made, tmp_path)
    lines = truth.files[1].read_text().splitlines()
    lines[5] = lines[5].replace(",", ",abc,", 1)
    (project.parent / truth.files[1].name).write_text("\n".join(lines) + "\n")
    s = open_session(project)
    assert len(s.messages) == 1 and "\n" not in s.messages[0]
    assert "cam1DLC.csv" in s.messages[0]
    assert s.view_names == ["cam0", "cam1", "cam2"] and s.n_frames == 0
    assert not s.fit()
    assert s.messages[-1].startswith("no keypoints")
    s.close()
