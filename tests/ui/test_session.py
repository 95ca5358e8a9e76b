"""The session: opening a project, frames, background fits and cancelling, corrections with
undo/redo, histograms, saving and reopening."""

from __future__ import annotations

import tomllib
from dataclasses import replace

import numpy as np
import pytest
import tomli_w

from kinematics.fit import AnnealParams, Fitter
from kinematics.model.fk import forward_kinematics
from kinematics.model.histogram_xml import archive_from_body, load_archive
from ui.state import Session
from videotrack.detect.detections import load_detections
from videotrack.detect.video import open_videos
from videotrack.results.files import read_results


def test_open_project_loads_everything(session, project):
    s = session
    assert s.messages == []
    assert s.n_frames == 12 and s.view_names == ["side", "top"]
    assert s.body.name == "locust-hindleg" and len(s.cameras) == 2
    assert s.params.n_end == 3000 and s.threshold == 10.0
    assert s.detections is not None and s.results == {}
    # unfitted frames are drawn in the start posture of Sect. 3.1 (histogram means)
    angles, roots, source = s.posture()
    assert source == "start"
    np.testing.assert_allclose(angles, s.body.mean_posture_deg())
    markers = forward_kinematics(s.body, angles, roots).markers
    for cam, ov in zip(s.cameras, s.overlays(), strict=True):
        np.testing.assert_allclose(ov.markers, cam.project(markers))


def test_frames_images_and_detections(session, project, qtbot):
    s = session
    det = load_detections(project.parent / "detections.npz")
    with qtbot.waitSignal(s.frameChanged) as sig:
        s.set_frame(7)
    assert sig.args == [7] and s.frame == 7
    s.step(100)
    assert s.frame == 11  # clipped to the last record
    s.step(-20)
    assert s.frame == 0
    with open_videos(project.parent / "video.avi", colour=True) as videos:
        frame = videos.read(4)[0]
    images = s.view_images(4)
    np.testing.assert_array_equal(images[0], frame[:288, :360])
    np.testing.assert_array_equal(images[1], frame[:288, 360:])
    for v in range(2):
        np.testing.assert_array_equal(s.frame_detections(4)[v], det.points_of(4, v))


def test_background_fit_to_completion_then_undo_redo(session, qtbot, wait_idle):
    s = session
    changed = []
    s.resultsChanged.connect(changed.extend)
    progress = []
    s.progress.connect(lambda *a: progress.append(a))
    with qtbot.waitSignal(s.busyChanged):
        assert s.fit()
    assert s.busy and not s.can_undo
    wait_idle(s)
    assert sorted(s.results) == list(range(12)) and sorted(set(changed)) == list(range(12))
    assert {r.status for r in s.results.values()} <= {"ok", "reanalysed", "ambiguous", "failed"}
    assert progress[-1][:2] == (12, 12) and progress[-1][2] > 0
    assert s.dirty and s.unsaved == ["results"]
    # the stored result is the fitter's: a single frame replays bit-identically
    fitter = Fitter(s.body, s.model.cameras, s.params)
    again = fitter.fit_frame(s.frame_detections(3), 3)
    np.testing.assert_array_equal(again.angles_deg, s.results[3].angles_deg)
    assert s.posture(3)[2] == "fit"
    assert s.undo_label == "fit (12 frames)"
    s.undo()
    assert s.results == {}
    s.redo()
    assert len(s.results) == 12


def test_cancel_a_fit_midway_keeps_what_arrived(session, qtbot, wait_idle, monkeypatch):
    from ui.state import backend

    monkeypatch.setattr(backend, "fit_chunk_size", lambda: 2)  # whatever the core count
    s = session
    # a long schedule without early stop: each batch of frames takes a noticeable time
    s.set_params(AnnealParams.paper(epsilon=0.0, max_runs=1).with_schedule(400_000))
    s.resultsChanged.connect(lambda frames: s.cancel())
    statuses = []
    s.status.connect(statuses.append)
    assert s.fit()
    wait_idle(s, timeout=60000)
    assert 0 < len(s.results) < 12
    assert statuses[-1] == f"cancelled after {len(s.results)} frames"
    assert sorted(s.results) == list(range(len(s.results)))  # in frame order, none lost
    s.undo()
    assert s.results == {}


