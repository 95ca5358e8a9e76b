"""``videotrack eval``: angle errors wrapped, sums, locked axes, 3D errors, tables and CSV."""

import csv

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from videotrack.cli import main
from videotrack.errors import VideoTrackError
from videotrack.results.evaluate import evaluate, evaluation_csv, parse_sum, wrap_deg
from videotrack.results.files import Results, write_results
from videotrack.results.tables import write_table

AXES = ("J0.phi", "J0.psi", "J1.rx", "J1.beta")  # J1.rx: a locked axis


def make_results(angles, markers, joints, frames=None) -> Results:
    n = len(angles)
    frames = np.arange(n) if frames is None else np.asarray(frames)
    return Results(
        axis_labels=AXES, view_names=("side",), chain_names=("leg",), marker_names=("M0",),
        joint_names=("J1",), frames=frames, video_frames=frames, fields=np.full(n, -1),
        times=frames / 50.0, angles_deg=np.asarray(angles, float), error=np.ones(n),
        error_per_view=np.ones((n, 1)), runs=np.ones(n, np.int64),
        iterations=np.full(n, 100), status=("ok",) * n, roots=np.zeros((n, 1, 3)),
        markers=np.asarray(markers, float), joints=np.asarray(joints, float))


def truth_table(angles, markers, joints):
    """Columns as synth writes them: frame, axes, then points."""
    cols = ["frame", *AXES, "M0.x", "M0.y", "M0.z", "J1.x", "J1.y", "J1.z"]
    n = len(angles)
    values = np.column_stack([np.arange(n), angles, np.reshape(markers, (n, 3)),
                              np.reshape(joints, (n, 3))])
    return cols, values


@pytest.fixture
def case():
    rng = np.random.default_rng(0)
    n = 20
    true = np.column_stack([rng.uniform(170, 190, n), rng.uniform(-10, 10, n), np.zeros(n),
                            rng.uniform(0, 40, n)])
    err = np.column_stack([np.full(n, 2.0), np.linspace(-3, 3, n), np.zeros(n),
                           np.full(n, -1.0)])
    err[0, 0] = 12.0  # one frame off by more than the threshold
    t_markers, t_joints = rng.normal(size=(n, 1, 3)), rng.normal(size=(n, 1, 3))
    shift = np.array([3.0, 4.0, 0.0])  # 5 units off in 3D
    fit = make_results(true + err, t_markers + shift, t_joints)
    return fit, truth_table(true, t_markers, t_joints), err


def test_errors_per_axis_sum_and_point(case):
    fit, (cols, truth), err = case
    ev = evaluate(fit, cols, truth, sums=["J0.phi+J1.beta"], threshold_deg=5.0)
    assert [r.name for r in ev.rows] == ["J0.phi", "J0.psi", "J1.beta", "J0.phi+J1.beta",
                                         "M0", "J1"]  # the locked J1.rx is left out
    phi = ev.row("J0.phi")
    assert phi.rmse == pytest.approx(np.sqrt(np.mean(err[:, 0] ** 2)))
    assert phi.median == pytest.approx(2.0) and phi.max == pytest.approx(12.0)
    assert phi.over == pytest.approx(100 / 20)
    assert ev.row("J0.psi").median == pytest.approx(np.median(np.abs(err[:, 1])))
    assert ev.row("J0.phi+J1.beta").median == pytest.approx(1.0)
    assert ev.row("M0").rmse == pytest.approx(5.0) and ev.row("J1").max == pytest.approx(0)
    assert ev.n_scored == 20 and ev.frames_over == pytest.approx(5.0)


def test_angles_wrap_and_unfitted_frames_are_counted(case):
    fit, (cols, truth), _ = case
    angles = fit.angles_deg.copy()
    truth = truth.copy()
    truth[:, 1] = 179.0
    angles[:, 0] = -179.5  # 1.5 degrees from 179 across the wrap
    angles[3] = np.nan  # no detections in frame 3
    res = make_results(angles, fit.markers, fit.joints, frames=np.arange(20) + 5)
    ev = evaluate(res, cols, truth)
    assert ev.row("J0.phi").max == pytest.approx(1.5)
    # frames 20..24 have no truth; frame 8 (row 3) has no fit
    assert (ev.n_frames, ev.n_scored, ev.unmatched) == (15, 14, 5)


@given(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4))
def test_wrap_is_the_shortest_signed_angle(a, b):
    d = float(wrap_deg(a - b))
    assert -180 <= d < 180
    assert abs((d - (a - b)) / 360 - round((d - (a - b)) / 360)) < 1e-6


def test_sum_syntax():
    labels = ["J0.alpha", "J1.beta", "coxa-femur.gamma", "coxa.gamma"]
    np.testing.assert_array_equal(parse_sum("J0.alpha+J1.beta", labels), [1, 1, 0, 0])
    np.testing.assert_array_equal(parse_sum("-J0.alpha - coxa-femur.gamma", labels),
                                  [-1, 0, -1, 0])
    for bad in ("J0.alpha+", "J0.alpha*2", "J2.gamma", ""):
        with pytest.raises(VideoTrackError, match="--sum"):
            parse_sum(bad, labels)


def test_cli_table_csv_and_errors(case, tmp_path, capsys):
    fit, (cols, truth), _ = case
    write_results(tmp_path / "r.csv", fit, {"markers": 1})
    write_table(tmp_path / "truth.csv", cols, truth)
    out_csv = tmp_path / "errors.csv"
    code = main(["eval", str(tmp_path / "r.csv"), str(tmp_path / "truth.csv"), "--sum",
                 "J0.phi+J1.beta", "--threshold", "2.5", "--csv", str(out_csv)])
    out = capsys.readouterr().out
    assert code == 0 and "RMSE (°)" in out and "J0.phi+J1.beta" in out and "M0" in out
    assert "off by more than 2.5°" in out and f"wrote {out_csv}" in out
    rows = list(csv.DictReader(out_csv.open()))
    assert [r["quantity"] for r in rows][:3] == ["J0.phi", "J0.psi", "J1.beta"]
    assert float(rows[0]["median_abs"]) == pytest.approx(2.0)
    assert rows[-1]["kind"] == "point" and rows[-1]["over_threshold_pct"] == ""
    ev = evaluate(fit, cols, truth)
    assert evaluation_csv(ev).splitlines()[0].startswith("quantity,kind,frames,rmse")
    for args, needle in ((["--sum", "J9.x"], "--sum: 'J9.x': no axis named like"),
                         (["--threshold", "-1"], "--threshold: must be a number >= 0")):
        assert main(["eval", str(tmp_path / "r.csv"), str(tmp_path / "truth.csv"),
                     *args]) == 1
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    assert main(["eval", str(tmp_path / "r.csv"), str(tmp_path / "bad.csv")]) == 1
    assert "bad.csv: frame: the truth table needs a 'frame' column" in capsys.readouterr().err
