"""The detection pipeline on planted-marker videos: views, fields, sync, bad input."""

import warnings

import numpy as np
import pytest

from videotrack.detect.deinterlace import Deinterlace
from videotrack.detect.detections import DetectSettings
from videotrack.detect.filters import FilterChain
from videotrack.detect.markers import MarkerSettings
from videotrack.detect.run import detect_video, format_summary, iter_detect, summarize
from videotrack.detect.video import VideoSource, open_videos
from videotrack.detect.views import View
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.synth.render import render_markers

THRESHOLD = FilterChain([{"type": "threshold", "value": 90}])
LEFT = View("left", (0, 0, 80, 60))
RIGHT = View("right", (80, 0, 80, 60), flip_x=True)


def match(found, truth):
    """Distances from each true point to the nearest found point (and counts must agree)."""
    assert len(found) == len(truth)
    return np.min(np.linalg.norm(found[:, None] - truth[None], axis=2), axis=0)


def test_planted_centroids_in_view_coordinates(scene_video):
    path, left, right = scene_video
    settings = DetectSettings((LEFT, RIGHT), THRESHOLD, MarkerSettings(min_area=3))
    det = detect_video(VideoSource(path), settings)
    assert det.n_records == len(left) and det.view_names == ["left", "right"]
    errors = []
    for r in range(det.n_records):
        errors += list(match(det.points_of(r, "left"), left[r]))
        errors += list(match(det.points_of(r, "right"), RIGHT.from_frame(right[r])))
    errors = np.array(errors)
    assert errors.max() < 0.1 and np.sqrt(np.mean(errors**2)) < 0.05
    assert np.all(det.areas >= 3) and det.frame_rate == 25.0
    np.testing.assert_array_equal(det.video_frames, np.arange(len(left)))
    np.testing.assert_array_equal(det.parities, -1)
    rows = summarize(det)
    assert [(r.view, r.min, r.median, r.max, r.empty) for r in rows] == [
        ("left", 3, 3.0, 3, 0), ("right", 3, 3.0, 3, 0)]
    assert "left" in format_summary(rows) and "median" in format_summary(rows)


def test_same_settings_same_detections(scene_video):
    path, _, _ = scene_video
    settings = DetectSettings((LEFT, RIGHT), THRESHOLD)
    a = detect_video(VideoSource(path), settings)
    b = detect_video(VideoSource(path), settings, frames="3:7")
    assert np.array_equal(a.points[a.offsets[6]:a.offsets[14]], b.points)
    assert b.metadata["frames"] == [3, 7]


@pytest.mark.parametrize("order", ["top", "bottom"])
def test_fields_are_records_in_time_order_at_full_frame_y(tmp_path, video_writer, order):
    # Each frame holds two instants: the earlier in the first field's rows.
    rng = np.random.default_rng(0)
    first_parity = 0 if order == "top" else 1
    truth, frames = [], []
    for _ in range(4):
        early, late = rng.uniform(12, 48, (2, 1, 2))
        a = render_markers((60, 60), early, 7.0, 200.0, 20.0, profile="gaussian")
        b = render_markers((60, 60), late, 7.0, 200.0, 20.0, profile="gaussian")
        frame = a.copy()
        frame[1 - first_parity::2] = b[1 - first_parity::2]
        frames.append(frame)
        truth += [early, late]
    path = video_writer(tmp_path / "i.avi", frames)
    for doubling in ("none", "repeat", "linear"):
        settings = DetectSettings((View("v"),), FilterChain([{"type": "threshold",
                                                              "value": 60}]),
                                  deinterlace=Deinterlace("fields", order, doubling))
        det = detect_video(VideoSource(path), settings)
        assert det.n_records == 8 and det.frame_rate == 50.0
        np.testing.assert_array_equal(det.video_frames, np.repeat(np.arange(4), 2))
        np.testing.assert_array_equal(det.parities, [first_parity, 1 - first_parity] * 4)
        np.testing.assert_allclose(np.diff(det.times), 0.02)
        for r in range(8):
            np.testing.assert_allclose(det.points_of(r, 0), truth[r], atol=0.1)


def test_synchronised_videos_one_view_each(tmp_path, video_writer):
    rng = np.random.default_rng(1)
    pa, pb = rng.uniform(8, 30, (5, 1, 2)), rng.uniform(8, 18, (5, 2, 2))
    pb[:, 1, 0] += 15  # keep the two markers apart
    a = video_writer(tmp_path / "a.avi", [render_markers((40, 40), p, 4.0) for p in pa])
    b = video_writer(tmp_path / "b.avi", [render_markers((40, 40), p, 4.0) for p in pb])
    settings = DetectSettings((View("cam_a"), View("cam_b", video=1)), THRESHOLD)
    det = detect_video(open_videos([a, b]), settings)
    for r in range(5):
        assert match(det.points_of(r, "cam_a"), pa[r]).max() < 0.05
        assert match(det.points_of(r, "cam_b"), pb[r]).max() < 0.05


