"""Warnings travel (issue 16, item 2): every warning of a trial reaches the results sidecar,
summary.csv (a warnings column, ``done-with-warnings``) and the printed summary, and survives
reruns; an incomplete trial (a truncated video, an unreadable image, no frame fitted) gives
exit status 3 unless --allow-incomplete, naming the file or frame."""

import csv
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from videotrack.cli import main
from videotrack.detect.video import VideoSource
from videotrack.synth.paper_setup import write_example_project

# the paper's settings: these tests are about the orchestration, not the fit
ANNEAL = {"profile": "paper", "n_end": 2000, "n_l": 200, "n_tau": 86}
N = 24


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A one-trial project whose video is a folder of PNG images, 0000.png ... 0023.png."""
    root = tmp_path_factory.mktemp("travel") / "project"
    write_example_project(root, ["s1/t1"], frames=N, anneal=ANNEAL)
    trial = root / "s1" / "t1"
    frames = trial / "frames"
    frames.mkdir()
    with VideoSource(trial / "video.avi") as video:
        for k, frame in video.frames():
            assert cv2.imwrite(str(frames / f"{k:04d}.png"), frame)
    (trial / "video.avi").unlink()
    (trial / "config.toml").write_text('[video]\npath = "frames"\n')
    return root


@pytest.fixture
def project(rendered, tmp_path):
    return Path(shutil.copytree(rendered, tmp_path / "project"))


def batch(capsys, root, *args):
    code = main(["batch", str(root), "--jobs", "1", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def row(root: Path) -> dict:
    (only,) = csv.DictReader((root / "summary.csv").open())
    return only


def test_a_truncated_image_makes_the_trial_incomplete_every_time(project, capsys):
    # issue 16: a folder of PNGs with 0017.png truncated kept 17 frames, exit 0, "done",
    # 0.0 % bad, and "up to date" the next time with the warning gone for good
    image = project / "s1" / "t1" / "frames" / "0017.png"
    image.write_bytes(image.read_bytes()[:200])
    for _attempt in range(2):
        code, out, err = batch(capsys, project)
        assert code == 3, err
        r = row(project)
        assert r["state"] == "incomplete" and r["frames"] == "17"
        assert "0017.png" in r["message"] and "frames 17..23 of 24 are missing" in r["message"]
        assert "0017.png: cannot read this image" in r["warnings"]
        assert "incomplete:\n  s1/t1: " in out and "warnings:\n  s1/t1: " in out
        assert "0017.png" in err and "--allow-incomplete" in err
        assert "Traceback" not in err
    assert "no log (nothing to do)" in out  # the second run found it up to date
    sidecar = json.loads((project / "s1" / "t1" / "frames.results.csv.json").read_text())
    assert any("0017.png" in w for w in sidecar["warnings"])
    code, out, err = batch(capsys, project, "--allow-incomplete")
    assert code == 0 and row(project)["state"] == "incomplete"


def test_warnings_reach_the_summary_and_survive_reruns(project, capsys):
    # frames 0..5 black: six frames without detections, 25 % of the trial
    frames = project / "s1" / "t1" / "frames"
    for k in range(6):
        black = np.zeros_like(cv2.imread(str(frames / f"{k:04d}.png"), cv2.IMREAD_GRAYSCALE))
        cv2.imwrite(str(frames / f"{k:04d}.png"), black)
    code, out, err = batch(capsys, project)
    assert code == 0, err
    r = row(project)
    assert r["state"] == "done-with-warnings" and r["message"] == ""
    assert "6 of 24 frames (25.0 %) have no fit to trust" in r["warnings"]
    assert "video frames 0, 1, 2, 3, 4, 5" in r["warnings"]
    assert "1 done-with-warnings" in out and "warnings:\n  s1/t1: 6 of 24 frames" in out
    code, out, err = batch(capsys, project)
    assert code == 0 and "1 up-to-date-with-warnings" in out
    assert row(project)["warnings"] == r["warnings"]


def test_fit_and_run_exit_3_when_incomplete(tmp_path, capsys):
    assert main(["synth", str(tmp_path / "p"), "--frames", "16", "--sequences", "2"]) == 0
    config = tmp_path / "p" / "project.toml"
    config.write_text(config.read_text() + "\n[anneal]\nn_end = 2000\nn_l = 200\nn_tau = 86\n")
    video = tmp_path / "p" / "video.avi"
    video.write_bytes(video.read_bytes()[: video.stat().st_size * 2 // 3])
    capsys.readouterr()
    for command in ("run", "fit"):  # run detects and fits, fit finds them up to date
        code = main([command, str(config)])
        err = capsys.readouterr().err
        assert code == 3, err
        assert "video.avi: decoding stopped at frame" in err
        assert "incomplete: video.avi cannot be decoded from frame" in err
    assert main(["fit", str(config), "--allow-incomplete"]) == 0
