"""Inputs are never overwritten (issue 16, item 3): an output path that is one of the run's
inputs is refused (even with --force), one holding an existing file of another kind is
refused unless --force; for fit, run, batch, detect and synth."""

import shutil
from pathlib import Path

import pytest

from videotrack.cli import main
from videotrack.synth.paper_setup import write_example_project

ANNEAL = ["--n-end", "2000"]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("guard") / "base"
    assert main(["synth", str(out), "--frames", "8", "--sequences", "1"]) == 0
    assert main(["detect", str(out / "project.toml")]) == 0
    return out


@pytest.fixture
def base(rendered, tmp_path, capsys):
    capsys.readouterr()
    return Path(shutil.copytree(rendered, tmp_path / "base"))


def run(capsys, *args):
    code = main([*map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_fit_results_over_an_input_is_refused_even_forced(base, capsys):
    # issue 16: videotrack fit base/project.toml --results base/chain.xml made it a CSV
    chain = (base / "chain.xml").read_bytes()
    for extra in ([], ["--force"]):
        code, _, err = run(capsys, "fit", base / "project.toml", "--results", base / "chain.xml",
                           *ANNEAL, *extra)
        assert code == 1 and err.count("\n") == 1, err
        assert f"{base / 'chain.xml'}: --results: is the chain of this run" in err
    assert (base / "chain.xml").read_bytes() == chain
    assert not (base / "chain.xml.json").exists()
    for name, what in (("cameras.toml", "the camera file"), ("video.avi", "the video"),
                       ("project.toml", "a config file"),
                       ("detections.npz", "the detections file")):
        before = (base / name).read_bytes()
        code, _, err = run(capsys, "run", base / "project.toml", "--results", base / name)
        assert code == 1 and f"is {what} of this run" in err, err
        assert (base / name).read_bytes() == before


def test_other_kinds_of_files_need_force(base, capsys):
    notes = base / "notes.csv"
    notes.write_text("my,own\n1,2\n")
    code, _, err = run(capsys, "fit", base / "project.toml", "--results", notes, *ANNEAL)
    assert code == 1 and "notes.csv: --results: exists and is not a results CSV" in err
    assert "(--force does)" in err and notes.read_text() == "my,own\n1,2\n"
    # the sidecar and the plot are outputs too
    (base / "r.csv.json").write_text("{}")
    code, _, err = run(capsys, "fit", base / "project.toml", "--results", base / "r.csv",
                       *ANNEAL)
    assert code == 1 and "r.csv.json: --results: exists and is not a results sidecar" in err
    (base / "r.png").write_text("not a picture")
    code, _, err = run(capsys, "fit", base / "project.toml", "--results", base / "q.csv",
                       "--plot", *ANNEAL)
    assert code == 0, err  # q.png is free
    code, _, err = run(capsys, "fit", base / "project.toml", "--results", base / "r.csv",
                       "--plot", "--force", *ANNEAL)
    assert code == 0, err
    assert (base / "r.csv").read_text().startswith("frame,video_frame,field,time")
    # results of an earlier fit are of the same kind: replaced as always
    assert run(capsys, "fit", base / "project.toml", "--results", base / "r.csv",
               "--seed", "4", *ANNEAL)[0] == 0


def test_detect_never_writes_over_the_video(base, capsys):
    video = (base / "video.avi").read_bytes()
    code, _, err = run(capsys, "detect", base / "project.toml", "-o", base / "video.avi",
                       "--force")
    assert code == 1 and "--output: is the video of this run" in err
    assert (base / "video.avi").read_bytes() == video


def test_synth_never_writes_over_its_inputs(base, capsys):
    truth = (base / "truth.csv").read_bytes()
    code, _, err = run(capsys, "synth", base, "--angles", base / "truth.csv")
    assert code == 1 and "truth.csv: is the --angles file of this run" in err
    assert (base / "truth.csv").read_bytes() == truth
    (base / "video.avi").write_text("a text file, not a video")
    code, _, err = run(capsys, "synth", base, "--frames", "4", "--sequences", "1")
    assert code == 1 and "video.avi: exists and is not a video: not overwritten" in err
    assert run(capsys, "synth", base, "--frames", "4", "--sequences", "1", "--force")[0] == 0


def test_batch_never_writes_over_an_input(tmp_path, capsys):
    root = tmp_path / "p"
    write_example_project(root, ["s1/t1", "s1/t2"], frames=6)
    chain = (root / "chain.xml").read_bytes()
    (root / "s1" / "t2" / "config.toml").write_text('[fit]\nresults = "../../chain.xml"\n')
    code, out, err = run(capsys, "batch", root, "--jobs", "1", "--force")
    assert code == 1 and "1 done, 1 failed" in out
    assert "chain.xml: is a chain of the project: an output never replaces an input" in out
    assert (root / "chain.xml").read_bytes() == chain
    # the summary is an output too
    (root / "s1" / "t2" / "config.toml").unlink()
    (root / "config.toml").write_text((root / "config.toml").read_text()
                                      + '\n[batch]\nsummary = "cameras.toml"\n')
    code, _, err = run(capsys, "batch", root, "--jobs", "1", "--force")
    assert code == 1 and "cameras.toml: batch.summary: is a camera file of this run" in err