def test_view_without_markers_warns_and_keeps_empty_records(scene_video):
    path, _, _ = scene_video
    settings = DetectSettings((LEFT, View("sky", (0, 0, 8, 6))), THRESHOLD)
    with pytest.warns(VideoTrackWarning, match="view 'sky': no markers in any of the 12"):
        det = detect_video(VideoSource(path), settings)
    assert det.counts()[:, 1].sum() == 0 and det.points_of(4, "sky").shape == (0, 2)
    assert summarize(det)[1].empty == 12


def test_truncated_video_keeps_detections_before_the_break(tmp_path, video_writer,
                                                           scene_renderer, scene):
    left, right = scene
    path = video_writer(tmp_path / "t.avi", scene_renderer(left, right))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 2 // 3])
    settings = DetectSettings((LEFT, RIGHT), THRESHOLD)
    with pytest.warns(VideoTrackWarning, match="decoding stopped at frame"):
        det = detect_video(VideoSource(path), settings)
    n = det.n_records
    assert 2 < n < 12 and det.metadata["broken_at"] == n and det.metadata["frames"] == [0, n]
    assert match(det.points_of(n - 1, "left"), left[n - 1]).max() < 0.1


def test_generator_yields_per_record_and_can_be_closed(scene_video):
    path, left, _ = scene_video
    gen = iter_detect(VideoSource(path), DetectSettings((LEFT,), THRESHOLD), frames=range(2, 9))
    first = next(gen)
    assert (first.record, first.video_frame, first.parity) == (0, 2, None)
    assert match(first.points[0], left[2]).max() < 0.1
    gen.close()


def test_opencv_runs_one_thread_while_detecting_and_gets_its_setting_back(scene_video):
    import cv2

    path, _, _ = scene_video
    before = cv2.getNumThreads()
    cv2.setNumThreads(3)
    try:
        settings = DetectSettings((LEFT,), THRESHOLD)
        a = iter_detect(VideoSource(path), settings)
        b = iter_detect(VideoSource(path), settings)
        next(a)
        next(b)  # two detections at once (the GUI's preview beside a run)
        assert cv2.getNumThreads() == 1
        a.close()
        assert cv2.getNumThreads() == 1  # b still runs
        list(b)
        assert cv2.getNumThreads() == 3  # the last to end restores the setting
    finally:
        cv2.setNumThreads(before)


def test_background_step_in_the_pipeline(tmp_path, video_writer):
    frames = [render_markers((40, 40), [(30.0, 30.0), (5 + 3 * i, 10.5)], 4.0)
              for i in range(9)]
    path = video_writer(tmp_path / "b.avi", frames)
    chain = FilterChain([{"type": "background", "frames": 9},
                         {"type": "threshold", "value": 90}])
    det = detect_video(VideoSource(path), DetectSettings((View("v"),), chain))
    np.testing.assert_array_equal(det.counts()[:, 0], 1)  # the static marker is background
    np.testing.assert_allclose(det.points_of(4, 0), [(17.0, 10.5)], atol=0.05)


def test_bad_settings_for_the_video(scene_video):
    path, _, _ = scene_video
    source = VideoSource(path)
    with pytest.raises(VideoTrackError, match="outside the 160x60 frame") as err:
        next(iter_detect(source, DetectSettings((View("a", (100, 0, 80, 60)),), THRESHOLD)))
    assert err.value.field == "views[0].roi"
    colour = FilterChain([{"type": "channel", "channel": "red"},
                          {"type": "threshold", "value": 9}])
    with pytest.raises(VideoTrackError, match="colour=True"):
        next(iter_detect(source, DetectSettings((LEFT,), colour)))
    masked = FilterChain([{"type": "mask", "rects": [[0, 0, 1, 1]], "view": "top"},
                          {"type": "threshold", "value": 9}])
    with pytest.raises(VideoTrackError, match="no view named 'top'"):
        next(iter_detect(source, DetectSettings((LEFT,), masked)))
    with pytest.raises(VideoTrackError, match="starts at 40"):
        next(iter_detect(source, DetectSettings((LEFT,), THRESHOLD), frames="40:"))


def test_colour_video_with_a_colour_chain(tmp_path, video_writer):
    frames = [render_markers((30, 40, 3), [(10.3, 12.2), (30.1, 20.6)], 4.0,
                             [[0, 0, 220], [0, 220, 0]], 10.0) for _ in range(3)]
    path = video_writer(tmp_path / "c.avi", frames)
    chain = FilterChain([{"type": "channel", "channel": "green"},
                         {"type": "threshold", "value": 100}])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        det = detect_video(VideoSource(path, colour=True), DetectSettings((View("v"),), chain))
    np.testing.assert_allclose(det.points_of(2, 0), [(30.1, 20.6)], atol=0.05)
