"""A many-limbed body in several pinhole views through the whole pipeline: `videotrack run`
matches its markers in 3D by default (match 'auto') and fits the planted movement."""

import numpy as np

from kinematics.cameras import PinholeCamera
from kinematics.model.chain_xml import loads_body
from tests.fixtures.bodies import LEG_XML
from tests.fixtures.cameras import four_cameras
from tests.fixtures.projects import cluttered_leg_project
from videotrack.cli import main
from videotrack.detect.detections import load_detections
from videotrack.project.config import load_config
from videotrack.results.files import read_results, read_sidecar
from videotrack.results.tables import read_table
from videotrack.synth.project import SynthOptions, write_synthetic_project
from videotrack.workflow import load_model, not_streamable

CHAIN = ('<body name="two-legs" units="mm" format="1">' + "".join(
    f'<chain name="{n}"><root mode="fixed" position="{x} 0 0"/>{LEG_XML.format(n=n)}</chain>'
    for n, x in (("front", 3), ("hind", -3))) + "</body>")


def test_run_matches_a_two_legged_body_in_3d(tmp_path, capsys):
    body = loads_body(CHAIN)
    cams = four_cameras()
    angles = np.array([[15 * np.sin(f / 4), 0, 20, 0, 0, -60,
                        -15 * np.sin(f / 4), 0, 10, 0, 0, -80] for f in range(8)])
    write_synthetic_project(tmp_path, body, CHAIN, cams, angles,
                            SynthOptions(layout="separate", seed=1))
    assert main(["run", str(tmp_path / "project.toml"), "--n-end", "3000"]) == 0
    res = read_results(tmp_path / "detections.results.csv")
    side = read_sidecar(tmp_path / "detections.results.csv")
    assert side["anneal"]["match"] == "auto" and side["anneal"]["start_samples"] is None
    assert load_model(load_config(tmp_path / "project.toml")).fitter().match_for(
        load_detections(tmp_path / "detections.npz")) == "3d"
    cols, truth = read_table(tmp_path / "truth.csv")
    want = truth[:, [cols.index(lb) for lb in res.axis_labels]]
    err = np.abs((res.angles_deg - want + 180) % 360 - 180)
    assert np.median(err) < 1.0 and err.max() < 5.0, err
    assert set(res.status) <= {"ok", "reanalysed", "ambiguous"}


def test_run_matches_a_leg_among_ghosts_in_3d(tmp_path, capsys):
    """A single chain whose views hold three detections per marker image: 'auto' matches it
    in 3D, decided on the whole video, and fits the planted movement."""
    cluttered_leg_project(tmp_path)
    assert main(["run", str(tmp_path / "project.toml"), "--n-end", "3000"]) == 0
    assert "markers matched in 3D (match 'auto'): 3.0 detections per marker image" in (
        capsys.readouterr().err)
    fitter = load_model(load_config(tmp_path / "project.toml")).fitter()
    det = load_detections(tmp_path / "detections.npz")
    assert det.counts().sum() >= 3 * 8 * 4 * 2 - 8 and fitter.match_for(det) == "3d"
    res = read_results(tmp_path / "detections.results.csv")
    cols, truth = read_table(tmp_path / "truth.csv")
    want = truth[:, [cols.index(lb) for lb in res.axis_labels]]
    err = np.abs((res.angles_deg - want + 180) % 360 - 180)
    assert np.median(err) < 1.0 and err.max() < 5.0, err


def test_a_video_whose_match_is_decided_on_its_detections_is_detected_before_the_fit(
        tmp_path):
    cluttered_leg_project(tmp_path)
    config = load_config(tmp_path / "project.toml")
    model = load_model(config, candidates=1, threshold_mode="absolute")
    assert "match 'auto'" in not_streamable(model)
    assert not_streamable(load_model(config, candidates=1, threshold_mode="absolute",
                                     match="views", noise_px=0.5)) is None


def test_a_match_decided_by_the_caller_is_not_decided_again(tmp_path):
    """``fit_project(match=...)`` fits with the match its caller decided (and printed), and
    the sidecar keeps the project's 'auto'."""
    from videotrack import workflow as pipeline

    cluttered_leg_project(tmp_path)
    model = load_model(load_config(tmp_path / "project.toml"), n_end=2000)
    det_path = tmp_path / "detections.npz"
    assert main(["detect", str(tmp_path / "project.toml")]) == 0
    det = load_detections(det_path)
    fits = {m: pipeline.fit_project(model, det, det_path, tmp_path / f"{m}.results.csv",
                                    match=None if m == "auto" else m)
            for m in ("auto", "3d", "views")}
    assert list(fits["auto"].error) == list(fits["3d"].error)  # 'auto' decided 3D itself
    assert list(fits["views"].error) != list(fits["3d"].error)  # E per view: another sum
    assert read_sidecar(tmp_path / "views.results.csv")["anneal"]["match"] == "auto"


def test_frames_with_detections_but_no_3d_point_are_named():
    """A frame whose markers only two views see has no 3D point: the fit warns by name
    instead of reporting a frame without detections and nothing else."""
    from kinematics.fit import AnnealParams, Fitter
    from kinematics.model.fk import forward_kinematics
    from videotrack.detect.detections import build_detections
    from videotrack.results.files import results_from_fit
    from videotrack.workflow import fit_warnings

    body = loads_body(CHAIN)
    k = [[900.0, 0, 320], [0, 900.0, 240], [0, 0, 1]]
    cams = {f"cam{i}": PinholeCamera(f"cam{i}", k, rvec=[0.5, yaw, 0], t=[0, 0, 120])
            for i, yaw in enumerate((-0.9, -0.3, 0.3, 0.9))}
    markers = forward_kinematics(body, np.zeros((3, body.n_axes)) + [0, 0, 20, 0, 0, -60] * 2
                                 ).markers
    records = [[(c.project(m), np.ones(len(m), np.int64)) for c in cams.values()]
               for m in markers]
    for v in (2, 3):  # record 1: seen by two views only
        records[1][v] = (np.empty((0, 2)), np.empty(0, np.int64))
    meta = {"view_names": list(cams), "videos": [{"fps": 50.0}],
            "settings": {"deinterlace": {"field_order": "top"}}}
    det = build_detections(records, [0, 1, 2], [-1, -1, -1], meta)
    res = Fitter(body, cams, AnnealParams().with_schedule(500)).fit(
        [[det.points_of(r, v) for v in range(4)] for r in range(3)])
    assert [r.status != "no-detections" for r in res] == [True, False, True]
    warnings = fit_warnings(results_from_fit(body, res, list(cams), det), det)
    assert any("1 frame(s) have detections but no 3D point (video frames 1)" in w
               and 'match = "views"' in w for w in warnings), warnings
