"""``videotrack batch``: skip, force, dry run, failures, parallel and Dask runs equal to local,
atomic outputs, and resuming after kill -9 with byte-identical results."""

import csv
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from videotrack.batch import TrialReport, plan_trial, project_lock, run_trial
from videotrack.cli import main
from videotrack.errors import VideoTrackError
from videotrack.project.folders import open_project
from videotrack.synth.paper_setup import write_example_project

#: A short schedule in the paper's proportions (N_end / N_l = 10, N_end / N_tau = 23).
# the paper's settings: these tests are about the orchestration, not the fit
ANNEAL = {"profile": "paper", "n_end": 2000, "n_l": 200, "n_tau": 86}
TRIALS = ["session1/trial01", "session1/trial02", "session2/trial01"]
INPUTS = {"video.avi", "truth.csv", "config.toml"}


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    root = tmp_path_factory.mktemp("rendered") / "project"
    write_example_project(root, TRIALS, frames=24, anneal=ANNEAL)
    return root


@pytest.fixture
def project(rendered, tmp_path):
    """A fresh copy of the rendered project (inputs only)."""
    return Path(shutil.copytree(rendered, tmp_path / "project"))


def outputs(root: Path) -> dict[str, bytes]:
    """Every file a batch wrote into the trial folders, by path relative to the project."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.parent != root and p.parent.name != "logs"
            and p.name not in INPUTS}


def strays(root: Path) -> list[str]:
    return sorted(p.name for p in root.rglob("*") if p.name.startswith(".")
                  or ".partial" in p.name)


def summary(root: Path) -> list[dict]:
    return list(csv.DictReader((root / "summary.csv").open()))


def last_log(root: Path) -> str:
    return max((root / "logs").iterdir(), key=lambda p: p.stat().st_mtime_ns).read_text()


def batch(capsys, root, *args):
    code = main(["batch", str(root), *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_batch_runs_then_skips_and_forces(project, capsys):
    code, out, err = batch(capsys, project, "--jobs", "1")
    assert code == 0, err
    rows = summary(project)
    assert [r["trial"] for r in rows] == TRIALS
    assert all(r["state"] == "done" and r["frames"] == "24" for r in rows)
    assert all(0 < float(r["median_error_px"]) < 10 and float(r["bad_frames_pct"]) == 0
               for r in rows)
    assert "3 trials: 3 done; wrote" in out and "session2/trial01" in out
    files = outputs(project)
    assert sorted(Path(k).name for k in files if k.startswith("session1/trial01")) == [
        "video.detections.npz", "video.results.csv", "video.results.csv.json"]
    logs = list((project / "logs").glob("batch-*.log"))
    assert len(logs) == 1 and "session1/trial01: done (detect, fit)" in logs[0].read_text()
    mtimes = {p: p.stat().st_mtime_ns for p in project.rglob("video.*")}

    code, out, _ = batch(capsys, project, "--jobs", "1")
    assert code == 0 and "3 up to date" in out and "no log (nothing to do)" in out
    assert {p: p.stat().st_mtime_ns for p in project.rglob("video.*")} == mtimes

    # a changed parameter makes only that trial stale; the dry run says why, writes nothing
    (project / "session2" / "config.toml").write_text("[anneal]\nseed = 5\n")
    code, out, _ = batch(capsys, project, "--dry-run")
    lines = {line.split()[0]: line for line in out.splitlines() if "/" in line}
    assert "up to date" in lines["session1/trial01"]
    assert "fit" in lines["session2/trial01"] and "changed: seed, anneal" in out
    assert len(list((project / "logs").iterdir())) == 1 and outputs(project) == files
    assert all(len(line) < 100 for line in out.splitlines())  # rows are not padded

    code, out, _ = batch(capsys, project, "--jobs", "1", "--trial", "session1/*", "--force")
    assert code == 0 and "2 done" in out
    rows = summary(project)  # the other trial's row is kept, not dropped
    assert [(r["trial"], r["state"]) for r in rows] == [
        ("session1/trial01", "done"), ("session1/trial02", "done"),
        ("session2/trial01", "up to date")]
    assert outputs(project) == files  # recomputed, identical


def test_batch_equals_the_single_trial_commands(project, capsys):
    assert batch(capsys, project, "--jobs", "1")[0] == 0
    files = outputs(project)
    results = project / "session1" / "trial02" / "video.results.csv"
    assert main(["run", str(project), "--trial", "session1/trial02", "--force"]) == 0
    assert results.read_bytes() == files["session1/trial02/video.results.csv"]


def test_jobs_and_dask_give_the_same_outputs(project, capsys):
    from dask.distributed import LocalCluster

    assert batch(capsys, project, "--jobs", "1")[0] == 0
    local = outputs(project)
    code, out, err = batch(capsys, project, "--jobs", "2", "--force")
    assert code == 0, err
    assert "3 done" in out and outputs(project) == local
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster:
        code, out, err = batch(capsys, project, "--force", "--scheduler",
                               cluster.scheduler_address)
    assert code == 0, err
    assert "3 done" in out and outputs(project) == local
    log = last_log(project)
    assert f"on Dask cluster {cluster.scheduler_address}" in log


def test_a_failing_trial_does_not_stop_the_others(project, capsys):
    (project / "session1" / "trial02" / "video.avi").write_bytes(b"\0" * 4000)
    bad_config = project / "session2" / "trial01" / "config.toml"
    bad_config.write_text("[anneal]\nn_ed = 3\n")
    code, out, _ = batch(capsys, project, "--dry-run")  # rows not padded to the longest why
    assert code == 0 and "fails" in out and all(line == line.rstrip()
                                                for line in out.splitlines())
    code, out, err = batch(capsys, project, "--jobs", "1")
    assert code == 1
    rows = {r["trial"]: r for r in summary(project)}
    assert rows["session1/trial01"]["state"] == "done"
    assert rows["session1/trial02"]["state"] == "failed"
    assert "video.avi: cannot open as a video" in rows["session1/trial02"]["message"]
    assert rows["session2/trial01"]["message"].startswith(
        f"{bad_config}: anneal.n_ed: unknown key 'n_ed'")
    assert "1 done, 2 failed" in out and "failed:\n  session1/trial02:" in out
    assert err.count("failed:") == 2 and "Traceback" not in err
    assert not list((project / "session1" / "trial02").glob("*.npz"))


def test_run_trial_reports_unexpected_errors(project, monkeypatch):
    import videotrack.workflow.run

    def boom(*args, **kwargs):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(videotrack.workflow.run, "fit_project", boom)
    trial = open_project(project).trials[0]
    report = run_trial(trial)
    assert isinstance(report, TrialReport) and report.state == "failed"
    assert report.message == "ZeroDivisionError: a bug"
    assert any("Traceback" in line for line in report.log)
    assert plan_trial(trial) == ("fit", "no results yet")  # the detections were kept


def test_stale_pairs_and_stray_temporaries(project, capsys):
    assert batch(capsys, project, "--jobs", "1")[0] == 0
    folder = project / "session1" / "trial01"
    tmp = folder / ".video.results.csv.k2j4.tmp"
    tmp.write_text("half a file")
    results = folder / "video.results.csv"
    good = results.read_bytes()
    # a CSV that is not the one its sidecar describes (a write cut between the two)
    results.write_text(results.read_text().replace(",ok,", ",failed,", 1))
    trial = open_project(project).trials[0]
    assert plan_trial(trial) == ("fit", "the results file does not match its sidecar")
    code, out, _ = batch(capsys, project, "--jobs", "1")
    assert code == 0 and "1 done, 2 up to date" in out
    assert results.read_bytes() == good and not tmp.exists() and strays(project) == []
    log = last_log(project)
    assert "removed .video.results.csv.k2j4.tmp, left by an interrupted run" in log


def test_one_batch_at_a_time(project, capsys):
    with project_lock(open_project(project)):
        code, _, err = batch(capsys, project)
    assert code == 1 and "another 'videotrack batch' is running on this project" in err


KILLER = textwrap.dedent("""\
    # Runs a batch that stops (sleeps) at an interruption point and says so in a file, so
    # the test can kill -9 it exactly there.
    import contextlib, sys, time
    from pathlib import Path
    import kinematics.fileio as fileio
    import videotrack.workflow.checkpoint as pipeline
    project, mark, point = sys.argv[1:4]

    def stop_here():
        Path(mark).touch()
        time.sleep(120)

    if point == "checkpoint":  # after the first checkpoint of the second trial's fit
        pipeline.CHECKPOINT_SECONDS = 0.0
        checkpoint = pipeline._checkpoint

        def stopping_checkpoint(partial, *args):
            checkpoint(partial, *args)
            if "trial02" in str(partial):
                stop_here()

        pipeline._checkpoint = stopping_checkpoint
    else:  # in the middle of writing the first trial's results file
        write = fileio.atomic_write

        @contextlib.contextmanager
        def stopping_write(path, mode="w", **kwargs):
            with write(path, mode, **kwargs) as fh:
                yield fh
                if str(path).endswith("trial01/video.results.csv"):
                    fh.flush()
                    stop_here()

        fileio.atomic_write = stopping_write
    from videotrack.cli import main
    sys.exit(main(["batch", project, "--jobs", "1"]))
    """)


@pytest.mark.parametrize("point", ["checkpoint", "results-write"])
def test_kill_9_and_resume_gives_identical_outputs(project, tmp_path, capsys, point):
    # interrupted runs are compared with an uninterrupted one in the same folder
    assert batch(capsys, project, "--jobs", "1")[0] == 0
    reference = outputs(project)
    for path in reference:
        (project / path).unlink()
    script, mark = tmp_path / "killer.py", tmp_path / "stopped"
    script.write_text(KILLER)
    proc = subprocess.Popen([sys.executable, str(script), str(project), str(mark), point],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not mark.exists():
        assert proc.poll() is None, proc.stderr.read().decode()
        assert time.monotonic() < deadline, "the batch never reached the interruption point"
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    proc.stderr.close()
    trial01 = project / "session1" / "trial01"
    if point == "checkpoint":  # trial 1 finished, trial 2 has a checkpoint and no results
        assert (trial01 / "video.results.csv").exists()
        assert (project / "session1" / "trial02" / "video.results.csv.partial").exists()
        assert not (project / "session1" / "trial02" / "video.results.csv").exists()
    else:  # the results file is half written: only its temporary file exists
        assert not (trial01 / "video.results.csv").exists()
        assert list(trial01.glob(".video.results.csv.*.tmp"))

    code, _, err = batch(capsys, project, "--jobs", "1")
    assert code == 0, err
    assert outputs(project) == reference
    assert strays(project) == []


def test_help_teaches(capsys):
    for command, needles in (("batch", ("--scheduler", "examples:", "config.toml")),
                             ("demo", ("--frames", "Table 2", "examples:")),
                             ("eval", ("--sum", "examples:", "truth.csv"))):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        out = capsys.readouterr().out
        assert all(n in out for n in needles), command


def test_bad_arguments_are_one_line(project, capsys, monkeypatch):
    import videotrack.batch
    import videotrack.batch_dask

    connect = videotrack.batch.connect  # a scheduler file is waited for: not that long here
    monkeypatch.setattr(videotrack.batch_dask, "connect", lambda address: connect(address, 0.2))
    for args, needle in ((["--jobs", "-1"], "--jobs: must be at least 0"),
                         (["--trial", "nope/*"], "no trial matches 'nope/*'"),
                         (["--scheduler", str(project / "sched.json")],
                          "--scheduler: no scheduler file after 0.2 s")):
        code, _, err = batch(capsys, project, *args)
        assert code == 1 and needle in err and err.count("\n") == 1, err
    with pytest.raises(VideoTrackError):
        open_project(project / "session1")


def test_a_finished_project_on_read_only_storage_can_be_checked(project, capsys):
    # batch and fit find everything up to date and write nothing (they wrote a log and a
    # checkpoint's removal before, and failed); needs a user the permissions bind (not root)
    assert batch(capsys, project, "--jobs", "1")[0] == 0
    before = {p: p.stat().st_mtime_ns for p in project.rglob("*")}
    folders = [project, *(p for p in project.rglob("*") if p.is_dir())]
    for folder in folders:
        folder.chmod(0o555)
    try:
        if os.access(project, os.W_OK):
            pytest.skip("this user can write to read-only folders (root)")
        code, out, err = batch(capsys, project)
        assert code == 0, err
        assert "3 up to date; no summary (read-only storage); no log" in out
        assert main(["fit", str(project), "--trial", "session1/trial01"]) == 0
        assert "up to date" in capsys.readouterr().out
    finally:
        for folder in folders:
            folder.chmod(0o755)
    assert {p: p.stat().st_mtime_ns for p in project.rglob("*")} == before
