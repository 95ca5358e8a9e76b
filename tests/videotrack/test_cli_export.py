"""``videotrack export``: a results file into TRC and .mot that read back to the results'
numbers, one-line errors, no input overwritten."""

from __future__ import annotations

import numpy as np
import pytest

from videotrack.cli import main
from videotrack.io.mot import read_mot
from videotrack.io.trc import read_trc
from videotrack.results.files import read_results


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    root = tmp_path_factory.mktemp("export")
    assert main(["synth", str(root / "demo"), "--frames", "6", "--sequences", "1"]) == 0
    assert main(["run", str(root / "demo" / "project.toml"), "--n-end", "2000"]) == 0
    return root / "demo" / "detections.results.csv"


def test_export_writes_files_that_read_back(fitted, tmp_path, capsys):
    trc, mot = tmp_path / "walk.trc", tmp_path / "walk.mot"
    capsys.readouterr()
    assert main(["export", str(fitted), str(trc), str(mot), "--units", "px",
                 "--all-frames"]) == 0
    assert capsys.readouterr().out.count("wrote") == 2
    results = read_results(fitted)
    points, angles = read_trc(trc), read_mot(mot)
    assert points.units == "px" and points.names[: len(results.marker_names)] == tuple(
        results.marker_names)
    np.testing.assert_allclose(points.points[:, : len(results.marker_names)],
                               results.markers, atol=1e-4)
    assert angles.in_degrees and list(angles.names[-len(results.axis_labels):]) == list(
        results.axis_labels)
    np.testing.assert_allclose(angles.values[:, -len(results.axis_labels):],
                               results.angles_deg, atol=1e-4)


def test_export_errors_are_one_line_and_inputs_stay(fitted, tmp_path, capsys):
    before = fitted.read_bytes()
    capsys.readouterr()
    assert main(["export", str(fitted), str(tmp_path / "walk.xyz")]) == 1
    err = capsys.readouterr().err
    assert "walk.xyz: unknown export type '.xyz'" in err and len(err.strip().splitlines()) == 1
    # an existing file of another kind is not replaced without --force
    other = tmp_path / "notes.trc"
    other.write_text("my notes\n")
    assert main(["export", str(fitted), str(other)]) == 1
    assert other.read_text() == "my notes\n" and "notes.trc" in capsys.readouterr().err
    assert main(["export", str(tmp_path / "missing.csv"), str(tmp_path / "a.trc")]) == 1
    assert "missing.csv" in capsys.readouterr().err
    assert fitted.read_bytes() == before
