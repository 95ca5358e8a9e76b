"""Detections files: exact round trip, atomic writes, stale detections, bad files."""

import json

import numpy as np
import pytest

from videotrack.detect.deinterlace import Deinterlace
from videotrack.detect.detections import (
    Detections,
    DetectSettings,
    check_fresh,
    load_detections,
    save_detections,
)
from videotrack.detect.filters import FilterChain
from videotrack.detect.markers import MarkerSettings
from videotrack.detect.run import detect_video
from videotrack.detect.video import VideoSource
from videotrack.detect.views import View
from videotrack.errors import VideoTrackError

SETTINGS = DetectSettings((View("left", (0, 0, 80, 60)), View("right", (80, 0, 80, 60), True)),
                          FilterChain([{"type": "threshold", "value": 90}]))


@pytest.fixture
def detections(scene_video):
    path, _, _ = scene_video
    return detect_video(VideoSource(path), SETTINGS)


def test_round_trip_is_exact(tmp_path, detections):
    out = save_detections(detections, tmp_path / "d.npz")
    back = load_detections(out)
    for key in ("points", "areas", "offsets", "video_frames", "parities"):
        a, b = getattr(detections, key), getattr(back, key)
        assert a.dtype == b.dtype and np.array_equal(a, b), key
    assert back.metadata == json.loads(json.dumps(detections.metadata))
    assert back.path == out and back.view_names == ["left", "right"]
    with np.load(out, allow_pickle=False) as raw:  # readable without VideoTrack
        meta = json.loads(str(raw["metadata"]))
    assert meta["format"] == "videotrack-detections" and meta["videos"][0]["name"] == "scene.avi"
    assert meta["settings_hash"] == SETTINGS.hash()


def test_failed_write_leaves_no_file(tmp_path, detections, monkeypatch):
    target = tmp_path / "d.npz"

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(Exception, match="No space left"):
        save_detections(detections, target)
    assert list(tmp_path.iterdir()) == [tmp_path / "scene.avi"]  # no target, no temp file
    monkeypatch.undo()
    save_detections(detections, target)
    old = target.read_bytes()
    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(Exception, match="No space left"):
        save_detections(detections, target)
    assert target.read_bytes() == old  # the old file survives a failed overwrite


def test_fresh_and_stale(tmp_path, scene_video, detections, video_writer, scene_renderer):
    path, left, right = scene_video
    video = VideoSource(path)
    check_fresh(detections, video, SETTINGS)
    check_fresh(detections, video, SETTINGS, frames=range(2, 12))
    changed = [
        DetectSettings(SETTINGS.views, FilterChain([{"type": "threshold", "value": 91}])),
        DetectSettings(SETTINGS.views, SETTINGS.filters, MarkerSettings(min_area=2)),
        DetectSettings(SETTINGS.views, SETTINGS.filters,
                       deinterlace=Deinterlace("fields")),
        DetectSettings((SETTINGS.views[0],), SETTINGS.filters),
    ]
    for settings, what in zip(changed, ["filters", "markers", "deinterlace", "views"],
                              strict=True):
        with pytest.raises(VideoTrackError, match=f"other {what} settings") as err:
            check_fresh(detections, video, settings)
        assert err.value.field == "settings"
    (tmp_path / "other").mkdir()  # same name, fewer frames
    other = video_writer(tmp_path / "other" / "scene.avi", scene_renderer(left[:10], right[:10]))
    with pytest.raises(VideoTrackError, match=r"another video .*frames 12 -> 10") as err:
        check_fresh(detections, VideoSource(other), SETTINGS)
    assert err.value.field == "video"
    part = detect_video(video, SETTINGS, frames="0:5")
    with pytest.raises(VideoTrackError, match="cover frames 0:5, not 0:12"):
        check_fresh(part, video, SETTINGS, frames=range(12))


def test_loading_bad_files(tmp_path, detections):
    with pytest.raises(VideoTrackError, match="no such detections file"):
        load_detections(tmp_path / "none.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(VideoTrackError, match=r"not an \.npz archive"):
        load_detections(tmp_path / "junk.npz")
    np.savez(tmp_path / "other.npz", points=np.zeros((0, 2)))
    with pytest.raises(VideoTrackError, match="not a detections file"):
        load_detections(tmp_path / "other.npz")
    meta = dict(detections.metadata, version=99)
    arrays = {k: getattr(detections, k) for k in ("points", "areas", "offsets", "video_frames",
                                                  "parities")}
    np.savez(tmp_path / "v99.npz", metadata=np.array(json.dumps(meta)), **arrays)
    with pytest.raises(VideoTrackError, match="version 99"):
        load_detections(tmp_path / "v99.npz")
    arrays["offsets"] = arrays["offsets"][:-1]
    np.savez(tmp_path / "cut.npz", metadata=np.array(json.dumps(detections.metadata)), **arrays)
    with pytest.raises(VideoTrackError, match="offsets"):
        load_detections(tmp_path / "cut.npz")


META_DAMAGE = {  # metadata edited or damaged: a located error, never "internal error"
    "a view name not a name": ({"view_names": [["left"], "right"]}, "view_names"),
    "a frame rate in a list": ({"frame_rate": [50]}, "frame_rate must be a number"),
    "an infinite frame": ({"frames": [0, float("inf")]}, "frames must be"),
    "broken frames as lists": ({"broken": [[1, 2]]}, "broken must be"),
    "warnings as one text": ({"warnings": "x"}, "warnings must be"),
    "a video without its fps": ({"videos": [{"name": "v"}]}, "fps"),
}


@pytest.mark.parametrize("case", META_DAMAGE)
def test_damaged_metadata_is_named(tmp_path, detections, case):
    change, message = META_DAMAGE[case]
    meta = dict(detections.metadata, **change)
    arrays = {k: getattr(detections, k) for k in ("points", "areas", "offsets", "video_frames",
                                                  "parities")}
    np.savez(tmp_path / "d.npz", metadata=np.array(json.dumps(meta)), **arrays)
    with pytest.raises(VideoTrackError, match=message) as err:
        load_detections(tmp_path / "d.npz")
    assert err.value.file == str(tmp_path / "d.npz") and err.value.field == "metadata"


@pytest.mark.parametrize(("array", "value", "message"), [
    ("video_frames", 2**62, "video_frames must be"), ("parities", 7, "parities must be")])
def test_damaged_arrays_are_named(tmp_path, detections, array, value, message):
    arrays = {k: getattr(detections, k).copy() for k in ("points", "areas", "offsets",
                                                         "video_frames", "parities")}
    arrays[array].flat[-1] = value
    np.savez(tmp_path / "d.npz", metadata=np.array(json.dumps(detections.metadata)), **arrays)
    with pytest.raises(VideoTrackError, match=message):
        load_detections(tmp_path / "d.npz")


def test_ragged_access(detections):
    counts = detections.counts()
    assert counts.shape == (12, 2) and counts.sum() == len(detections.points)
    k = 5 * 2 + 1
    np.testing.assert_array_equal(
        detections.points_of(5, "right"),
        detections.points[detections.offsets[k]:detections.offsets[k + 1]])
    assert detections.areas_of(5, 1).shape == (counts[5, 1],)
    with pytest.raises(KeyError):
        detections.points_of(0, "top")
    with pytest.raises(VideoTrackError, match="inconsistent"):
        Detections(detections.points, detections.areas[:-1], detections.offsets,
                   detections.video_frames, detections.parities, detections.metadata)
