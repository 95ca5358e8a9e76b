"""The markerless route through a project: `videotrack fit project.toml` with [keypoints]
files fits the chain to DeepLabCut keypoints (2D) or to their triangulation (3D)."""

import json

import numpy as np
import pytest

from videotrack.cli import main
from videotrack.project.config import load_config
from videotrack.results.files import read_results, read_sidecar, sidecar_path
from videotrack.synth.keypoints import write_session

N_FRAMES = 16
ANNEAL = "[anneal]\nseed = 1\nn_end = 8000\nn_l = 800\nn_tau = 350\n"
TRIANGULATED = ('route = "3d"\ntriangulation = "ransac"\n' + ANNEAL
                + "tau0 = 5.0\nreanalysis_threshold = 3.0\ncap_px = 30.0\n")


def angle_errors(results, session) -> np.ndarray:
    err = np.abs((results.angles_deg - session.angles_deg + 180) % 360 - 180)
    return err[:, ~session.body.locked_mask()]


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return write_session(tmp_path_factory.mktemp("markerless"), N_FRAMES, noise_px=1.0,
                         bad_share=0.1, project_text=ANNEAL)


def fit(project, *extra) -> int:
    return main(["fit", str(project), *extra])


def test_fit_to_2d_keypoints_matches_truth_then_is_up_to_date(session, capsys):
    assert fit(session.project) == 0
    out = capsys.readouterr().out
    assert f"fitted {N_FRAMES} frames" in out
    csv = session.project.parent / "cam0DLC.results.csv"
    res = read_results(csv)
    assert len(res) == N_FRAMES and res.view_names == ("cam0", "cam1", "cam2", "cam3")
    np.testing.assert_array_equal(res.video_frames, np.arange(N_FRAMES))
    err = angle_errors(res, session)
    assert np.median(err) < 2.0 and np.median(err.max(axis=1)) < 5.0
    assert np.median(np.linalg.norm(res.joints - session.joints, axis=2)) < 1.0  # mm
    side = read_sidecar(csv)
    assert side["keypoints"] == [p.name for p in session.files]
    assert len(side["keypoints_sha256"]) == 4 and "detections" not in side
    assert side["keypoints_options"]["route"] == "2d"
    before = csv.stat().st_mtime_ns
    assert fit(session.project) == 0
    assert "is up to date" in capsys.readouterr().out
    assert csv.stat().st_mtime_ns == before


def test_changed_keypoint_file_or_setting_makes_results_stale(session, tmp_path, capsys):
    from videotrack.workflow import plan_project

    folder = tmp_path / "copy"
    moved = write_session(folder, N_FRAMES, noise_px=1.0, bad_share=0.1, project_text=ANNEAL)
    assert fit(moved.project) == 0
    assert plan_project(load_config(moved.project)) == ("up to date", "")
    lines = moved.files[2].read_text().splitlines()
    lines[5] = lines[5].replace(".", "1.", 1)  # one coordinate of frame 2 moves
    moved.files[2].write_text("\n".join(lines) + "\n")
    assert plan_project(load_config(moved.project)) == ("fit", "changed: keypoints")
    capsys.readouterr()
    assert fit(moved.project) == 0
    assert f"fitted {N_FRAMES} frames" in capsys.readouterr().out
    text = moved.project.read_text()
    moved.project.write_text(text.replace("[anneal]", "min_score = 0.5\n[anneal]"))
    assert plan_project(load_config(moved.project)) == ("fit", "changed: keypoint settings")


def test_fit_to_triangulated_points(session, tmp_path, capsys):
    tri = write_session(tmp_path, N_FRAMES, noise_px=1.0, bad_share=0.1,
                        project_text=TRIANGULATED)
    assert fit(tri.project) == 0
    out = capsys.readouterr().out
    assert " px" not in out.split("median error")[1].splitlines()[0]  # E is a length in 3D
    res = read_results(tmp_path / "cam0DLC.results.csv")
    err = angle_errors(res, tri)
    assert np.median(err) < 3.0
    assert np.median(np.linalg.norm(res.joints - tri.joints, axis=2)) < 1.5
    assert read_sidecar(tmp_path / "cam0DLC.results.csv")["keypoints_options"]["route"] == "3d"


@pytest.mark.parametrize("change, field", [
    (lambda s: s.files[1].write_text(s.files[1].read_text().replace("0.", "abc", 1)), "cam1DLC"),
    (lambda s: s.project.write_text(s.project.read_text() + '[keypoints.markers]\n'
                                    'knee = "kneecap"\n'), "keypoints.markers"),
    (lambda s: s.project.write_text(s.project.read_text().replace(', "cam3DLC.csv"', "")),
     "keypoints.files"),
    (lambda s: s.project.write_text(s.project.read_text().replace(
        "[keypoints]", "[keypoints]\ncrop_offsets = [[0, 0], [1, 2]]")), "keypoints.crop_offsets"),
])
def test_bad_keypoint_input_is_one_line_and_writes_nothing(tmp_path, capsys, change, field):
    s = write_session(tmp_path, 6, project_text=ANNEAL)
    change(s)
    before = sorted(p.name for p in tmp_path.iterdir())
    assert fit(s.project) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0] and "Traceback" not in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_outputs_never_replace_a_keypoint_file(session, capsys):
    assert fit(session.project, "--results", str(session.files[0])) == 1
    assert "keypoint file 0" in capsys.readouterr().err


