"""The main window and its dialogs, offscreen or on a real display: what the items draw is
checked against the model's projection, the table against the results, dialogs against the
session's state."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt
from PySide6.QtGui import QImage
from PySide6.QtWidgets import QMessageBox

from kinematics.model.fk import forward_kinematics
from ui import adapters
from ui.views import style
from videotrack.detect.detections import load_detections


def expected_markers(session, body=None, angles=None):
    """The model markers of the current frame projected by each camera (the oracle)."""
    a, roots, _ = session.posture()
    pose = forward_kinematics(body or session.body, a if angles is None else angles, roots)
    return [cam.project(pose.markers) for cam in session.cameras], [
        cam.project(np.concatenate([pose.joints, pose.segment_ends])) for cam in session.cameras]


def assert_drawn_is_model(window, body=None):
    s = window.session
    markers, points = expected_markers(s, body)
    for k, view in enumerate(window.video_views):
        drawn = view.drawn()
        np.testing.assert_allclose(drawn["markers"], markers[k], atol=1e-9)
        edges = adapters.skeleton(body or s.body).edges
        np.testing.assert_allclose(drawn["lines"], points[k][edges.ravel()], atol=1e-9)
        np.testing.assert_allclose(drawn["detections"], s.frame_detections()[k])


def assert_gl_draws_markers(posture_view, qtbot):
    """The OpenGL view's picture has pixels of the marker colour (it renders, not only
    holds data)."""
    import pyqtgraph as pg

    image = posture_view.gl_view.grabFramebuffer().convertToFormat(
        QImage.Format.Format_RGB888)
    rgb = np.frombuffer(image.constBits(), np.uint8).reshape(
        image.height(), image.bytesPerLine())[:, :3 * image.width()].reshape(
        image.height(), image.width(), 3)
    colour = np.array(pg.mkColor(style.MARKER).getRgb()[:3])
    assert (np.abs(rgb.astype(int) - colour).max(axis=2) < 40).sum() > 20


def test_layout_and_overlays_follow_the_frames(window, qtbot, project):
    s = window.session
    assert [v.name for v in window.video_views] == ["side", "top"]
    assert window.table.model().rowCount() == 12
    assert window.windowTitle() == "VideoTrack — project.toml"
    det = load_detections(project.parent / "detections.npz")
    for frame in (0, 1, 2):
        if frame:
            window.act_next.trigger()
        assert s.frame == frame and window.slider.value() == frame
        assert window.timeline.frame_line_value == frame
        assert_drawn_is_model(window)
        np.testing.assert_allclose(window.video_views[1].drawn()["detections"],
                                   det.points_of(frame, 1))
        image = window.video_views[0].image.image
        np.testing.assert_array_equal(image, s.view_images()[0][..., ::-1])
    markers = s.geometry().markers
    if window.posture_view.opengl:
        # a real display: the 3D scene holds the posture and really draws it
        np.testing.assert_allclose(window.posture_view.gl_markers_world(), markers)
        assert_gl_draws_markers(window.posture_view, qtbot)
    else:
        # the 3D fallback shows the same posture: side (x, y), top (x, z), front (z, y)
        side, top, front = window.posture_view.projections()
        np.testing.assert_allclose(side, markers[:, [0, 1]])
        np.testing.assert_allclose(top, markers[:, [0, 2]])
        np.testing.assert_allclose(front, markers[:, [2, 1]])
    window.frame_box.setValue(9)
    assert s.frame == 9
    window.act_prev.trigger()
    assert s.frame == 8


def test_background_fit_updates_table_timeline_and_views(window, qtbot, wait_idle):
    s = window.session
    s.set_frame(6)
    window.act_fit_all.trigger()
    assert window.progress.isVisible() or not s.busy
    assert not window.act_fit_all.isEnabled() or not s.busy
    wait_idle(s)
    qtbot.waitUntil(lambda: not window._timeline_timer.isActive())
    model = window.table.source
    for f in range(12):
        r = s.results[f]
        assert model.value(f, 1) == r.error
        assert model.value(f, 6) == r.status
        assert model.value(f, 5) == pytest.approx(float(np.max(r.sd_deg)))  # its largest sd
    _x, y = window.timeline.error_curve.getData()
    np.testing.assert_array_equal(y, [s.results[f].error for f in range(12)])
    assert_drawn_is_model(window)  # frame 6 is now drawn in its fitted posture
    assert s.posture()[2] == "fit"
    assert "12 of 12 frames fitted" in window.summary.text()
    assert window.act_undo.isEnabled() and window.act_undo.text() == "&Undo fit all (12 frames)"


def test_table_highlights_sorts_and_jumps(window, qtbot, wait_idle):
    from kinematics.fit import AnnealParams

    s = window.session
    s.set_params(AnnealParams.paper())  # errors of a few px, a threshold among them
    s.fit()
    wait_idle(s)
    errors = np.array([s.results[f].error for f in range(12)])
    threshold = float(np.median(errors))
    window.threshold.setValue(threshold)
    assert s.threshold == pytest.approx(round(threshold, 1))
    bad = [f for f in range(12) if errors[f] > s.threshold]
    model = window.table.source
    assert model.highlighted_rows() == bad
    for f in range(12):
        colour = model.data(model.index(f, 0), Qt.ItemDataRole.BackgroundRole)
        assert (colour == style.BAD_ROW) == (f in bad)
    assert window.timeline.bad.getData()[0].tolist() == bad
    table = window.table
    table.sortByColumn(1, Qt.SortOrder.DescendingOrder)
    worst = int(np.argmax(errors))
    assert table.frame_at(0) == worst
    rect = table.visualRect(table.model().index(0, 0))
    qtbot.mouseClick(table.viewport(), Qt.MouseButton.LeftButton, pos=rect.center())
    assert s.frame == worst
    s.set_frame(0)
    window.act_next_bad.trigger()
    assert s.frame == next(f for f in bad if f > 0)


def test_cancel_from_the_window(window, qtbot, wait_idle, monkeypatch):
    from kinematics.fit import AnnealParams
    from ui.state import backend

    monkeypatch.setattr(backend, "fit_chunk_size", lambda: 2)  # whatever the core count
    s = window.session
    s.set_params(AnnealParams.paper(epsilon=0.0, max_runs=1).with_schedule(400_000))
    s.resultsChanged.connect(lambda *_: window.cancel_button.click())
    window.act_fit_all.trigger()
    assert window.cancel_button.isVisible()
    wait_idle(s, timeout=60000)
    assert 0 < len(s.results) < 12
    assert not window.cancel_button.isVisible()
    assert window.statusBar().currentMessage().startswith("cancelled after")


def test_window_stays_responsive_while_fitting(window, qtbot, monkeypatch, wait_idle):
    import time

    from PySide6.QtCore import QTimer

    from kinematics.fit import AnnealParams
    from ui.state import backend

    monkeypatch.setattr(backend, "fit_chunk_size", lambda: 2)
    s = window.session
    # first a short fit of the same kind: kernels numba compiles (holding the GIL, in a cold
    # cache) are compiled before the timed fit, whose gaps would otherwise be the compiler's
    s.set_params(AnnealParams.paper(epsilon=0.0, max_runs=1).with_schedule(2000))
    window.act_fit_all.trigger()
    wait_idle(s)
    # long enough (seconds) that a blocked event loop would show as one long gap
    s.set_params(AnnealParams.paper(epsilon=0.0, max_runs=1).with_schedule(2_000_000))
    ticks = []
    timer = QTimer()
    timer.timeout.connect(lambda: ticks.append(time.perf_counter()))
    timer.start(10)
    arrived = []
    s.resultsChanged.connect(lambda frames: arrived.append(len(s.results)))
    window.act_fit_all.trigger()
    while s.busy:  # the user steps through frames while the fit runs
        window.act_next.trigger()
        qtbot.wait(20)
    timer.stop()
    assert len(s.results) == 12 and len(arrived) > 1  # results came in several batches
    gaps = np.diff(ticks)
    busy = ticks[-1] - ticks[0]
    assert len(ticks) > 10 and gaps.max() < min(1.0, busy / 2), (gaps.max(), busy)
    assert s.frame == 11


def test_chain_editor_length_edit_reprojects_and_commits(window, qtbot):
    s = window.session
    s.set_frame(3)
    before = window.video_views[0].drawn()["markers"].copy()
    editor = window.open_chain_editor()
    editor.select("segment", "femur")
    assert editor.seg_length.value() == 91.0
    editor.seg_length.setValue(120.0)
    edited = adapters.edit_segment(s.body, "femur", length=120.0)
    assert_drawn_is_model(window, body=edited)  # drawn at once, before OK
    after = window.video_views[0].drawn()["markers"]
    assert np.linalg.norm(after[3] - before[3]) > 5
    assert s.body is editor.original  # nothing committed yet
    # an invalid value is reported and not drawn
    editor.select("axis", "gamma")
    editor.axis_min.setValue(170.0)
    assert "min 170 is greater than max 160" in editor.message.text()
    assert not editor.buttons.button(editor.buttons.StandardButton.Ok).isEnabled()
    editor.axis_min.setValue(20.0)
    editor.accept()
    femur = adapters.find_element(s.body, "segment", "femur")
    assert femur.length == 120.0 and s.preview_body is None
    assert_drawn_is_model(window)
    assert s.unsaved == ["chain"] and s.undo_label == "edit chain"
    window.act_undo.trigger()
    assert adapters.find_element(s.body, "segment", "femur").length == 91.0
    np.testing.assert_allclose(window.video_views[0].drawn()["markers"], before)


def test_chain_editor_sliders_preview_and_cancel(window, tmp_path):
    from kinematics.model.chain_xml import load_body

    s = window.session
    before = window.video_views[1].drawn()["markers"].copy()
    editor = window.open_chain_editor()
    editor.sliders.rows[8][2].setValue(150.0)  # gamma's number box
    angles = s.posture()[0]
    assert s.posture()[2] == "preview" and angles[8] == 150.0
    assert_drawn_is_model(window)
    editor.select("marker", "M3")
    editor.marker_offset.boxes[0].setValue(-20.0)
    assert s.save_chain_as(tmp_path / "edited.xml", editor.body)
    assert load_body(tmp_path / "edited.xml").marker_names == s.body.marker_names
    editor.reject()
    assert s.preview_body is None and s.preview_angles is None
    np.testing.assert_allclose(window.video_views[1].drawn()["markers"], before)
    assert not s.dirty


def test_chain_editor_root_mode_marker_and_windows(window):
    s = window.session
    editor = window.open_chain_editor()
    ok = editor.buttons.button(editor.buttons.StandardButton.Ok)
    editor.select("chain", "hindleg")
    assert editor.root_mode.currentText() == "fixed" and not editor.root_twin.isEnabled()
    assert [editor.root_marker.itemText(i) for i in range(editor.root_marker.count())] == [
        "(none)", "M0", "M1", "M2", "M3"]
    # a marker root without a marker is reported, not applied
    editor.root_mode.setCurrentText("marker")
    assert "a marker root follows a root marker" in editor.message.text()
    assert not ok.isEnabled() and editor.body.chains[0].root.mode == "fixed"
    editor.root_marker.setCurrentText("M0")
    assert editor.message.text() == "✓ valid chain" and ok.isEnabled()
    assert editor.tree.currentItem().text(1) == "root marker M0"
    # free: the windows are enabled, empty shows the default from the body's size
    editor.root_mode.setCurrentText("free")
    assert editor.root_twin.isEnabled() and editor.root_rwin.isEnabled()
    w_t, w_r = adapters.default_root_windows(editor.body, "hindleg")
    assert editor.root_twin.placeholderText() == f"default {w_t:.4g} px"
    assert editor.root_rwin.placeholderText() == f"default {w_r:.4g}°"
    assert "(M0, M1)" in editor.root_note.text()
    editor.root_twin.setText("abc")
    assert "translation window must be a number > 0" in editor.message.text()
    assert not ok.isEnabled()
    editor.root_twin.setText("0")
    assert "translation_window must be a number > 0, got 0" in editor.message.text()
    editor.root_twin.setText("4")
    editor.root_rwin.setText("30")
    assert ok.isEnabled()
    root = editor.body.chains[0].root
    assert (root.mode, root.marker, root.translation_window, root.rotation_window_deg) == (
        "free", "M0", 4.0, 30.0)
    assert_drawn_is_model(window, body=editor.body)
    # a free root cannot have a locked root axis: the axis page says so
    editor.select("axis", "psi")
    editor.axis_locked.setChecked(True)
    assert "a free root turns about all three axes" in editor.message.text()
    assert not ok.isEnabled()
    editor.axis_locked.setChecked(False)
    assert ok.isEnabled()
    # selecting the chain again shows what was set
    editor.select("chain", "hindleg")
    assert (editor.root_mode.currentText(), editor.root_marker.currentText(),
            editor.root_twin.text(), editor.root_rwin.text()) == ("free", "M0", "4", "30")
    editor.accept()
    assert s.body.chains[0].root.mode == "free" and s.undo_label == "edit chain"
    window.act_undo.trigger()
    assert s.body.chains[0].root.mode == "fixed"


def test_manual_correction_with_sliders_and_undo(window, qtbot, wait_idle):
    s = window.session
    s.fit()
    wait_idle(s)
    s.set_frame(7)
    old = s.results[7]
    panel = window.correction
    panel.sliders.rows[5][2].setValue(40.0)  # J1.beta, typed: preview and commit
    wait_idle(s)
    r = s.results[7]
    assert r.status == "corrected" and r.angles_deg[5] == 40.0
    assert_drawn_is_model(window)
    model = window.table.source
    assert model.value(7, 6) == "corrected"
    assert model.data(model.index(7, 0), Qt.ItemDataRole.BackgroundRole) == style.CORRECTED_ROW
    assert panel.sliders.rows[5][0].font().bold()  # the pinned axis is marked
    assert "1 axes pinned" in panel.source.text()
    window.act_undo.trigger()
    assert s.results[7] is old and model.value(7, 6) == old.status
    assert not panel.sliders.rows[5][0].font().bold()
    window.act_redo.trigger()
    assert s.results[7].status == "corrected"


def test_drag_a_marker_in_a_video_view(window, qtbot, wait_idle):
    s = window.session
    s.set_frame(1)
    angles, roots, _ = s.posture()
    angles[8] -= 30.0
    target = s.cameras[1].project(forward_kinematics(s.body, angles, roots).markers[3])
    view = window.video_views[1]
    view.markers.dragged.emit(3, float(target[0]), float(target[1]))
    wait_idle(s)
    assert s.results[1].status == "corrected"
    drawn = view.drawn()["markers"][3]
    assert np.linalg.norm(drawn - target) < 1.0
    assert s.undo_label == "drag M3 in top"


def test_histogram_dialog_bars_and_learning(window, qtbot, wait_idle, tmp_path):
    from kinematics.model.histogram_xml import load_archive

    s = window.session
    s.fit()
    wait_idle(s)
    s.set_frame(2)
    dialog = window.open_histograms()
    dialog.axes.setCurrentRow(8)  # J2.gamma
    hist = s.body.axis_refs()[8].axis.histogram
    x, h = dialog.bar_data()
    bars = adapters.histogram_bars(hist, s.results[2].angles_deg[8])
    np.testing.assert_array_equal(x, bars.centres)
    np.testing.assert_array_equal(h, bars.heights)
    assert dialog.current.value() == pytest.approx(s.results[2].angles_deg[8])
    dialog.learn()
    learned = s.body.axis_refs()[8].axis.histogram
    assert learned.n_trials > hist.n_trials
    np.testing.assert_array_equal(dialog.bar_data()[1], adapters.histogram_bars(learned).heights)
    assert f"N = {learned.n_trials}" in dialog.info.text()
    s.export_histograms(tmp_path / "h.xml")
    assert load_archive(tmp_path / "h.xml")[("hindleg", "J2", "gamma")] == learned
    s.set_frame(5)
    assert dialog.current.value() == pytest.approx(s.results[5].angles_deg[8])
    dialog.close()


def test_project_dialog_live_preview_and_apply(window, qtbot, project):
    s = window.session
    dialog = window.open_project_dialog()
    dialog.wait_preview()
    det = s.frame_detections()
    for v, view in enumerate(dialog.preview_result):
        np.testing.assert_allclose(view.points, det[v])
        assert view.mask.any()
    dialog.set_step_value(0, "value", 250)  # brighter than any marker: nothing is left
    dialog.wait_preview()
    assert all(len(v.points) == 0 and not v.mask.any() for v in dialog.preview_result)
    assert "side: 0" in dialog.preview_label.text()
    # views: editing a cell moves the rectangle on the frame
    dialog.view_table.item(1, 3).setText("300")
    assert dialog.rois[1].size()[0] == 300
    assert dialog.view_tables()[1]["roi"] == [360, 0, 300, 288]
    dialog.view_table.item(1, 3).setText("360")
    dialog.accept()
    assert s.settings.filters.steps[0]["value"] == 250
    assert s.unsaved == ["config"] and window.windowTitle().endswith("*")


def test_project_dialog_rejects_invalid_settings(window):
    dialog = window.open_project_dialog()
    dialog.view_table.item(0, 3).setText("9999")  # wider than the frame
    dialog.wait_preview()
    assert "reaches outside" in dialog.message.text()
    dialog.accept()  # refused: the dialog stays open, nothing applied
    assert dialog.isVisible() and not window.session.dirty
    dialog.reject()


def test_errors_show_as_dialogs_and_close_asks(window, qtbot, monkeypatch):
    s = window.session
    s.error.emit("file.toml:3: views[0].roi: bad")
    assert window.errors[-1] == "file.toml:3: views[0].roi: bad"
    boxes = [w for w in window.findChildren(QMessageBox) if w.isVisible()]
    assert boxes and boxes[-1].text() == "file.toml:3: views[0].roi: bad"
    s.correct({0: 190.0}, refit=False)
    assert s.dirty and window.windowTitle().endswith("*")
    window.ask_unsaved = lambda: QMessageBox.StandardButton.Cancel
    assert not window.close() and window.isVisible()
    saved = []
    monkeypatch.setattr(s, "save", lambda: saved.append(1) or True)
    window.ask_unsaved = lambda: QMessageBox.StandardButton.Save
    assert window.close() and saved == [1]


def test_playback_advances_and_stops_at_the_end(window, qtbot):
    s = window.session
    s.set_frame(9)
    window.toggle_play()
    assert window.playing
    qtbot.waitUntil(lambda: s.frame == 11 and not window.playing, timeout=5000)


def test_timeline_line_moves_the_frame(window):
    s = window.session
    line = window.timeline.lines[0]
    line.setValue(5.3)
    line.sigDragged.emit(line)
    assert s.frame == 5 and window.timeline.frame_line_value == 5


def test_project_dialog_writes_only_changed_annealing_keys(window):
    dialog = window.open_project_dialog()
    raw = dialog.edited_raw()
    assert raw["anneal"] == {"n_end": 3000, "n_l": 300, "n_tau": 130}
    assert raw["chain"] == {"path": "chain.xml"} and raw["cameras"] == {"path": "cameras.toml"}
    dialog.anneal_form.widgets["seed"].setValue(7)
    assert dialog.edited_raw()["anneal"]["seed"] == 7
    dialog.accept()
    assert window.session.params.seed == 7


def test_bar_is_the_threshold_the_fit_measured_until_the_user_sets_one(window, qtbot,
                                                                       wait_idle):
    s = window.session
    assert s.params.threshold_mode == "auto"
    project = s.threshold
    s.fit([3, 4])  # before any Fit all: decided by the project's threshold, bar unmoved
    wait_idle(s)
    assert s.results[3].threshold == project and s.threshold == project
    s.fit()
    wait_idle(s)
    measured = s.results[0].threshold
    assert np.isfinite(measured) and measured != s.params.reanalysis_threshold
    assert s.threshold == measured  # the bar the fit's statuses were decided by
    assert window.threshold.value() == pytest.approx(measured, abs=0.06)
    failed = {f for f, r in s.results.items() if r.status == "failed"}
    assert failed <= {f for f, r in s.results.items() if r.error > s.threshold}
    # fits of some frames, re-fits and corrections keep the bar and are decided by it
    # (they measured their own on those few frames: it moved the bar, and every frame
    # after a re-fit forward was flagged)
    s.fit([3, 4])
    wait_idle(s)
    assert s.threshold == measured and s.results[3].threshold == measured
    s.set_frame(3)
    assert s.refit_from(1)
    wait_idle(s)
    assert s.results[5].threshold == measured and s.threshold == measured
    assert s.correct({0: float(s.results[8].angles_deg[0]) + 1.0}, frame=8)
    wait_idle(s)
    assert s.results[8].status == "corrected" and s.threshold == measured
    window.threshold.setValue(measured + 5.0)  # the user's bar stays after another fit
    s.fit()
    wait_idle(s)
    assert s.threshold == pytest.approx(round(measured + 5.0, 1))
    s.fit([2])  # and decides a fit of some frames
    wait_idle(s)
    assert s.results[2].threshold == pytest.approx(round(measured + 5.0, 1))


def test_an_ambiguous_frame_shows_the_posture_a_swaps_to(window, wait_idle):
    """The other candidate of an ambiguous frame is drawn dashed in every view, so the user
    sees whether A helps before pressing it; gone once the frame is decided. The summary
    counts the frames left to check."""
    from dataclasses import replace

    from kinematics.fit import Candidate

    s = window.session
    s.fit([3])
    wait_idle(s)
    s.set_frame(3)
    assert all(len(v.drawn()["alternative"]) == 0 for v in window.video_views)
    fitted = s.results[3]
    mirror = fitted.angles_deg.copy()
    mirror[8] = -mirror[8]  # femur-tibia angle mirrored
    s.set_results([replace(fitted, status="ambiguous", candidates=(
        Candidate(fitted.angles_deg, fitted.root_positions, fitted.error, None, None, None),
        Candidate(mirror, fitted.root_positions, fitted.error + 0.1, None, None, None)))],
        "ambiguous")
    expected, _ = expected_markers(s, angles=mirror)
    for k, view in enumerate(window.video_views):
        np.testing.assert_allclose(view.drawn()["alternative"], expected[k], atol=1e-9)
    window.refresh_timeline()
    assert window.summary.text().endswith("· 1 to check")
    window.act_swap.trigger()  # A: the frame is decided (corrected), nothing else drawn
    assert s.results[3].status == "corrected"
    for k, view in enumerate(window.video_views):
        assert len(view.drawn()["alternative"]) == 0
        np.testing.assert_allclose(view.drawn()["markers"], expected[k], atol=1e-9)
    window.refresh_timeline()
    assert window.summary.text().endswith("· 0 to check")
