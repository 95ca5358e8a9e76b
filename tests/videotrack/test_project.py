"""Project folders: trial discovery, config inheritance, validation errors naming the file."""

from pathlib import Path

import pytest

from videotrack.errors import VideoTrackError
from videotrack.project.config import load_config, merge_layers, parse_layer
from videotrack.project.folders import load_trial_config, open_project

ROOT_CONFIG = """\
[[views]]
name = "side"
roi = [0, 0, 360, 288]

[[views]]
name = "top"
roi = [360, 0, 360, 288]

[[filters.steps]]
type = "threshold"
value = 96

[markers]
min_area = 3
max_area = 500

[chain]
path = "chain.xml"

[cameras]
path = "cameras.toml"

[anneal]
n_end = 2000
seed = 1
"""


def make(root: Path, files: dict[str, str]) -> Path:
    """Write ``files`` (relative path -> text; an empty text makes an empty stand-in video)."""
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


@pytest.fixture
def project(tmp_path):
    return make(tmp_path / "p", {
        "config.toml": ROOT_CONFIG,
        "s1/t1/walk.avi": "", "s1/t2/walk.avi": "", "s2/t1/walk.avi": "",
        "s2/config.toml": '[[views]]\nname = "front"\n\n[markers]\nmin_area = 5\n\n'
                          '[chain]\npath = "leg2.xml"\n',
        "s2/t1/config.toml": "[anneal]\nseed = 7\n",
        "s1/notes/readme.txt": "no video here",
        ".hidden/t9/walk.avi": "", "logs/old/walk.avi": "",
    })


def trial(proj, name):
    return next(t for t in proj.trials if t.name == name)


def test_trials_are_found_and_inherit_keys(project):
    proj = open_project(project)
    assert [t.name for t in proj.trials] == ["s1/t1", "s1/t2", "s2/t1"]
    assert [(f.name, why) for f, why in proj.ignored] == [
        ("notes", "no video matching *.avi, *.mp4, *.mov, *.mkv")]
    c1, c3 = trial(proj, "s1/t1").config, trial(proj, "s2/t1").config
    # the trial's video fills [video] path; outputs go beside it
    assert c1["video"]["path"] == project / "s1/t1/walk.avi" and c1.folder == project / "s1/t1"
    assert c1["anneal"]["seed"] == 1 and c1["anneal"]["n_end"] == 2000
    assert c1["chain"]["path"] == project / "chain.xml"
    # deeper files override keys; the rest of a section is inherited
    assert c3["anneal"]["seed"] == 7 and c3["anneal"]["n_end"] == 2000
    assert c3["markers"]["min_area"] == 5 and c3["markers"]["max_area"] == 500
    # an array of tables replaces the one above, it is not appended to
    assert [v["name"] for v in c3["views"]] == ["front"]
    assert [v["name"] for v in c1["views"]] == ["side", "top"]
    # a relative path resolves against the file that sets it
    assert c3["chain"]["path"] == project / "s2/leg2.xml"
    assert c3["cameras"]["path"] == project / "cameras.toml"
    assert c3.sources == (project / "config.toml", project / "s2/config.toml",
                          project / "s2/t1/config.toml")
    assert c3.path == project / "s2/t1/config.toml"
    assert proj.summary_path == project / "summary.csv"


def test_errors_name_the_file_and_fail_only_the_trials_below(project):
    (project / "s2/config.toml").write_text("[anneal]\nn_end = 0\n")
    (project / "s1/t2/config.toml").write_text("[markers]\nmin_aera = 4\n")
    proj = open_project(project)
    assert trial(proj, "s1/t1").config is not None
    assert trial(proj, "s2/t1").error == (
        f"{project / 's2/config.toml'}: anneal.n_end: must be at least 1, got 0")
    assert trial(proj, "s1/t2").error.startswith(
        f"{project / 's1/t2/config.toml'}: markers.min_aera: unknown key 'min_aera'")
    (project / "s1/t2/config.toml").write_text('[fit]\nplot = "yes"\n')
    assert trial(open_project(project), "s1/t2").error == (
        f"{project / 's1/t2/config.toml'}: fit.plot: must be true or false, got a string")
    (project / "s1/t2/config.toml").write_text("[fit\n")
    assert "s1/t2/config.toml:1: TOML syntax" in trial(open_project(project), "s1/t2").error


def test_project_config_errors_stop_everything(project):
    (project / "config.toml").write_text(ROOT_CONFIG + "[oops]\n")
    with pytest.raises(VideoTrackError, match=r"config.toml: oops: unknown section"):
        open_project(project)
    (project / "config.toml").unlink()
    with pytest.raises(VideoTrackError, match=r"no config\.toml"):
        open_project(project)
    with pytest.raises(VideoTrackError, match="no such project folder"):
        open_project(project / "nowhere")