def test_correction_pins_the_axis_and_refits_the_rest(session, qtbot, wait_idle):
    s = session
    s.fit()
    wait_idle(s)
    s.set_frame(5)
    before = s.results[5]
    assert s.correct({0: 200.0})  # J0.phi
    wait_idle(s)
    after = s.results[5]
    assert after.status == "corrected" and after.angles_deg[0] == 200.0
    assert s.pins == {5: {0: 200.0}}
    assert after.runs >= 1  # the rest was fitted again
    # its error is that of its posture
    e, _ = Fitter(s.body, s.model.cameras, s.params).error(after.angles_deg,
                                                           s.frame_detections(5))
    assert after.error == pytest.approx(e, rel=1e-9)
    # a second correction in the same frame keeps the first pin
    s.correct({8: 100.0}, refit=False)
    assert s.pins[5] == {0: 200.0, 8: 100.0}
    assert s.results[5].angles_deg[[0, 8]].tolist() == [200.0, 100.0]
    s.undo()
    assert s.pins[5] == {0: 200.0} and s.results[5] is after
    s.undo()
    assert s.results[5] is before and 5 not in s.pins
    s.redo()
    assert s.results[5] is after and s.pins == {5: {0: 200.0}}


def test_drag_marker_moves_it_to_the_drop_point(session, wait_idle):
    s = session
    s.set_frame(2)
    angles, roots, _ = s.posture()
    target_angles = angles.copy()
    target_angles[8] += 25.0  # gamma
    target = s.cameras[0].project(forward_kinematics(s.body, target_angles, roots).markers[3])
    assert s.drag_marker(0, 3, target)
    wait_idle(s)
    r = s.results[2]
    assert r.status == "corrected"
    drawn = s.overlays()[0].markers[3]
    assert np.linalg.norm(drawn - target) < 1.0
    assert set(s.pins[2]) == {0, 1, 2, 5, 8}  # everything the tibia tip hangs on is held
    s.undo()
    assert 2 not in s.results


def test_correction_of_an_axis_refits_in_a_copy_of_the_body(session, wait_idle):
    s = session
    original = s.body
    s.correct({1: 10.0})
    wait_idle(s)
    assert s.body is original and not s.body.axis_refs()[1].axis.locked


def test_histograms_learn_export_and_reload(session, tmp_path, wait_idle):
    s = session
    s.fit()
    wait_idle(s)
    good = sum(r.status in ("ok", "reanalysed", "corrected") for r in s.results.values())
    assert s.learn_histograms() == good
    refs = s.body.axis_refs()
    assert refs[0].axis.histogram.n_trials == 1 + good
    assert refs[3].axis.histogram.n_trials == 1  # locked axes are not learned
    assert s.unsaved == ["chain", "results"]
    path = tmp_path / "learned.xml"
    assert s.export_histograms(path)
    learned = archive_from_body(s.body)
    assert dict(load_archive(path)) == dict(learned)
    s.undo()  # back to the chain's initial histograms
    assert s.body.axis_refs()[0].axis.histogram.n_trials == 1
    assert s.import_histograms(path)
    assert dict(archive_from_body(s.body)) == dict(learned)


def test_save_and_reopen_keeps_corrections(session, project, qtbot, wait_idle):
    s = session
    s.fit()
    wait_idle(s)
    s.set_frame(4)
    s.correct({8: 90.0}, refit=False)
    s.learn_histograms()
    assert s.save() and not s.dirty
    table = read_results(project.parent / "detections.results.csv")
    assert len(table) == 12 and table.status[4] == "corrected"
    assert table.angles_deg[4, 8] == 90.0
    again = Session()
    again.open_project(project)
    assert again.results[4].status == "corrected"
    np.testing.assert_array_equal(again.results[4].angles_deg, s.results[4].angles_deg)
    assert again.body.axis_refs()[0].axis.histogram.n_trials > 1  # learned and saved
    again.close()


def test_apply_config_marks_stale_detections(session, project):
    s = session
    statuses = []
    s.status.connect(statuses.append)
    raw = tomllib.loads(project.read_text())
    raw["filters"]["steps"][0]["value"] = 150
    assert s.apply_config(raw)
    assert s.settings.filters.steps[0]["value"] == 150
    assert s.unsaved == ["config"]
    assert any("stale detections" in m for m in statuses)
    raw["filters"]["steps"][0]["value"] = 999
    assert not s.apply_config(raw)
    assert "filters.steps[0].value: must be at most 254" in s.messages[-1]
    s.save()
    assert tomllib.loads(project.read_text())["filters"]["steps"][0]["value"] == 150


def test_saving_the_config_keeps_the_users_comments(session, project):
    s = session
    project.write_text("# my rig, calibrated in May\n" + project.read_text().replace(
        "[cameras]", "[cameras]  # the May calibration"), encoding="utf-8")
    assert s.open_project(project)
    raw = tomllib.loads(project.read_text())
    raw["filters"]["steps"][0]["value"] = 150
    assert s.apply_config(raw) and s.save()
    text = project.read_text()
    assert text.startswith("# my rig, calibrated in May\n")
    assert "[cameras]  # the May calibration" in text
    assert tomllib.loads(text) == raw


