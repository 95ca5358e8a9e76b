"""Fitting while detecting (``videotrack.workflow.streaming.FitAlongside``): ``run`` fits the
records while the next are detected when the settings allow it, and then writes what
detecting first and fitting afterwards writes; an interrupted run leaves no half-written
output and resumes; a truncated video is reported in one line."""

import shutil
import threading
from pathlib import Path

import pytest

import videotrack.workflow as pipeline
from videotrack.cli import main
from videotrack.project.config import load_config
from videotrack.workflow import Cancelled, checkpoint, not_streamable, run_project, streaming

N_FRAMES = 40
#: One answer per frame and a fixed re-analysis threshold (streamable), a short schedule.
FAST = {"profile": "paper", "n_end": 2000}
OUTPUTS = ("detections.npz", "detections.results.csv", "detections.results.csv.json")


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A synthetic project (not yet detected) whose [anneal] section is :data:`FAST`."""
    out = tmp_path_factory.mktemp("overlap") / "project"
    assert main(["synth", str(out), "--frames", str(N_FRAMES), "--sequences", "2",
                 "--noise", "2"]) == 0
    toml = out / "project.toml"
    toml.write_text(toml.read_text() + '\n[anneal]\nprofile = "paper"\nn_end = 2000\n'
                    "n_l = 200\nn_tau = 86\n")
    return out


@pytest.fixture
def project(rendered, tmp_path, capsys, monkeypatch):
    """A fresh copy of :func:`rendered`, fitted in chunks of 7 records (the last one short)."""
    monkeypatch.setattr(streaming, "STREAM_CHUNK", 7)
    capsys.readouterr()
    return Path(shutil.copytree(rendered, tmp_path / "project")) / "project.toml"


@pytest.fixture(scope="module")
def reference(rendered, tmp_path_factory):
    """The outputs of detecting first and fitting afterwards: {file name: bytes}."""
    folder = Path(shutil.copytree(rendered, tmp_path_factory.mktemp("ref") / "p"))
    config = load_config(folder / "project.toml")
    assert run_project(config, fit=False).steps == ("detect",)
    run = run_project(config)
    assert run.steps == ("fit",) and not run.overlapped
    return outputs(folder / "project.toml")


def outputs(project: Path) -> dict:
    """Every file of the project's folder: {name: bytes}."""
    return {p.name: p.read_bytes() for p in sorted(project.parent.iterdir())}


def fit_threads() -> list:
    return [t for t in threading.enumerate() if t.name == "videotrack-fit"]


def test_fitting_while_detecting_writes_what_one_after_the_other_writes(project, reference):
    config = load_config(project)
    assert not_streamable(pipeline.load_model(config)) is None
    events, notes = [], []
    run = run_project(config, progress=events.append, log=notes.append)
    assert run.overlapped and run.steps == ("detect", "fit") and run.n_frames == N_FRAMES
    assert outputs(project) == reference
    # progress as when one follows the other: every frame detected, then every record fitted
    assert [(e.step, e.done) for e in events] == [
        *(("detect", k) for k in range(1, N_FRAMES + 1)),
        *(("fit", k) for k in range(N_FRAMES + 1))]
    assert notes[1].endswith(", begun while detecting")
    assert run.fit_seconds >= run.detect_seconds > 0
    assert not fit_threads()


def test_settings_that_look_at_other_frames_detect_first(project):
    config = load_config(project)
    model = pipeline.load_model(config, profile="best", n_end=2000)
    assert "candidates > 1" in not_streamable(model)
    model = pipeline.load_model(config, candidates=1, threshold_mode="auto")
    assert "threshold_mode 'auto'" in not_streamable(model)
    run = run_project(config, anneal={"profile": "best", "n_end": 2000})
    assert run.steps == ("detect", "fit") and not run.overlapped


def test_cancel_while_detecting_leaves_nothing_and_reruns_the_same(project, reference,
                                                                  rendered):
    config = load_config(project)
    seen = []

    def enough() -> bool:  # half the video detected, several chunks handed to the fit
        return len(seen) > N_FRAMES // 2

    with pytest.raises(Cancelled):
        run_project(config, progress=seen.append, cancel=enough)
    # not a file more than before: no detections, results, checkpoint or temporary file
    assert sorted(p.name for p in project.parent.iterdir()) == sorted(
        p.name for p in rendered.iterdir())
    assert not fit_threads()
    run = run_project(config)
    assert run.overlapped and outputs(project) == reference


def test_cancel_while_fitting_keeps_a_checkpoint_and_resumes(project, reference, monkeypatch):
    monkeypatch.setattr(checkpoint, "CHECKPOINT_SECONDS", 0.0)
    config = load_config(project)
    seen = []

    def enough() -> bool:
        return len([e for e in seen if e.step == "fit"]) > 12

    with pytest.raises(Cancelled):
        run_project(config, progress=seen.append, cancel=enough)
    assert (project.parent / "detections.npz").read_bytes() == reference["detections.npz"]
    assert not (project.parent / "detections.results.csv").exists()
    assert (project.parent / "detections.results.csv.partial").exists()
    assert not fit_threads()
    run = run_project(config)
    assert run.steps == ("fit",) and run.resumed >= 10 and not run.overlapped
    assert outputs(project) == reference
    assert not list(project.parent.glob("*.partial*"))


def test_truncated_video_is_one_line_and_fitted_as_far_as_it_goes(project, capsys):
    video = project.parent / "video.avi"
    data = video.read_bytes()
    video.write_bytes(data[: len(data) * 2 // 3])
    sequential = Path(shutil.copytree(project.parent, project.parent.with_name("seq")))
    assert main(["run", str(project)]) == 3  # incomplete
    err = capsys.readouterr().err
    assert "Traceback" not in err and ", begun while detecting" in err
    lines = [ln for ln in err.splitlines() if "decoding stopped at frame" in ln]
    assert len(lines) == 1 and lines[0].startswith("videotrack: warning: ")
    run = run_project(load_config(project))
    assert run.up_to_date and 0 < run.n_frames < N_FRAMES and run.incomplete
    # the same as detecting the truncated video first and fitting afterwards
    config = load_config(sequential / "project.toml")
    run_project(config, fit=False)
    assert not run_project(config).overlapped
    assert outputs(project) == outputs(sequential / "project.toml")
    # cut before the first frame: one line naming the file, exit 1, no output
    video.write_bytes(data[:200])
    for name in OUTPUTS:
        (project.parent / name).unlink()
    before = sorted(p.name for p in project.parent.iterdir())
    assert main(["run", str(project)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(video) in err and "Traceback" not in err
    assert sorted(p.name for p in project.parent.iterdir()) == before
    assert not fit_threads()


def test_records_go_to_the_fit_in_blocks_that_fill_the_lanes(rendered):
    """Fewer records per block than the lanes of every thread take leave the streamed fit to
    the scalar kernel (2-2.5x slower); blocks that fill them once run their last runs in
    half-empty lanes, so a block fills them four times."""
    import numba

    from kinematics._kernels.lanes import LANES

    model = pipeline.load_model(load_config(rendered / "project.toml"))
    with pipeline.FitAlongside(model) as stream:
        assert stream.chunk == 4 * model.fitter().lane_frames() == \
            4 * LANES * numba.get_num_threads()
    with pipeline.FitAlongside(model, chunk=5) as stream:
        assert stream.chunk == 5
