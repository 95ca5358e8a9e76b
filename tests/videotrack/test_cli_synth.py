"""`videotrack synth` end to end: files written, ground truth consistent, bad input one line."""

import cv2
import numpy as np

from videotrack.cli import main
from videotrack.results.tables import read_table


def test_synth_writes_a_detect_ready_project(tmp_path, capsys):
    out = tmp_path / "proj"
    code = main(["synth", str(out), "--frames", "8", "--sequences", "2", "--noise", "2",
                 "--ghosts", "1", "--seed", "3"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "wrote 8 frames" in printed and "videotrack detect" in printed
    names = sorted(p.name for p in out.iterdir())
    assert names == ["cameras.toml", "chain.xml", "project.toml", "truth.csv", "video.avi"]
    cap = cv2.VideoCapture(str(out / "video.avi"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 8
    assert int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)) == 720
    cols, truth = read_table(out / "truth.csv")
    assert truth.shape[0] == 8 and "top.M3.u" in cols
    # the same seeds give the same video
    main(["synth", str(tmp_path / "again"), "--frames", "8", "--sequences", "2", "--noise", "2",
          "--ghosts", "1", "--seed", "3"])
    a, b = cv2.VideoCapture(str(out / "video.avi")), cv2.VideoCapture(
        str(tmp_path / "again" / "video.avi"))
    for _ in range(8):
        np.testing.assert_array_equal(a.read()[1], b.read()[1])


def test_synth_interlaced_separate_png(tmp_path):
    out = tmp_path / "p"
    assert main(["synth", str(out), "--frames", "6", "--sequences", "1", "--interlaced",
                 "--layout", "separate", "--codec", "png"]) == 0
    assert sorted(p.name for p in out.glob("video_*")) == ["video_side_png", "video_top_png"]
    assert len(list((out / "video_side_png").iterdir())) == 3  # 6 fields = 3 frames
    assert 'deinterlace = "fields"' in (out / "project.toml").read_text()


def test_synth_bad_input_is_one_line(tmp_path, capsys):
    assert main(["synth", str(tmp_path / "x"), "--occlusions", "2"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "occlusion_fraction" in err and "Traceback" not in err
    assert not (tmp_path / "x" / "video.avi").exists()
    bad = tmp_path / "angles.csv"
    bad.write_text("J0.phi,J0.psi\n1,2\n")
    assert main(["synth", str(tmp_path / "y"), "--angles", str(bad)]) == 1
    assert "no column for axis J0.alpha" in capsys.readouterr().err
