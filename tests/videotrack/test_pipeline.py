"""``videotrack.workflow.run.run_project``, the one workflow: detect when stale, fit when stale,
skip what is up to date, force, plot, cancel; and ``fit``, ``run``, ``batch`` and ``demo``
write the same results file as calling it directly."""

import re
import shutil
import warnings
from pathlib import Path

import pytest

from kinematics.errors import LocatedError
from videotrack.cli import main
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.project.config import load_config
from videotrack.results.files import read_sidecar
from videotrack.workflow import Cancelled, plan_project, run_project

#: A short schedule in the paper's proportions, so a fit takes a fraction of a second.
SHORT = {"n_end": 2000, "n_l": 200, "n_tau": 86}
N_FRAMES = 16


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A synthetic project (video, chain, cameras, project.toml), not yet detected."""
    out = tmp_path_factory.mktemp("pipeline") / "project"
    assert main(["synth", str(out), "--frames", str(N_FRAMES), "--sequences", "2"]) == 0
    return out


@pytest.fixture
def project(rendered, tmp_path, capsys):
    """A fresh copy of :func:`rendered`; returns its project file."""
    capsys.readouterr()
    return Path(shutil.copytree(rendered, tmp_path / "project")) / "project.toml"


def test_detects_fits_skips_and_forces(project):
    config = load_config(project)
    events, notes = [], []
    run = run_project(config, anneal=SHORT, progress=events.append, log=notes.append)
    assert run.steps == ("detect", "fit") and run.detected and run.fitted
    assert run.fit_reason == "no results yet" and run.plot_path is None
    assert run.n_frames == N_FRAMES == run.n_ok + run.n_bad and run.n_ok >= N_FRAMES - 1
    assert run.detect_seconds > 0 and run.fit_seconds > 0 and run.warnings == ()
    assert run.results_path == project.parent / "detections.results.csv"
    assert run.detections_path == project.parent / "detections.npz"
    assert read_sidecar(run.results_path)["anneal"]["n_end"] == 2000
    # progress: every video frame detected, then the fit announced and every record fitted
    assert [e.done for e in events if e.step == "detect"] == list(range(1, N_FRAMES + 1))
    assert [(e.done, e.total) for e in events if e.step == "fit"] == [
        (k, N_FRAMES) for k in range(N_FRAMES + 1)]
    assert notes[0] == "detected 16 records into detections.npz" and len(notes) == 2
    assert notes[1].startswith("fitting 16 records (no results yet), ")
    first = run.results_path.read_bytes()
    mtimes = [p.stat().st_mtime_ns for p in (run.results_path, run.detections_path)]

    again = run_project(config, anneal=SHORT)
    assert again.up_to_date and again.steps == () and again.fit_reason == ""
    assert again.n_frames == N_FRAMES and again.results is not None
    assert [p.stat().st_mtime_ns for p in (run.results_path, run.detections_path)] == mtimes

    forced = run_project(config, anneal=SHORT, force=True)
    assert forced.steps == ("detect", "fit") and forced.fit_reason == "--force"
    assert run.results_path.read_bytes() == first

    other = run_project(config, anneal={**SHORT, "seed": 3})
    assert other.steps == ("fit",) and other.fit_reason == "changed: seed, anneal"


def test_plot_subset_and_plan(project):
    project.write_text(project.read_text() + "\n[anneal]\nn_end = 2000\nn_l = 200\n"
                       "n_tau = 86\n")
    config = load_config(project)
    assert plan_project(config) == ("detect + fit", "no detections yet")
    run = run_project(config, plot=True)
    assert run.steps == ("detect", "fit", "plot")
    assert run.plot_path == project.parent / "detections.results.png"
    assert plan_project(config) == plan_project(config, plot=True) == ("up to date", "")
    assert plan_project(config, force=True) == ("detect + fit", "--force")
    assert run_project(config, plot=True).steps == ()  # the plot is newer than the results
    run.plot_path.unlink()
    assert plan_project(config, plot=True) == ("plot", "no plot of the current results")
    assert run_project(config, plot=True).steps == ("plot",)
    # a subset of records is always fitted (and is then the whole results file)
    part = run_project(config, frames=slice(2, 6), results=project.parent / "part.csv")
    assert part.steps == ("fit",) and part.fit_reason == "records 2:6" and part.n_frames == 4
    assert list(part.results.frames) == [2, 3, 4, 5]
    assert run_project(config, frames=slice(10, None), results=project.parent / "p.csv"
                       ).n_frames == N_FRAMES - 10


def test_detect_only_use_as_is_and_errors(project):
    config = load_config(project)
    with pytest.raises(VideoTrackError, match="no detections yet"):
        run_project(config, detect=False)
    det = run_project(config, fit=False)
    assert det.steps == ("detect",) and det.model is None and det.results is None
    assert det.detections.n_records == N_FRAMES
    assert run_project(config, fit=False).steps == ()
    # detect=False uses the file as it is, and refuses one made with other settings
    fitted = run_project(config, detect=False, anneal=SHORT)
    assert fitted.steps == ("fit",)
    project.write_text(project.read_text().replace("value = 96", "value = 120"))
    with pytest.raises(VideoTrackError, match="stale detections"):
        run_project(load_config(project), detect=False, anneal=SHORT)
    # a bad chain fails before any detection
    project.write_text(project.read_text().replace('path = "chain.xml"', 'path = "no.xml"'))
    det.detections_path.unlink()
    with pytest.raises(LocatedError, match=r"no\.xml"):
        run_project(load_config(project))
    assert not det.detections_path.exists()


def test_cancel_and_warnings(project):
    config = load_config(project)
    with pytest.raises(Cancelled):
        run_project(config, cancel=lambda: True)
    assert not (project.parent / "detections.npz").exists()
    seen = []

    def enough() -> bool:
        return len([e for e in seen if e.step == "fit"]) > 5

    with pytest.raises(Cancelled):
        run_project(config, anneal=SHORT, progress=seen.append, cancel=enough)
    assert (project.parent / "detections.npz").exists()
    assert not (project.parent / "detections.results.csv").exists()
    # VideoTrack's warnings are collected into the run, not shown
    project.write_text(project.read_text().replace("min_area = 3", "min_area = 3\nmax_area = 4"))
    with warnings.catch_warnings(), pytest.raises(  # (an error passes its warnings on)
            LocatedError, match="set-up check: no detections in any view"):
        warnings.simplefilter("ignore", VideoTrackWarning)
        run_project(load_config(project), anneal=SHORT)  # a video without markers: refused
    accepted = {**SHORT, "accept_setup": True}
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        run = run_project(load_config(project), anneal=accepted)
    assert not [w for w in shown if issubclass(w.category, VideoTrackWarning)]
    assert len(run.warnings) == 4 and "no markers in any of the 16 records" in run.warnings[0]
    assert any(w.startswith("set-up check (accepted): no detections") for w in run.warnings)
    assert any(w.startswith("16 of 16 frames (100.0 %) have no fit to trust")
               for w in run.warnings)
    assert run.n_ok == 0 and run.n_bad == N_FRAMES
    assert run.incomplete.startswith("not one of the 16 frames has a fit to trust")
    # the warnings are kept with the detections and results, and travel to the next run
    again = run_project(load_config(project), anneal=accepted)
    assert again.up_to_date and again.warnings == run.warnings
    assert again.incomplete == run.incomplete


def test_fit_and_run_write_what_run_project_writes(project, capsys):
    config = load_config(project)
    direct = run_project(config, anneal={"n_end": 2000}, results=project.parent / "direct.csv")
    args = ["--n-end", "2000", "--results", str(project.parent / "cli.csv")]
    assert main(["fit", str(project), *args]) == 0
    out = capsys.readouterr().out
    assert f"fitted {N_FRAMES} frames" in out and "wrote" in out
    cli = project.parent / "cli.csv"
    assert cli.read_bytes() == direct.results_path.read_bytes()
    assert read_sidecar(cli) == read_sidecar(direct.results_path)
    assert main(["run", str(project), *args, "--plot"]) == 0
    out = capsys.readouterr().out
    assert "detections.npz is up to date (--force detects again)" in out
    assert "cli.csv is up to date (--force fits again)" in out
    assert f"wrote {project.parent / 'cli.png'}" in out
    assert main(["run", str(project), *args, "--force"]) == 0
    out = capsys.readouterr().out
    assert "markers per view per frame" in out and f"fitted {N_FRAMES} frames" in out
    assert cli.read_bytes() == direct.results_path.read_bytes()


def test_batch_writes_what_run_project_writes(tmp_path, capsys):
    from videotrack.project.folders import open_project
    from videotrack.synth.paper_setup import write_example_project

    root = tmp_path / "batch"
    write_example_project(root, ["s1/t1"], frames=12, anneal=SHORT)
    assert main(["batch", str(root), "--jobs", "1"]) == 0
    capsys.readouterr()
    results = root / "s1" / "t1" / "video.results.csv"
    batched = results.read_bytes()
    trial = open_project(root).trials[0]
    assert run_project(trial.config).up_to_date
    assert run_project(trial.config, force=True).fitted
    assert results.read_bytes() == batched


def test_demo_writes_what_run_project_writes(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--frames", "12", "--n-end", "1000"]) == 0
    capsys.readouterr()
    run = run_project(load_config(out / "project.toml"), anneal={"n_end": 1000, "seed": 0},
                      results=out / "direct.csv")
    assert run.steps == ("fit",)  # the demo's detections are up to date
    assert run.results_path.read_bytes() == (out / "detections.results.csv").read_bytes()


def test_fit_says_when_it_resumed(project, capsys, monkeypatch):
    # issue 16: 'fit' did not say when it resumed from a checkpoint
    from dataclasses import replace

    from kinematics.fit import tuning
    from videotrack.workflow import checkpoint

    # a resumed fit keeps whole windows of the path through time: here of 2 x 4 frames
    monkeypatch.setattr(tuning, "TUNING", replace(tuning.TUNING, path_lag=4))
    config = load_config(project)
    run_project(config, fit=False)
    monkeypatch.setattr(checkpoint, "CHECKPOINT_SECONDS", 0.0)
    seen = []

    def enough() -> bool:
        return len([e for e in seen if e.step == "fit"]) > 6

    with pytest.raises(Cancelled):
        run_project(config, anneal={"n_end": 2000}, progress=seen.append, cancel=enough)
    assert main(["fit", str(project), "--n-end", "2000"]) == 0
    out, err = capsys.readouterr()
    kept = re.search(rf"resumed an interrupted fit: (\d+) of {N_FRAMES} frames kept from its "
                     "checkpoint", out)
    assert kept and int(kept[1]) >= 4 and int(kept[1]) % 4 == 0, out
    assert (f"resumed an interrupted fit: {kept[1]} of {N_FRAMES} records kept from "
            "detections.results.csv.partial") in err


def test_sidecar_records_the_threshold_that_decided_the_statuses(tmp_path):
    from videotrack.cli import main
    from videotrack.results.files import read_results, read_sidecar

    assert main(["synth", str(tmp_path), "--frames", "10", "--sequences", "1", "--ghosts",
                 "1"]) == 0
    project = tmp_path / "project.toml"
    assert main(["run", str(project)]) == 0
    results = next(tmp_path.glob("*.results.csv"))
    threshold = read_sidecar(results)["threshold"]
    assert threshold > 0 and threshold != 10.0  # measured on the video (the defaults)
    table = read_results(results)
    failed = table.status == "failed"
    assert (table.error[failed] > threshold).all() and (table.error[~failed] <= threshold).all()
