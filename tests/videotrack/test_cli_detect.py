"""``videotrack detect`` end to end: output, summary, freshness, and one-line errors."""

import numpy as np
import pytest

from videotrack.cli import main
from videotrack.detect.detections import load_detections
from videotrack.detect.views import View


def run(capsys, *args):
    code = main(["detect", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_detect_writes_detections_and_a_summary(project, capsys):
    config, _, right = project
    code, out, err = run(capsys, config)
    assert code == 0, err
    target = config.parent / "scene.detections.npz"
    assert f"wrote {target}" in out
    assert "markers per view per frame (12 frames from frames 0:12, 25 per second)" in out
    lines = out.splitlines()
    assert lines[1].split() == ["view", "records", "min", "median", "max", "empty"]
    assert lines[3].split() == ["left", "12", "3", "3", "3", "0"]
    det = load_detections(target)
    right_view = View("right", (80, 0, 80, 60), flip_x=True)
    np.testing.assert_allclose(np.sort(right_view.to_frame(det.points_of(7, "right")), axis=0),
                               np.sort(right[7], axis=0), atol=0.1)

    code, out, _ = run(capsys, config)
    assert code == 0 and "is up to date" in out
    mtime = target.stat().st_mtime_ns
    code, out, _ = run(capsys, config, "--force")
    assert code == 0 and "wrote" in out and target.stat().st_mtime_ns >= mtime
    code, out, err = run(capsys, config, "--frames", "2:5", "-o", config.parent / "part.npz")
    assert code == 0 and "(3 frames from frames 2:5" in out
    assert load_detections(config.parent / "part.npz").video_frames.tolist() == [2, 3, 4]


def test_changed_settings_are_detected_again(project, capsys):
    config, _, _ = project
    assert run(capsys, config)[0] == 0
    config.write_text(config.read_text().replace("value = 90", "value = 95"))
    code, out, err = run(capsys, config)
    assert code == 0 and "out of date" in err and "filters" in err and "wrote" in out


def test_help_teaches(capsys):
    with pytest.raises(SystemExit):
        main(["detect", "--help"])
    out = capsys.readouterr().out
    assert "examples:" in out and "[[filters.steps]]" in out and "--frames A:B" in out


@pytest.mark.parametrize("edit, message", [
    (("roi = [80, 0, 80, 60]", "roi = [100, 0, 80, 60]"),
     "project.toml: views[1].roi: ROI [x=100, y=0, w=80, h=60] reaches outside the 160x60"),
    (("value = 90", "value = 900"), "project.toml: filters.steps[0].value: must be at most 254"),
    (("min_area = 3", "min_area = 3\nmin_aera = 4"), "project.toml: markers.min_aera: unknown key"),
    (('path = "scene.avi"', 'path = "missing.avi"'), "missing.avi: no such file or folder"),
    (('path = "scene.avi"', 'path = "junk.avi"'), "junk.avi: cannot open as a video"),
    (('path = "scene.avi"', 'path = "scene.avi"\nframes = "50:60"'),
     "project.toml: video.frames: frame range starts at 50"),
])
def test_bad_input_is_one_line_and_writes_nothing(project, capsys, edit, message):
    config, _, _ = project
    (config.parent / "junk.avi").write_bytes(b"\0" * 5000)
    config.write_text(config.read_text().replace(*edit))
    code, _, err = run(capsys, config)
    assert code == 1 and message in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not list(config.parent.glob("*.npz")) and not list(config.parent.glob(".*.tmp"))


def test_other_files_are_not_overwritten_unasked(project, capsys):
    config, _, _ = project
    code, _, err = run(capsys, config, "-o", config)  # an input: never, not even --force
    assert code == 1 and "--output: is a config file of this run" in err
    assert run(capsys, config, "-o", config, "--force")[0] == 1
    assert config.read_text().startswith("[video]")
    other = config.parent / "notes.txt"
    other.write_text("my notes\n")
    code, _, err = run(capsys, config, "-o", other)
    assert code == 1 and "not a detections file" in err and "(--force does)" in err
    assert other.read_text() == "my notes\n"


def test_missing_config_and_bad_frames_option(tmp_path, project, capsys):
    code, _, err = run(capsys, tmp_path / "none.toml")
    assert code == 1 and "none.toml: no such config file" in err
    code, _, err = run(capsys, project[0], "--frames", "7")
    assert code == 1 and "--frames: frame range must look like" in err


def test_truncated_video_is_reported_and_kept(project, capsys):
    config, _, _ = project
    video = config.parent / "scene.avi"
    data = video.read_bytes()
    video.write_bytes(data[: len(data) * 2 // 3])
    code, _, err = run(capsys, config)
    assert code == 0
    assert "videotrack: warning:" in err and "decoding stopped at frame" in err
    det = load_detections(config.parent / "scene.detections.npz")
    assert 0 < det.n_records < 12 and det.metadata["broken_at"] == det.n_records
    assert run(capsys, config)[1].endswith("is up to date (--force detects again)\n")


def test_view_without_markers_is_a_warning(project, capsys):
    config, _, _ = project
    config.write_text(config.read_text() + '[[views]]\nname = "corner"\nroi = [0, 0, 6, 6]\n')
    code, out, err = run(capsys, config)
    assert code == 0 and "view 'corner': no markers in any of the 12 records" in err
    assert out.splitlines()[5].split() == ["corner", "12", "0", "0", "0", "12"]


def test_interrupted_run_leaves_no_file(project, capsys, monkeypatch):
    import videotrack.detect.run as detect

    calls = []

    def interrupt(self, frame_set):
        calls.append(1)
        if len(calls) == 5:
            raise KeyboardInterrupt
        return original(self, frame_set)

    original = detect.FrameDetector.__call__
    monkeypatch.setattr(detect.FrameDetector, "__call__", interrupt)
    config, _, _ = project
    code, _, err = run(capsys, config)
    assert code == 130 and "interrupted" in err
    assert not list(config.parent.glob("*.npz")) and not list(config.parent.glob(".*"))