def test_video_path_only_in_the_trial_own_config(project):
    (project / "s1/t2/cam1.avi").write_text("")
    (project / "s1/t2/config.toml").write_text('[video]\npath = ["walk.avi", "cam1.avi"]\n')
    (project / "s2/config.toml").write_text('[video]\npath = "shared.avi"\n')
    proj = open_project(project)
    assert trial(proj, "s1/t2").config["video"]["path"] == [project / "s1/t2/walk.avi",
                                                           project / "s1/t2/cam1.avi"]
    assert trial(proj, "s2/t1").error.startswith(
        f"{project / 's2/config.toml'}: video.path: set above the trial folder")


def test_several_videos_are_cameras_in_name_order(project):
    for name in ("cam10.mp4", "cam2.mp4", ".cam3.mp4.x.tmp"):
        (project / "s1/t1" / name).write_text("")
    (project / "s1/config.toml").write_text('[batch]\nvideos = ["cam*.mp4"]\n')
    cfg = trial(open_project(project), "s1/t1").config
    assert cfg["video"]["path"] == [project / "s1/t1/cam2.mp4", project / "s1/t1/cam10.mp4"]


def test_batch_keys(project):
    (project / "s1/config.toml").write_text("[batch]\njobs = 3\n")
    err = trial(open_project(project), "s1/t1").error
    assert err.endswith("s1/config.toml: batch.jobs: a project-wide key: set it in "
                        f"{project / 'config.toml'}")
    (project / "s1/config.toml").unlink()
    (project / "config.toml").write_text(ROOT_CONFIG + '[batch]\ntrials = ["*"]\n'
                                         'summary = "out/summary.csv"\n')
    (project / "t0").mkdir()
    (project / "t0/walk.mp4").write_text("")
    proj = open_project(project)
    assert [t.name for t in proj.trials] == ["t0"]  # logs/ and hidden folders never are
    assert proj.summary_path == project / "out/summary.csv"
    (project / "config.toml").write_text(ROOT_CONFIG + '[batch]\ntrials = ["../*"]\n')
    with pytest.raises(VideoTrackError, match=r"batch\.trials: patterns must be relative"):
        open_project(project)
    (project / "config.toml").write_text(ROOT_CONFIG + '[batch]\ntrials = ["x/*"]\n')
    with pytest.raises(VideoTrackError, match="no trial: no folder matching"):
        open_project(project)


def test_shared_output_paths_fail_the_trials_that_collide(project):
    (project / "s1/config.toml").write_text('[output]\ndetections = "all.npz"\n')
    proj = open_project(project)
    for name in ("s1/t1", "s1/t2"):
        assert "trials s1/t1, s1/t2 would all write this file" in trial(proj, name).error
    assert trial(proj, "s2/t1").config is not None


def test_select_and_load_one_trial(project):
    proj = open_project(project)
    assert [t.name for t in proj.select(["s1/*"])] == ["s1/t1", "s1/t2"]
    assert [t.name for t in proj.select(["*/t1"])] == ["s1/t1", "s2/t1"]
    with pytest.raises(VideoTrackError, match="no trial matches 's9/\\*'"):
        proj.select(["s9/*"])
    cfg = load_trial_config(project, "s2/t1")
    assert cfg["anneal"]["seed"] == 7
    with pytest.raises(VideoTrackError, match="--trial: no trial 's3/t1'"):
        load_trial_config(project, "s3/t1")


def test_merge_layers_and_single_files(tmp_path):
    a = parse_layer({"markers": {"min_area": 2, "max_area": 9},
                     "views": [{"name": "a"}, {"name": "b"}]}, tmp_path / "a.toml")
    b = parse_layer({"markers": {"max_area": 50}, "views": [{"name": "c"}]},
                    tmp_path / "b" / "b.toml")
    merged = merge_layers([a, b])
    assert merged["markers"] == {"min_area": 2, "max_area": 50}
    assert [v["name"] for v in merged["views"]] == ["c"]
    assert a["markers"] == {"min_area": 2, "max_area": 9}  # layers are not changed
    # one file is the one-layer case: defaults, required keys, relative paths
    steps = '[[filters.steps]]\ntype = "otsu"\n'
    (tmp_path / "p.toml").write_text('[video]\npath = "v.avi"\n' + steps)
    cfg = load_config(tmp_path / "p.toml")
    assert cfg["video"]["path"] == tmp_path / "v.avi" and cfg.folder == tmp_path
    assert cfg.sources == (tmp_path / "p.toml",)
    (tmp_path / "p.toml").write_text("[markers]\nmin_area = 2\n" + steps)
    with pytest.raises(VideoTrackError, match=r"p\.toml: video\.path: missing"):
        load_config(tmp_path / "p.toml")
