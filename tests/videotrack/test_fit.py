"""`videotrack fit` / `run`: results files, accuracy against ground truth, resume, bad input."""

import numpy as np
import pytest

from videotrack.cli import main
from videotrack.errors import VideoTrackError
from videotrack.project.config import load_config
from videotrack.results.files import read_results, read_sidecar, results_from_fit, write_results
from videotrack.results.tables import read_table


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    out = tmp_path_factory.mktemp("fitproj")
    assert main(["synth", str(out), "--frames", "16", "--sequences", "2"]) == 0
    assert main(["detect", str(out / "project.toml")]) == 0
    return out


def truth_angles(project, labels):
    cols, truth = read_table(project / "truth.csv")
    return truth[:, [cols.index(lb) for lb in labels]]


def test_run_fits_planted_postures(project, capsys):
    code = main(["run", str(project / "project.toml"), "--n-end", "7000", "--plot"])
    assert code == 0
    out = capsys.readouterr().out
    assert "fitted 16 frames" in out and "frames/s" in out
    res = read_results(project / "detections.results.csv")
    assert len(res) == 16 and set(res.status) <= {"ok", "reanalysed", "ambiguous"}
    truth = truth_angles(project, res.axis_labels)
    err = np.abs((res.angles_deg - truth + 180) % 360 - 180)
    # gamma is well determined in both views; the others within a few degrees on most frames
    assert np.median(err[:, res.axis_labels.index("J2.gamma")]) < 1.5
    assert np.median(err) < 3.0
    side = read_sidecar(project / "detections.results.csv")
    assert side["seed"] == 0 and side["anneal"]["n_end"] == 7000 and side["rows"] == 16
    assert (project / "detections.results.png").stat().st_size > 10_000
    # 3D points are the FK of the angles: the tibia tip M3 sits 77 px from J2
    d = np.linalg.norm(res.markers[:, 3] - res.joints[:, 2], axis=1)
    np.testing.assert_allclose(d, 77.0, atol=1e-9)
    assert (project / "detections.results.candidates.csv").exists()  # the default fit's


def test_candidates_file_round_trip_and_stale_removal(project, tmp_path):
    from dataclasses import replace

    from kinematics.model.chain_xml import load_body
    from videotrack.results.files import attach_candidates, frame_results, write_candidates

    fitted = project / "detections.results.csv"
    results = attach_candidates(frame_results(read_results(fitted), 0), fitted)
    assert any(len(r.candidates) for r in results.values())
    body = load_body(project / "chain.xml")
    out = write_candidates(tmp_path / "r.csv", body, list(results.values()))
    assert out.read_text() == (project / "detections.results.candidates.csv").read_text()
    # results without candidates (the paper's settings): the earlier file would not match
    assert write_candidates(tmp_path / "r.csv", body,
                            [replace(r, candidates=()) for r in results.values()]) is None
    assert not out.exists()


def test_up_to_date_results_are_not_fitted_again(project, capsys):
    csv = project / "detections.results.csv"
    before = csv.stat().st_mtime_ns
    assert main(["run", str(project / "project.toml"), "--n-end", "7000"]) == 0
    assert "is up to date (--force fits again)" in capsys.readouterr().out
    assert csv.stat().st_mtime_ns == before
    # other parameters make them stale
    assert main(["fit", str(project / "project.toml"), "--n-end", "7000", "--seed", "1"]) == 0
    assert "fitted 16 frames" in capsys.readouterr().out
    assert main(["fit", str(project / "project.toml"), "--n-end", "7000"]) == 0  # restore


def test_results_round_trip(project, tmp_path):
    res = read_results(project / "detections.results.csv")
    write_results(tmp_path / "r.csv", res, read_sidecar(project / "detections.results.csv"))
    assert (tmp_path / "r.csv").read_text() == (project / "detections.results.csv").read_text()
    again = read_results(tmp_path / "r.csv")
    np.testing.assert_array_equal(again.angles_deg, res.angles_deg)
    assert again.marker_names == ("M0", "M1", "M2", "M3")
    assert again.joint_names == ("J0", "J1", "J2")