def test_errors_are_one_line_messages(qtbot, project, tmp_path):
    s = Session()
    messages = []
    s.error.connect(messages.append)
    assert not s.open_project(tmp_path / "missing.toml")
    assert messages[-1].endswith("missing.toml: no such config file")
    raw = tomllib.loads(project.read_text())
    raw["chain"]["path"] = "nowhere.xml"
    project.write_text(tomli_w.dumps(raw))
    assert s.open_project(project)  # the video still opens; the chain is reported
    assert "nowhere.xml" in messages[-1] and "\n" not in messages[-1]
    assert s.n_frames == 12 and s.body is None and s.overlays() == []
    assert not s.fit()
    s.close()


def test_detect_in_the_background_with_edited_filters(session, project, qtbot, wait_idle):
    s = session
    raw = tomllib.loads(project.read_text())
    raw["markers"] = {**raw.get("markers", {}), "max_area": 4}  # too small for any marker
    assert s.apply_config(raw)
    statuses = []
    s.status.connect(statuses.append)
    with qtbot.waitSignal(s.detectionsChanged, timeout=30000):
        assert s.detect()
    wait_idle(s)
    assert s.detections.n_records == 12 and len(s.detections.points) == 0
    on_disk = load_detections(project.parent / "detections.npz")
    assert on_disk.metadata["settings"]["markers"]["max_area"] == 4
    assert s.frame_detections()[0].shape == (0, 2)
    assert "warning: view 'side': no markers in any of the 12 records" in statuses[-2]


def test_another_chain_file_replaces_the_chain(session, project, wait_idle):
    from kinematics.model.chain_xml import save_body
    from ui import adapters

    s = session
    s.fit([0, 1])
    wait_idle(s)
    longer = adapters.edit_segment(s.body, "tibia", length=100.0)
    save_body(project.parent / "long.xml", longer)
    raw = tomllib.loads(project.read_text())
    raw["chain"]["path"] = "long.xml"
    assert s.apply_config(raw)
    assert adapters.find_element(s.body, "segment", "tibia").length == 100.0
    assert sorted(s.results) == [0, 1]  # same axes: the results still apply
    assert s.model.chain_path.name == "long.xml"


def test_open_a_trial_of_a_project_folder(synth_project, tmp_path, qtbot, wait_idle):
    import shutil

    root = tmp_path / "lab"
    trial = root / "animal1" / "walk01"
    trial.mkdir(parents=True)
    shutil.copy(synth_project / "video.avi", trial / "walk.avi")
    for name in ("chain.xml", "cameras.toml"):
        shutil.copy(synth_project / name, root / name)
    raw = tomllib.loads((synth_project / "project.toml").read_text())
    del raw["video"]["path"], raw["output"]  # each trial's video; outputs beside it
    (root / "config.toml").write_text(tomli_w.dumps(raw))
    s = Session()
    messages = []
    s.error.connect(messages.append)
    assert s.open_project(root, trial="animal1/walk01")
    assert messages == [] and not s.editable and s.detections is None
    assert s.n_frames == 12 and s.body is not None
    assert not s.apply_config(raw) and "edit them there" in messages[-1]
    assert s.detect()
    wait_idle(s)
    assert (trial / "walk.detections.npz").exists()
    assert s.fit([0, 1, 2])
    wait_idle(s)
    assert s.save()
    assert len(read_results(trial / "walk.results.csv")) == 3
    s.close()


def test_an_alternative_posture_is_one_key_away(session, wait_idle, tmp_path):
    from kinematics.fit import Candidate

    s = session
    s.fit([3])
    wait_idle(s)
    fitted = s.results[3]
    # a frame the fit found ambiguous: its mirror posture kept as a candidate
    mirror = fitted.angles_deg.copy()
    mirror[0] += 20.0
    alt = Candidate(mirror, fitted.root_positions, fitted.error + 0.1, None, None, None)
    s.results[3] = replace(fitted, status="ambiguous", candidates=(
        Candidate(fitted.angles_deg, fitted.root_positions, fitted.error, None, None, None),
        alt))
    before = s.results[3]
    assert s.swap_candidate(3)
    after = s.results[3]
    assert after.status == "corrected" and after.angles_deg[0] == pytest.approx(mirror[0])
    assert after.candidates[0] is alt and len(after.candidates) == 2
    e, _ = Fitter(s.body, s.model.cameras, s.params).error(mirror, s.frame_detections(3))
    assert after.error == pytest.approx(e, rel=1e-9)
    assert s.swap_candidate(3)  # again: back to the fitted posture
    assert s.results[3].angles_deg[0] == pytest.approx(fitted.angles_deg[0])
    s.undo()
    s.undo()
    assert s.results[3] is before
    assert not s.swap_candidate(4)  # no alternatives there


