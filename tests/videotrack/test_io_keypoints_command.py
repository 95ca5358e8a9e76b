"""``videotrack keypoints``: import, filter, summarise and write keypoint files."""

from __future__ import annotations

import numpy as np
import pytest

from tests.fixtures.keypoint_files import planted_tracks, write_analysis_h5, write_dlc_csv
from videotrack import cli
from videotrack.io.keypoints import read_keypoints, read_npz


def test_the_command_is_listed():
    assert "videotrack.commands.keypoints" in cli.COMMAND_MODULES


@pytest.fixture
def two_cameras(tmp_path):
    xy, score = planted_tracks(n=30)
    xy = 100.0 + np.arange(30)[:, None, None] * np.array([[2.0, 1.0], [0.5, 3.0], [1.0, 1.0]])
    xy[2, 1] = np.nan  # smooth tracks, one point missing
    a = write_dlc_csv(tmp_path / "left.csv", xy, score)
    xy2 = xy.copy()
    xy2[5, 0] += 300.0  # an outlier the median filter drops
    b = write_analysis_h5(tmp_path / "right.analysis.h5", xy2, score)
    return a, b, xy


def test_summary_filters_and_npz(two_cameras, tmp_path, capsys):
    a, b, xy = two_cameras
    out = tmp_path / "session.keypoints.npz"
    code = cli.main(["keypoints", str(a), str(b), "--names", "left,right", "--median", "5",
                     "--offset-threshold", "1000", "--score-threshold", "0.2",
                     "--crop-offset", "0,0", "--crop-offset", "10,5", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    lines = text.splitlines()
    assert lines[0].split() == ["camera", "frames", "first-last", "keypoints", "individual",
                                "missing", "filtered", "moved"]
    assert lines[1].split()[:5] == ["left", "30", "0-29", "3", "-"]
    assert lines[2].split()[:5] == ["right", "30", "0-29", "3", "track_0"]
    assert f"wrote {out}" in text
    cams = read_npz(out)
    assert list(cams) == ["left", "right"]
    right = cams["right"]
    assert np.isfinite(right.xy[5, 0]).all()  # offset threshold 1000: kept
    np.testing.assert_allclose(right.xy[6], xy[6] + np.array([10.0, 5.0]), equal_nan=True)
    missing = float(lines[1].split()[5].rstrip("%"))
    assert missing == pytest.approx(100 / 90, abs=0.06)


def test_median_drops_outlier_and_writes_dlc_csv_per_camera(two_cameras, tmp_path, capsys):
    a, b, _ = two_cameras
    folder = tmp_path / "filtered"
    assert cli.main(["keypoints", str(a), str(b), "--median", "5", "-o", str(folder)]) == 0
    capsys.readouterr()
    right = read_keypoints(folder / "right.csv")
    assert right.missing[5, 0] and not read_keypoints(folder / "left.csv").missing[5, 0]


def test_errors_are_one_line_and_inputs_are_never_replaced(two_cameras, tmp_path, capsys):
    a, b, _ = two_cameras
    before = a.read_bytes()
    assert cli.main(["keypoints", str(a), "-o", str(a)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "an output never replaces an input" in err
    assert a.read_bytes() == before
    assert cli.main(["keypoints", str(a), str(b), "-o", str(tmp_path / "one.csv")]) == 1
    assert "--output: one .csv holds one camera" in capsys.readouterr().err
    assert cli.main(["keypoints", str(a), "--median", "4"]) == 1
    assert "--median: must be odd" in capsys.readouterr().err
    assert cli.main(["keypoints", str(a), "--crop-offset", "1"]) == 1
    assert "--crop-offset: expected X,Y" in capsys.readouterr().err
    (tmp_path / "broken.csv").write_text("scorer,a\nbodyparts,p\ncoords,x\n0,zz\n")
    assert cli.main(["keypoints", str(tmp_path / "broken.csv")]) == 1
    err = capsys.readouterr().err
    assert err.strip() == f"videotrack: error: {tmp_path / 'broken.csv'}:4: p x: not a " \
                          "number: 'zz'"