def test_resume_after_interruption_gives_identical_file(tmp_path, monkeypatch):
    """A resumed fit keeps the checkpoint's leading whole windows of the path through time
    (here of 2 x 4 frames, every 4), and the threshold that judged them, so the rest is
    decided as the whole fit decided it."""
    from dataclasses import replace

    from kinematics.fit import tuning
    from videotrack import workflow as pipeline
    from videotrack.markerless.route import load_keypoints
    from videotrack.workflow import checkpoint

    monkeypatch.setattr(tuning, "TUNING", replace(tuning.TUNING, path_lag=4))

    # every root marker in every frame: the free root's seed of a frame does not depend on
    # the frames fitted before it (with gaps it is carried over from them; see the report)
    session = write_session(tmp_path / "s", N_FRAMES, noise_px=1.0, bad_share=0.0,
                            project_text=ANNEAL)
    config = load_config(session.project)
    model = pipeline.load_model(config, n_end=3000)
    data = load_keypoints(config, model)
    full = tmp_path / "full.csv"
    pipeline.fit_project(model, data, None, full)
    monkeypatch.setattr(checkpoint, "CHECKPOINT_SECONDS", 0.0)
    cut = tmp_path / "cut.csv"
    seen = []

    def killer(r):
        seen.append(r.frame)
        if len(seen) == 6:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        pipeline.fit_project(model, data, None, cut, progress=killer)
    assert not cut.exists() and (tmp_path / "cut.csv.partial").exists()
    # a checkpoint's threshold that is no finite positive number (an edited or old sidecar)
    # is measured again; the checkpoint's frames are kept either way
    partial = tmp_path / "cut.csv.partial"
    side = sidecar_path(partial)
    meta = read_sidecar(partial)
    assert meta["threshold"] > 0
    for bad in (True, "12", -1.0, float("inf"), None):
        side.write_text(json.dumps({**meta, "threshold": bad}))
        frames, threshold, _ = checkpoint._resume(partial, meta)
        assert threshold is None and len(frames) == 5, bad
    side.write_text(json.dumps(meta))
    kept = []
    pipeline.fit_project(model, data, None, cut, resumed=lambda n, of: kept.append(n))
    assert kept == [4]  # 6 frames checkpointed, one window's 4 kept
    assert cut.read_text() == full.read_text()
    # judged by the whole fit's threshold (measured on its sample), not the rest's
    assert read_sidecar(cut)["threshold"] == read_sidecar(full)["threshold"]
    assert (tmp_path / "cut.candidates.csv").read_text() == (
        tmp_path / "full.candidates.csv").read_text()


def test_the_2d_route_defaults_to_a_keypoint_sized_cap(session, tmp_path):
    from videotrack.project.config import load_config
    from videotrack.workflow import KEYPOINT_CAP_PX, anneal_params

    assert anneal_params(load_config(session.project)).error.cap_px == KEYPOINT_CAP_PX
    own = tmp_path / "own.toml"
    own.write_text(session.project.read_text().replace("[anneal]", "[anneal]\ncap_px = 12.0"))
    assert anneal_params(load_config(own)).error.cap_px == 12.0  # a project's own value wins


def test_batch_finds_markerless_trials_by_their_keypoint_files(tmp_path, capsys):
    import shutil

    root = tmp_path / "project"
    sessions = {name: write_session(root / name, 10, noise_px=1.0, bad_share=0.0, seed=k)
                for k, name in enumerate(("t1", "t2"))}
    for shared in ("rat.xml", "cameras.toml"):
        shutil.copy(root / "t1" / shared, root / shared)
    (root / "config.toml").write_text(
        '[chain]\npath = "rat.xml"\n[cameras]\npath = "cameras.toml"\n'
        '[batch]\ntrials = ["*"]\nkeypoints = ["cam*DLC.csv"]\n' + ANNEAL, encoding="utf-8")
    assert main(["batch", str(root), "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    assert "2 trials: 2 done" in out, out
    for name in ("t1", "t2"):
        res = read_results(root / name / "cam0DLC.results.csv")
        assert len(res) == 10 and np.median(angle_errors(res, sessions[name])) < 3
    assert main(["batch", str(root), "--jobs", "1"]) == 0
    assert "2 up to date" in capsys.readouterr().out
    # a keypoint list set for every trial at once is refused, naming the file
    (root / "config.toml").write_text((root / "config.toml").read_text()
                                      + '[keypoints]\nfiles = ["a.csv"]\n', encoding="utf-8")
    assert main(["batch", str(root), "--jobs", "1"]) == 1
    assert "every trial would read the same keypoint files" in capsys.readouterr().err



def test_the_optimised_triangulation_holds_the_chains_rigid_pairs(tmp_path):
    from videotrack.markerless.route import rigid_pairs

    tri = write_session(tmp_path, N_FRAMES, noise_px=1.0, bad_share=0.1,
                        project_text=TRIANGULATED.replace('"ransac"', '"optim"'))
    pairs, lengths = rigid_pairs(tri.body, list(tri.body.marker_names))
    # the pelvis markers (hips and tail base) are the only ones sharing a segment
    assert pairs == [(0, 1), (0, 2), (1, 2)]
    truth = tri.markers[0]
    np.testing.assert_allclose(lengths, [np.linalg.norm(truth[a] - truth[b])
                                         for a, b in pairs], rtol=1e-9)
    assert fit(tri.project) == 0
    res = read_results(tmp_path / "cam0DLC.results.csv")
    assert np.median(angle_errors(res, tri)) < 3.0