def test_an_alternative_posture_carries_along_the_stretch_on_the_same_branch(session,
                                                                             wait_idle):
    """The fit took the mirror branch for frames 3-6: A on frame 4 swaps 3 and 5 as well
    (each kept the right posture as a candidate, near the chosen one), not frame 2, on the
    right branch; frame 6 kept no other candidate and is flagged instead; one undo restores
    them all."""
    from kinematics.fit import Candidate

    s = session
    s.fit()
    wait_idle(s)
    fitted = {f: s.results[f] for f in range(12)}

    def cand(r, angles):
        return Candidate(angles, r.root_positions, r.error, None, None, None)

    for f in (2, 3, 4, 5, 6, 7):
        r = fitted[f]
        right, mirror = r.angles_deg.copy(), r.angles_deg.copy()
        mirror[8] += 60.0  # the femur-tibia angle on the other branch
        on_mirror = f in (3, 4, 5, 6)
        shown = mirror if on_mirror else right
        if f == 6:  # on the mirror too, but the fit kept nothing else
            s.results[f] = replace(r, angles_deg=shown, status="ok", candidates=(
                cand(r, shown),))
            continue
        s.results[f] = replace(r, angles_deg=shown, status="ambiguous", candidates=(
            cand(r, shown), cand(r, right if on_mirror else mirror)))
    before = dict(s.results)
    assert s.swap_candidate(4)
    for f in (3, 4, 5):
        assert s.results[f].status == "corrected"
        np.testing.assert_allclose(s.results[f].angles_deg, fitted[f].angles_deg)
    assert s.results[2] is before[2]
    # frame 6 is left as it was, flagged: the user is sent there next
    assert s.results[6].status == "ambiguous"
    np.testing.assert_array_equal(s.results[6].angles_deg, before[6].angles_deg)
    assert s.results[7] is before[7]
    assert s.undo_label == "frame 4: alternative posture"
    # A again cycles the whole stretch back (the frames the last A set are not held)
    assert s.swap_candidate(4)
    for f in (3, 4, 5):
        np.testing.assert_allclose(s.results[f].angles_deg, before[f].angles_deg)
    s.undo()
    s.undo()
    assert all(s.results[f] is before[f] for f in range(12))
    # a neighbour set by hand stops the carry
    s.accept([5])
    assert s.swap_candidate(4)
    assert s.results[3].status == "corrected" and s.results[5].angles_deg[8] == pytest.approx(
        before[5].angles_deg[8])



def test_reopened_results_keep_the_bar_their_fit_used(session, project, wait_idle):
    from ui.state import Session

    s = session
    assert s.fit()
    wait_idle(s)
    measured = s.threshold
    assert np.isfinite(measured) and measured != s.params.reanalysis_threshold
    assert s.save()
    again = Session()
    try:
        assert again.open_project(project)
        assert again.threshold == measured
    finally:
        again.close()


def test_a_re_fit_forward_keeps_the_carried_branch_only_when_the_anneal_left_it():
    """Re-fitting from a neighbour: the anneal's result, unless it went to another branch
    (far from the neighbour's posture refined in place, which is nearer the neighbour) for
    an E not much lower, then the refined posture with the anneal's as its alternative; a
    refinement stuck far from the data never wins."""
    from kinematics.fit import Candidate
    from ui.state import backend
    from ui.state.corrections import carried_or_annealed

    def result(theta, error):
        angles = np.array([0.0, theta])
        r = backend.manual_result(7, angles, np.zeros((1, 3)), error, np.ones(2), 0)
        return replace(r, candidates=(Candidate(angles, r.root_positions, error, None, None,
                                                None),))

    previous = np.array([0.0, 30.0])
    mirror, kept = result(-28.0, 26.3), result(31.0, 28.0)
    chosen = carried_or_annealed(mirror, kept, previous)  # a mirror, 6 % lower E
    assert chosen.angles_deg[1] == 31.0 and chosen.error == 28.0
    assert [c.angles_deg[1] for c in chosen.candidates] == [31.0, -28.0]
    same = result(33.0, 27.0)  # the anneal stayed on the branch: its result
    assert carried_or_annealed(same, kept, previous) is same
    stuck = result(31.0, 123.0)  # the refinement far from the data
    assert carried_or_annealed(mirror, stuck, previous) is mirror
    assert carried_or_annealed(mirror, result(-25.0, 27.0), previous) is mirror  # not nearer
