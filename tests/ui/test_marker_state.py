"""Per-view marker state (issue 15, item 3): removing a ghost, adding or moving a detection
with the mouse in a video view, the edits sidecar, and the per-marker residual table."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt

from kinematics.model.fk import forward_kinematics
from videotrack.detect.edits import edits_path, load_edits


def _click(qtbot, view, x, y, modifier):
    pos = view.mapFromScene(view.scene_pos(x, y))
    qtbot.mouseClick(view.viewport(), Qt.MouseButton.LeftButton, modifier, pos)


def _fitted(window, wait_idle):
    s = window.session
    s.fit([s.frame], "fit frame")
    wait_idle(s)
    window.refresh_frame()


def test_shift_click_removes_a_ghost_and_e_uses_it_at_once(window, qtbot, wait_idle):
    s = window.session
    s.set_frame(4)
    _fitted(window, wait_idle)
    view = window.video_views[1]
    before = s.frame_detections()[1].copy()
    raw = s.detections.points_of(4, 1).copy()
    target = before[0]
    _click(qtbot, view, *target, Qt.KeyboardModifier.ShiftModifier)
    after = s.frame_detections()[1]
    assert len(after) == len(before) - 1
    assert not np.any(np.all(np.isclose(after, target), axis=1))
    np.testing.assert_allclose(view.drawn()["detections"], after)  # drawn at once
    np.testing.assert_array_equal(s.detections.points_of(4, 1), raw)  # the file's stay
    # E of the frame is that of its posture against the edited detections
    r = s.results[4]
    error, per_view = s._fitter().error(r.angles_deg, s.frame_detections(), r.root_positions)
    assert r.error == error and np.array_equal(r.error_per_view, per_view)
    assert s.undo_label.startswith("remove a detection in top")
    s.undo()
    np.testing.assert_array_equal(s.frame_detections()[1], before)
    assert "detection edits" in s.unsaved  # undone, but the file may need rewriting


def test_ctrl_click_adds_a_detection_snapped_to_the_marker(window, qtbot):
    s = window.session
    s.set_frame(2)
    view = window.video_views[0]
    target = s.frame_detections()[0][0].copy()
    s.edit_detection(0, remove=target)  # take a true marker's detection away
    assert len(s.frame_detections()[0]) == len(s.detections.points_of(2, 0)) - 1
    _click(qtbot, view, target[0] + 1.5, target[1] - 1.5, Qt.KeyboardModifier.ControlModifier)
    added = s.frame_detections()[0][-1]
    assert np.hypot(*(added - target)) < 0.5  # the click snapped to the blob's centroid
    assert len(s.frame_detections()[0]) == len(s.detections.points_of(2, 0))


def test_moving_detections_drives_the_fit_and_saves_a_sidecar(window, qtbot, wait_idle,
                                                              project):
    s = window.session
    s.set_frame(5)
    det_file = project.parent / "detections.npz"
    det_bytes = det_file.read_bytes()
    for xy in s.frame_detections()[1].copy():  # no detection left in the top view
        assert s.edit_detection(1, remove=xy)
    moved_from = s.frame_detections()[0][0].copy()
    assert s.edit_detection(0, remove=moved_from, add=(40.0, 30.0))
    assert len(s.frame_detections()[1]) == 0
    assert np.any(np.all(s.frame_detections()[0] == (40.0, 30.0), axis=1))
    _fitted(window, wait_idle)
    assert s.results[5].missing_views == ("top",)  # the fit used the edited detections
    assert s.save()
    assert det_file.read_bytes() == det_bytes  # never the detections file
    side = edits_path(s.results_path)
    edits = load_edits(side, s.view_names)
    assert edits == s.detection_edits and (5, 1) in edits
    window.session.close()
    # reopened, the edits are back and used
    assert window.open_project(project)
    assert len(window.session.frame_detections(5)[1]) == 0


def test_a_bad_sidecar_is_one_line_and_the_rest_opens(window, project):
    s = window.session
    side = edits_path(s.results_path)
    side.write_text("{not json")
    window.errors.clear()
    assert window.open_project(project)
    assert len(window.errors) == 1 and str(side) in window.errors[0]
    assert "\n" not in window.errors[0]
    assert window.session.detection_edits == {}


def test_marker_residual_table_is_the_distance_to_the_nearest_detection(window, wait_idle):
    s = window.session
    s.set_frame(3)
    _fitted(window, wait_idle)
    angles, roots, _ = s.posture()
    pose = forward_kinematics(s.body, angles, roots)
    table = window.marker_table
    assert table.rowCount() == len(s.body.marker_names)
    assert table.columnCount() == len(s.view_names)
    for v, cam in enumerate(s.cameras):
        proj = cam.project(pose.markers)
        dets = s.frame_detections()[v]
        for m in range(len(proj)):
            nearest = np.min(np.hypot(*(dets - proj[m]).T))
            assert table.text(m, v) == f"{nearest:.2f}"
    # they follow a preview (a slider being dragged) too
    angles = angles.copy()
    angles[8] += 20.0
    s.set_preview_angles(angles)
    proj = s.cameras[0].project(forward_kinematics(s.body, angles, roots).markers)
    last = len(proj) - 1
    nearest = np.min(np.hypot(*(s.frame_detections()[0] - proj[last]).T))
    assert table.text(last, 0) == f"{nearest:.2f}"


def _click_marker(qtbot, view, marker):
    x, y = view.marker_xy(marker)
    at = view.mapFromScene(view.scene_pos(x, y))
    qtbot.mouseClick(view.viewport(), Qt.MouseButton.LeftButton, pos=at)


def test_h_hides_the_clicked_marker_in_its_view(window, qtbot, wait_idle, project):
    """H on a clicked model marker marks it hidden in that view: drawn as a cross, "hidden"
    in the residual table, E and the fit leave it out at once, undoable, saved in the
    sidecar and back on reopening."""
    s = window.session
    s.set_frame(4)
    _fitted(window, wait_idle)
    view = window.video_views[1]
    _click_marker(qtbot, view, 3)
    assert window.selected_marker == (1, 3)
    side_before = s.results[4].error_per_view[0]
    qtbot.keyClick(window.table, Qt.Key.Key_H)
    assert s.hidden_in_frame()[1, 3] and s.hidden_in_frame().sum() == 1
    assert view.drawn()["hidden"].tolist() == [False, False, False, True]
    assert window.marker_table.text(3, 1) == "hidden"
    assert window.marker_table.text(3, 0) != "hidden"
    assert s.undo_label == "hide M3 in top, frame 4"
    r = s.results[4]
    dets = s.frame_detections(4)
    hidden = np.zeros((2, 4), bool)
    hidden[1, 3] = True
    assert r.error == s._fitter().error(r.angles_deg, dets, r.root_positions, hidden)[0]
    assert r.error_per_view[0] == pytest.approx(side_before, abs=1e-9)  # as it was
    # M3's detection in top is now explained by no marker: the bounded term's 3 px
    assert r.error_per_view[1] == pytest.approx(3.0, abs=0.1)
    _fitted(window, wait_idle)  # the fit takes the mark: no residual for M3 in top
    assert np.isnan(s.results[4].marker_residuals[1, 3])
    assert np.isfinite(s.results[4].marker_residuals[0, 3])
    assert s.save()
    side = load_edits(edits_path(s.results_path), s.view_names)
    assert side[(4, 1)].hidden == ("M3",)
    s.close()
    assert window.open_project(project)
    assert window.session.hidden_in_frame(4)[1, 3]
    s = window.session
    s.set_frame(4)
    window.refresh_frame()
    _click_marker(qtbot, window.video_views[1], 3)
    qtbot.keyClick(window.table, Qt.Key.Key_H)  # H again: seen again
    assert not s.hidden_in_frame().any()
    s.undo()
    assert s.hidden_in_frame()[1, 3]


def test_h_over_a_table_selection_hides_the_marker_in_every_selected_frame(window, qtbot):
    s = window.session
    table = window.table
    s.set_frame(2)

    def click(frame, modifier=Qt.KeyboardModifier.NoModifier):
        rect = table.visualRect(table.model().index(table.row_of(frame), 0))
        qtbot.mouseClick(table.viewport(), Qt.MouseButton.LeftButton, modifier, rect.center())

    click(2)
    click(6, Qt.KeyboardModifier.ShiftModifier)
    assert table.selected_frames() == [2, 3, 4, 5, 6]
    _click_marker(qtbot, window.video_views[0], 2)
    window.act_hide_marker.trigger()
    assert [bool(s.hidden_in_frame(f)[0, 2]) for f in range(1, 8)] == [
        False, True, True, True, True, True, False]
    assert s.undo_label == "hide M2 in side, frames 2–6"
    s.undo()
    assert not any(s.hidden_in_frame(f).any() for f in range(12))


def test_h_without_a_clicked_marker_says_what_to_do(window):
    notes = []
    window.session.status.connect(notes.append)
    window.act_hide_marker.trigger()
    assert notes[-1].startswith("click a model marker") and not window.session.can_undo


def test_hidden_marks_follow_the_chain(window):
    from dataclasses import replace

    s = window.session
    assert s.toggle_hidden(1, 3, [4])
    marked = s.fit_detections
    assert marked.hidden[4, 1, 3] and marked.hidden.sum() == 1
    assert s.commit_body(replace(s.body, name="renamed"))
    assert s.fit_detections is not marked  # the marks are made again for the new chain
    assert s.fit_detections.hidden[4, 1, 3]


def test_each_marker_draws_its_residual_to_the_point_it_is_measured_to(window, wait_idle,
                                                                      qtbot):
    """XMALab-style residual lines: from each model marker to its nearest detection in the
    view, as long as the table's residual; none for a marker hidden there."""
    s = window.session
    s.set_frame(3)
    _fitted(window, wait_idle)
    for v, view in enumerate(window.video_views):
        drawn = view.drawn()
        pairs = drawn["residuals"].reshape(-1, 2, 2)
        assert len(pairs) == len(s.body.marker_names)
        np.testing.assert_allclose(pairs[:, 0], drawn["markers"])
        dets = s.frame_detections()[v]
        for m, (a, b) in enumerate(pairs):
            assert np.any(np.all(dets == b, axis=1))  # a detection ...
            length = np.hypot(*(b - a))
            assert window.marker_table.text(m, v) == f"{length:.2f}"  # ... the table's
    _click_marker(qtbot, window.video_views[1], 3)
    qtbot.keyClick(window.table, Qt.Key.Key_H)
    assert len(window.video_views[1].drawn()["residuals"]) == 2 * 3  # M3's is gone there
    assert len(window.video_views[0].drawn()["residuals"]) == 2 * 4