def test_resume_after_interruption_gives_identical_file(project, tmp_path, monkeypatch):
    from videotrack import workflow as pipeline
    from videotrack.detect.detections import load_detections
    from videotrack.workflow import checkpoint

    config = load_config(project / "project.toml")
    model = pipeline.load_model(config, n_end=2000)
    det_path = project / "detections.npz"
    det = load_detections(det_path)
    full = tmp_path / "full.csv"
    pipeline.fit_project(model, det, det_path, full)
    monkeypatch.setattr(checkpoint, "CHECKPOINT_SECONDS", 0.0)
    cut = tmp_path / "cut.csv"
    seen = []

    def killer(r):
        seen.append(r.frame)
        if len(seen) == 10:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        pipeline.fit_project(model, det, det_path, cut, progress=killer)
    assert not cut.exists() and (tmp_path / "cut.csv.partial").exists()
    fitted_again = []
    pipeline.fit_project(model, det, det_path, cut, progress=lambda r: fitted_again.append(r))
    assert cut.read_text() == full.read_text()
    # the candidate postures too: the checkpoint keeps them, the path continues from it
    assert (tmp_path / "cut.candidates.csv").read_text() == (
        tmp_path / "full.candidates.csv").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "cut.candidates.csv", "cut.csv", "cut.csv.json", "full.candidates.csv", "full.csv",
        "full.csv.json"]
    assert len(fitted_again) == 16  # resumed frames are reported too


def test_fit_bad_inputs_are_one_line(project, tmp_path, capsys):
    text = (project / "project.toml").read_text()
    cases = {
        "nochain.toml": (text.replace('path = "chain.xml"', 'path = ""'), "chain.path"),
        "nocam.toml": (text.replace('camera = "top"', 'camera = "front"'), "views[1].camera"),
        "zero.toml": (text + "\n[anneal]\nn_end = 0\n", "anneal.n_end"),
    }
    for name, (body, needle) in cases.items():
        path = project / name
        path.write_text(body)
        assert main(["fit", str(path)]) == 1
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1 and "Traceback" not in err
    # detections made with other filter settings are stale
    stale = project / "stale.toml"
    stale.write_text(text.replace("value = 96", "value = 120"))
    assert main(["fit", str(stale)]) == 1
    assert "stale detections" in capsys.readouterr().err


def test_frames_without_detections_get_nan_points(locust, tmp_path):
    from kinematics.fit import FrameResult

    nan = np.full(locust.n_axes, np.nan)
    r = FrameResult(0, nan, np.nan, np.array([np.nan, np.nan]), 0, 0, 0, "no-detections",
                    np.zeros((1, 3)))
    res = results_from_fit(locust, [r], ["side", "top"])
    assert np.isnan(res.markers).all() and res.status == ("no-detections",)
    assert not res.ok_mask()[0]
    write_results(tmp_path / "r.csv", res, {"markers": 4})
    back = read_results(tmp_path / "r.csv")
    assert back.status == ("no-detections",) and np.isnan(back.angles_deg).all()
    with pytest.raises(VideoTrackError, match="not a VideoTrack results file"):
        (tmp_path / "x.csv").write_text("a,b\n1,2\n")
        read_results(tmp_path / "x.csv")


def test_frames_beyond_the_detections_are_refused_or_said(project, tmp_path, capsys):
    # 16 records: a range past them all is a one-line error (it was "internal error"), a
    # range running past the end fits what there is and says so
    code = main(["fit", str(project / "project.toml"), "--frames", "500:600",
                 "--results", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err
    assert code == 1 and "500:600 selects no record" in err and "16 records" in err
    assert "internal error" not in err and not (tmp_path / "x.csv").exists()
    code = main(["fit", str(project / "project.toml"), "--frames", "14:40", "--n-end", "500",
                 "--results", str(tmp_path / "y.csv")])
    err = capsys.readouterr().err
    assert code == 0 and "frames 14:40: the detections have 16 records; fitting 14:16" in err
    assert len(read_results(tmp_path / "y.csv")) == 2


def test_results_and_candidates_are_one_set(project, tmp_path, capsys):
    # a candidates file lost (a full disk cut the writes) makes the set stale: fitted again,
    # where the results alone used to read "up to date"
    import shutil

    folder = tmp_path / "p"
    shutil.copytree(project, folder)
    cfg = str(folder / "project.toml")
    assert main(["fit", cfg, "--n-end", "7000", "--force"]) == 0
    candidates = folder / "detections.results.candidates.csv"
    assert candidates.exists() and read_sidecar(folder / "detections.results.csv")[
        "candidates_sha256"]
    capsys.readouterr()
    assert main(["fit", cfg, "--n-end", "7000"]) == 0
    assert "is up to date" in capsys.readouterr().out
    candidates.unlink()
    assert main(["fit", cfg, "--n-end", "7000"]) == 0
    out = capsys.readouterr()
    assert "is up to date" not in out.out and "candidates file does not match" in out.err
    assert candidates.exists()
