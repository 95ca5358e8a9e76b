"""``videotrack demo``: the paper's test end to end, its Table 2 and throughput output."""

import re

from videotrack.cli import main
from videotrack.results.files import read_results
from videotrack.synth.paper_setup import TABLE2_BOTH_VIEWS


def table_row(out: str, label: str) -> list[float]:
    line = next(line for line in out.splitlines() if line.startswith(label))
    return [float(x) for x in line[len(label):].split()]


def test_demo_prints_table2_and_keeps_files(tmp_path, capsys):
    out_dir = tmp_path / "demo"
    assert main(["demo", "--out", str(out_dir), "--frames", "40", "--n-end", "3500",
                 "--plot"]) == 0
    out = capsys.readouterr().out
    assert "φ     ψ     α     β   α+β     γ" in out
    assert table_row(out, "RMSE, the paper") == list(TABLE2_BOTH_VIEWS.values())
    rmse = table_row(out, "RMSE, this run")
    assert len(rmse) == 6 and max(rmse) < 15 and rmse[5] < 3  # γ is well determined
    assert re.search(r"fitted 40 frames in [\d.]+ s \(\d+ frames/s on \d+ threads, N_end "
                     r"3500; the paper: 0.4\)", out)
    assert re.search(r"40 frames analysed in [\d.]+ s: \d+ frames/s end to end", out)
    assert read_results(out_dir / "detections.results.csv").angles_deg.shape == (40, 9)
    assert (out_dir / "angles.png").stat().st_size > 10_000
    assert (out_dir / "truth.csv").exists() and (out_dir / "project.toml").exists()
    assert "videotrack eval" in out  # says what to do next


def test_demo_with_temp_leaves_nothing(tmp_path, capsys, monkeypatch):
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--temp", "--frames", "12", "--n-end", "1000"]) == 0
    assert "RMSE, this run" in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []
    assert main(["demo", "--frames", "0"]) == 1
    assert "--frames: must be at least 1" in capsys.readouterr().err
