"""The CLI's choice lists and the config's allowed values come from one definition each (the
settings records, the keypoint format registry), and ``fit --start track`` reaches the fitter."""

import argparse

import pytest

from kinematics.fit.settings import PROFILES, START_MODES
from videotrack.cli import build_parser, main
from videotrack.errors import VideoTrackError
from videotrack.io.keypoints import FORMATS, KEYPOINT_FORMATS, detect_format, read_keypoints
from videotrack.project.config import (
    ANNEAL,
    KEYPOINTS,
    TRIANGULATION_INITS,
    TRIANGULATION_METHODS,
    parse_layer,
)
from videotrack.results.files import read_sidecar


def option(command: str, flag: str) -> argparse.Action:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return next(a for a in sub.choices[command]._actions if flag in a.option_strings)


def test_fit_start_offers_every_start_mode_of_the_settings():
    assert "track" in START_MODES
    for command in ("fit", "run"):
        assert tuple(option(command, "--start").choices) == START_MODES
    assert ANNEAL.key("start").choices == START_MODES
    assert ANNEAL.key("profile").choices == PROFILES


def test_keypoint_formats_come_from_the_registry():
    assert tuple(KEYPOINT_FORMATS) == FORMATS
    assert tuple(option("keypoints", "--format").choices) == FORMATS
    assert KEYPOINTS.key("format").choices == ("", *FORMATS)
    help_text = option("triangulate", "--format").help
    assert all(name in help_text for name in FORMATS)


def test_triangulation_choices_are_the_configs():
    assert tuple(option("triangulate", "--method").choices) == TRIANGULATION_METHODS
    assert KEYPOINTS.key("triangulation").choices == TRIANGULATION_METHODS
    assert tuple(option("triangulate", "--init").choices) == TRIANGULATION_INITS
    assert set(TRIANGULATION_INITS) < set(TRIANGULATION_METHODS)
    from kinematics.observe import triangulation

    for method in TRIANGULATION_METHODS:  # what markerless.py calls for [keypoints] route 3d
        assert callable(getattr(triangulation, f"triangulate_{method}"))


def test_detection_reads_the_registry(tmp_path):
    (tmp_path / "a.slp").write_bytes(b"")
    assert detect_format(tmp_path / "a.slp") == "sleap"
    (tmp_path / "json").mkdir()
    assert detect_format(tmp_path / "json") == "openpose"
    (tmp_path / "f.json").write_text("{}")
    assert detect_format(tmp_path / "f.json") == "openpose"
    for fmt in KEYPOINT_FORMATS.values():  # every suffix is some detected format's
        for suffix in fmt.suffixes:
            assert any(suffix in f.suffixes for f in KEYPOINT_FORMATS.values() if f.detect)
    with pytest.raises(VideoTrackError, match="no such keypoint file or folder"):
        detect_format(tmp_path / "missing.json")
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(VideoTrackError, match=r"unknown keypoint file type \(expected "
                       r"DeepLabCut \.h5/\.csv, SLEAP \.slp/\.h5, an OpenPose JSON folder or "
                       r"a Lightning Pose \.csv\)"):
        detect_format(tmp_path / "x.txt")
    with pytest.raises(VideoTrackError, match=r"format: unknown keypoint format 'mat' \(one "
                       r"of dlc, sleap, openpose, lightning-pose, anipose\)"):
        read_keypoints(tmp_path / "x.txt", "mat")


def test_config_accepts_every_registered_format(tmp_path):
    path = tmp_path / "config.toml"
    for name in FORMATS:
        layer = parse_layer({"keypoints": {"format": name}}, path)
        assert layer["keypoints"]["format"] == name
    with pytest.raises(VideoTrackError, match=r"keypoints\.format: must be one of '', 'dlc'"):
        parse_layer({"keypoints": {"format": "mat"}}, path)


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    out = tmp_path_factory.mktemp("startproj")
    assert main(["synth", str(out), "--frames", "8", "--sequences", "2"]) == 0
    assert main(["detect", str(out / "project.toml")]) == 0
    return out


def test_fit_start_track_reaches_the_fitter(project, monkeypatch, capsys):
    import videotrack.workflow.model as pipeline  # where the fitter class is looked up

    seen = []

    class Spy(pipeline.Fitter):
        def __init__(self, body, cameras, params, *args, **kwargs):
            seen.append(params.start)
            super().__init__(body, cameras, params, *args, **kwargs)

    monkeypatch.setattr(pipeline, "Fitter", Spy)
    results = project / "track.results.csv"
    code = main(["fit", str(project / "project.toml"), "--start", "track", "--n-end", "2000",
                 "--results", str(results)])
    assert code == 0, capsys.readouterr().err
    assert "fitted 8 frames" in capsys.readouterr().out
    assert seen and set(seen) == {"track"}
    assert read_sidecar(results)["anneal"]["start"] == "track"


def test_fit_rejects_an_unknown_start(capsys):
    with pytest.raises(SystemExit):
        main(["fit", "project.toml", "--start", "bogus"])
    assert "invalid choice: 'bogus' (choose from mean, previous, track)" in \
        capsys.readouterr().err.replace("'mean', 'previous', 'track'", "mean, previous, track")
