"""Regression tests of the bugs listed in issue 15 ("Why → Bugs"), on the real widgets."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QEvent, Qt
from PySide6.QtWidgets import QApplication, QPushButton

from ui import adapters


def _delete_later_now() -> None:
    QApplication.sendPostedEvents(None, QEvent.Type.DeferredDelete)
    QApplication.processEvents()


def test_closed_histogram_dialog_leaves_frame_steps_alone(window, qtbot):
    s = window.session
    for how in ("close", "reject"):  # the Close button and Esc
        dialog = window.open_histograms()
        dialog.axes.setCurrentRow(8)
        getattr(dialog, how)()
        _delete_later_now()
        with qtbot.captureExceptions() as caught:
            window.act_next.trigger()
            s.set_frame(s.frame + 1)
            window.refresh_overlays()
        assert caught == []
    # an open dialog still follows the frame
    dialog = window.open_histograms()
    dialog.axes.setCurrentRow(8)
    s.set_frame(4)
    assert f"current frame {s.frame}:" in dialog.info.text()
    dialog.close()


def test_wheel_over_unfocused_correction_sliders_changes_nothing(window, qtbot, wheel):
    s = window.session
    window.table.setFocus()
    for _label, slider, box in window.correction.sliders.rows.values():
        before = (slider.value(), box.value())
        for w in (slider, box):
            assert not w.hasFocus()
            wheel(w)
            wheel(w, -240)
        assert (slider.value(), box.value()) == before
    assert not s.busy and not s.can_undo and not s.dirty
    # a focused slider still takes the wheel
    _label, slider, _box = next(iter(window.correction.sliders.rows.values()))
    slider.setFocus()
    qtbot.waitUntil(slider.hasFocus)
    before = slider.value()
    wheel(slider)
    assert slider.value() != before


def test_table_selection_follows_arrow_keys_and_f7_fits_it(window, qtbot, wait_idle):
    s = window.session
    table = window.table

    def click(frame, modifier=Qt.KeyboardModifier.NoModifier):
        rect = table.visualRect(table.model().index(table.row_of(frame), 0))
        qtbot.mouseClick(table.viewport(), Qt.MouseButton.LeftButton, modifier, rect.center())

    # a Ctrl-click multi-selection is kept while the current frame is in it
    click(2)
    click(5, Qt.KeyboardModifier.ControlModifier)
    assert s.frame == 5 and table.selected_frames() == [2, 5]
    # → steps the frame: the highlight moves with it (the old rows are not left selected)
    changed = []
    table.selectionModel().selectionChanged.connect(lambda *_: changed.append(1))
    qtbot.keyClick(window, Qt.Key.Key_Right)
    assert s.frame == 6 and table.selected_frames() == [6] and changed
    assert table.currentIndex().row() == table.row_of(6)
    # Up/Down in the table move the current frame along with the highlighted row
    table.setFocus()
    qtbot.waitUntil(table.hasFocus)
    qtbot.keyClick(table, Qt.Key.Key_Down)
    assert table.selected_frames() == [7] and s.frame == 7
    qtbot.keyClick(table, Qt.Key.Key_Up)
    qtbot.keyClick(table, Qt.Key.Key_Up)
    assert table.selected_frames() == [5] and s.frame == 5
    # F7 fits the highlighted frame, which is the current one
    window.act_fit_selected.trigger()
    wait_idle(s)
    assert sorted(s.results) == [5]


def test_enter_in_the_chain_editor_commits_the_field_and_keeps_it_open(window, qtbot):
    s = window.session
    editor = window.open_chain_editor()
    editor.select("segment", "femur")
    box = editor.seg_length
    box.setFocus()
    qtbot.waitUntil(box.hasFocus)
    box.lineEdit().selectAll()
    qtbot.keyClicks(box.lineEdit(), "120")
    assert box.value() == 91.0  # not committed while typing
    qtbot.keyClick(box.lineEdit(), Qt.Key.Key_Return)
    assert editor.isVisible() and editor.result() == 0
    assert box.value() == 120.0
    assert adapters.find_element(editor.body, "segment", "femur").length == 120.0
    assert s.body is editor.original  # nothing applied to the project yet
    qtbot.keyClick(editor.tree, Qt.Key.Key_Enter)  # Enter elsewhere neither
    assert editor.isVisible()
    editor.buttons.button(editor.buttons.StandardButton.Ok).click()
    assert not editor.isVisible()
    assert adapters.find_element(s.body, "segment", "femur").length == 120.0


def test_settings_ok_keeps_the_threshold_and_the_view(window, qtbot):
    s = window.session
    filed = s.threshold
    window.threshold.setValue(filed + 3.5)
    view = window.video_views[0]
    view.plot.setRange(xRange=(40, 90), yRange=(30, 70), padding=0)
    zoom = view.plot.viewRange()
    dialog = window.open_project_dialog()
    dialog.accept()  # nothing about the threshold or the views changed
    assert not dialog.isVisible()
    assert s.threshold == filed + 3.5 and window.threshold.value() == filed + 3.5
    assert window.video_views[0] is view
    assert view.plot.viewRange() == zoom
    # a threshold changed in the dialog is applied
    dialog = window.open_project_dialog()
    dialog.anneal_form.widgets["reanalysis_threshold"].setValue(filed + 1.0)
    dialog.accept()
    assert s.threshold == filed + 1.0 and window.threshold.value() == filed + 1.0


def test_learning_within_the_threshold_uses_the_current_threshold(window, wait_idle):
    s = window.session
    s.fit()
    wait_idle(s)
    errors = np.array([s.results[f].error for f in range(12)])
    stored_good = sum(r.status in adapters.GOOD_STATUSES for r in s.results.values())
    # stricter than the fit's (as the window's threshold box does, finer than its 0.1 px)
    s.set_bar(float(np.median(errors)))
    within = int(np.sum(errors <= s.threshold))
    assert 0 < within != stored_good
    dialog = window.open_histograms()
    assert dialog.good_only.isChecked()
    n0 = s.body.axis_refs()[0].axis.histogram.n_trials
    next(b for b in dialog.findChildren(QPushButton) if b.text().startswith("Learn")).click()
    assert s.body.axis_refs()[0].axis.histogram.n_trials == n0 + within
    dialog.close()


def test_errors_after_a_chain_edit_are_flagged_until_refitted(window, wait_idle):
    s = window.session
    s.fit()
    wait_idle(s)
    s.set_frame(3)
    assert not window.stale_label.isVisible()
    editor = window.open_chain_editor()
    editor.select("segment", "femur")
    editor.seg_length.setValue(95.0)  # (a chain that still fits: 120 is refused)
    editor.buttons.button(editor.buttons.StandardButton.Ok).click()
    assert window.stale_label.isVisible()
    assert "errors of 12 frames are of the previous chain" in window.stale_label.text()
    assert "(previous chain)" in window.video_views[0].info.textItem.toPlainText()
    window.act_undo.trigger()  # the old chain again: its errors are current
    assert not window.stale_label.isVisible()
    window.act_redo.trigger()
    assert window.stale_label.isVisible()
    s.fit([3, 4], "fit")
    wait_idle(s)
    assert "errors of 10 frames" in window.stale_label.text()
    assert "(previous chain)" not in window.video_views[0].info.textItem.toPlainText()
    window.act_fit_all.trigger()
    wait_idle(s)
    assert not window.stale_label.isVisible() and not s.stale
    s.learn_histograms()  # histograms do not change the projection
    assert not window.stale_label.isVisible()
