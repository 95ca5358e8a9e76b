"""Video input: files, image sequences, random access, truncation, bad files, sync."""

import os
import subprocess
import sys
import warnings

import cv2
import numpy as np
import pytest

from videotrack.detect.video import (
    VideoSet,
    VideoSource,
    natural_key,
    open_videos,
    parse_frame_range,
    resolve_frames,
)
from videotrack.detect.video_backends import _Packets
from videotrack.errors import VideoTrackError, VideoTrackWarning


def noise_frames(n, shape=(48, 64), seed=0):
    """Distinct frames: each frame's index is written into its first pixel."""
    rng = np.random.default_rng(seed)
    frames = [rng.integers(0, 256, shape, dtype=np.uint8) for _ in range(n)]
    for i, f in enumerate(frames):
        f[:8, :8] = i * 7 % 256
    return frames


def test_ffv1_is_read_losslessly_with_fps_and_count(tmp_path, video_writer):
    frames = noise_frames(10)
    path = video_writer(tmp_path / "a.avi", frames, fps=50)
    with VideoSource(path) as v:
        assert (v.n_frames, v.fps, v.width, v.height, v.shape) == (10, 50.0, 64, 48, (48, 64))
        got = [f.copy() for _, f in v.frames(reuse=True)]
        assert all(np.array_equal(a, b) for a, b in zip(got, frames, strict=True))
        ident = v.identity()
    assert ident["name"] == "a.avi" and ident["frames"] == 10 and ident["bytes"] > 0


@pytest.mark.parametrize("fourcc, ext", [("FFV1", ".avi"), ("MJPG", ".avi"), ("mp4v", ".mp4")])
def test_random_access_equals_sequential_decoding(tmp_path, video_writer, fourcc, ext):
    path = video_writer(tmp_path / f"a{ext}", noise_frames(30), fourcc=fourcc)
    with VideoSource(path) as v:
        sequential = [f.copy() for _, f in v.frames()]
        assert len(sequential) == 30
        with warnings.catch_warnings():
            warnings.simplefilter("error", VideoTrackWarning)  # seeking must be exact here
            for i in [17, 3, 29, 0, 28, 12, 12, 13, 1]:
                assert np.array_equal(v.read(i), sequential[i]), i


def test_inexact_seeking_falls_back_to_sequential_decoding(tmp_path, video_writer, monkeypatch):
    path = video_writer(tmp_path / "a.mp4", noise_frames(20), fourcc="mp4v")
    v = VideoSource(path)
    sequential = [f.copy() for _, f in v.frames()]
    monkeypatch.setattr(VideoSource, "_probe_seek", lambda self, target: False)
    with pytest.warns(VideoTrackWarning, match="not frame-exact"):
        assert np.array_equal(v.read(15), sequential[15])
    for i in [4, 19, 0, 7]:
        assert np.array_equal(v.read(i), sequential[i])


def test_colour_mode_and_grey_conversion(tmp_path, video_writer):
    rng = np.random.default_rng(2)
    frames = [rng.integers(0, 256, (16, 24, 3), dtype=np.uint8) for _ in range(3)]
    path = video_writer(tmp_path / "c.avi", frames)
    with VideoSource(path, colour=True) as v:
        assert v.shape == (16, 24, 3) and np.array_equal(v.read(2), frames[2])
    with VideoSource(path) as v:
        assert np.array_equal(v.read(1), cv2.cvtColor(frames[1], cv2.COLOR_BGR2GRAY))
    grey_path = video_writer(tmp_path / "g.avi", noise_frames(2, (16, 24)))
    with VideoSource(grey_path, colour=True) as v:
        f = v.read(1)
        assert f.shape == (16, 24, 3) and np.array_equal(f[..., 0], f[..., 2])


def smooth_colour_frames(n, shape=(48, 64), seed=3):
    """Colour frames a camera might record: smooth shading, bright blobs, sensor noise."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    frames = []
    for i in range(n):
        f = 40 + 0.5 * xx + 0.3 * yy + 150 * (np.hypot(xx - 10 - i, yy - 20) < 4)
        f = f[..., None] * np.array([1.0, 0.9, 0.8]) + rng.normal(0, 2, (*shape, 3))
        frames.append(np.clip(f, 0, 255).astype(np.uint8))
    return frames


def ffmpeg_grey(path):
    """Every frame as FFmpeg decodes it, converted to grey (the path packets replace)."""
    cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    frames = []
    while (got := cap.read())[0]:
        frames.append(cv2.cvtColor(got[1], cv2.COLOR_BGR2GRAY))
    return frames


def test_mjpeg_is_decoded_from_its_packets_with_exact_seeking(tmp_path, video_writer,
                                                             monkeypatch):
    # decoded ahead, any runner
    monkeypatch.setattr("videotrack.detect.video_backends.DECODE_THREADS", 4)
    frames = smooth_colour_frames(24)
    path = video_writer(tmp_path / "m.avi", frames, fourcc="MJPG")
    truth = [cv2.cvtColor(f, cv2.COLOR_BGR2GRAY).astype(float) for f in frames]
    reference = ffmpeg_grey(path)
    with VideoSource(path) as v:
        assert isinstance(v._backend, _Packets)
        got = [f.copy() for _, f in v.frames()]
        order = np.random.default_rng(0).permutation(24)
        with warnings.catch_warnings():
            warnings.simplefilter("error", VideoTrackWarning)
            assert all(np.array_equal(v.read(i), got[i]) for i in [1, *order, 1, 0, 2, 1])
        for i, f in v.frames(3, 20):  # decoded ahead, in threads, then left early
            assert np.array_equal(f, got[i])
            if i == 9:
                break
        assert np.array_equal(v.read(10), got[10]) and np.array_equal(v.read(16), got[16])
        assert all(np.array_equal(f, got[i]) for i, f in v.frames(reuse=True))
    assert len(got) == 24
    # the JPEG's own luma: no rounding bias, and within rounding of FFmpeg's decode
    assert abs(np.mean([(g - t).mean() for g, t in zip(got, truth, strict=True)])) < 0.3
    assert max(cv2.absdiff(g, r).mean() for g, r in zip(got, reference, strict=True)) < 1.5
    with VideoSource(path, colour=True) as v:
        colour = v.read(5)
        assert colour.shape == (48, 64, 3)
        assert np.abs(colour.astype(float) - frames[5]).mean() < 3


def test_reads_between_frames_of_a_paused_sequential_read(tmp_path, video_writer,
                                                          monkeypatch):
    monkeypatch.setattr("videotrack.detect.video_backends.DECODE_THREADS", 4)
    path = video_writer(tmp_path / "m.avi", smooth_colour_frames(40), fourcc="MJPG")
    with VideoSource(path) as v:
        whole = [f.copy() for _, f in v.frames()]
        walk = v.frames(10, 40)
        seen = [next(walk) for _ in range(3)]  # frames 10-12, more decoded ahead
        assert np.array_equal(v.read(30), whole[30])  # a seek elsewhere while paused
        seen += [next(walk) for _ in range(3)]
        assert np.array_equal(v.read(16), whole[16])  # the next one in order
        seen += [next(walk) for _ in range(2)]
        assert v.verify_frame_count() == 40  # decodes the whole file meanwhile
        seen += list(walk)
    assert [i for i, _ in seen] == list(range(10, 40))
    assert all(np.array_equal(f, whole[i]) for i, f in seen)


def test_mjpeg_packets_refused_fall_back_to_ffmpeg(tmp_path, video_writer, monkeypatch):
    path = video_writer(tmp_path / "m.avi", smooth_colour_frames(6), fourcc="MJPG")
    # no packet matches
    monkeypatch.setattr("videotrack.detect.video_backends._PACKET_TOLERANCE", -1.0)
    with VideoSource(path) as v:
        assert not isinstance(v._backend, _Packets)
        got = [f.copy() for _, f in v.frames()]
        assert np.array_equal(v.read(3), got[3])
    assert all(np.array_equal(g, r) for g, r in zip(got, ffmpeg_grey(path), strict=True))


def test_damaged_mjpeg_frames_are_decoded_by_ffmpeg(tmp_path, video_writer, monkeypatch):
    monkeypatch.setattr("videotrack.detect.video_backends.DECODE_THREADS", 4)
    path = video_writer(tmp_path / "d.avi", smooth_colour_frames(30), fourcc="MJPG")
    whole = [f.copy() for _, f in VideoSource(path).frames()]
    data = bytearray(path.read_bytes())
    starts = [i for i in range(len(data) - 2) if data[i:i + 3] == b"\xff\xd8\xff"]
    data[starts[10]:starts[10] + 2] = b"\0\0"  # frame 10 is no JPEG any more
    path.write_bytes(bytes(data))
    reference = ffmpeg_grey(path)
    with VideoSource(path) as v:
        got = [(i, f.copy()) for i, f in v.frames()]
        assert np.array_equal(v.read(10), got[10][1])
    assert len(got) == len(reference) == 30 and v.broken_at is None
    assert np.array_equal(got[10][1], reference[10])  # as FFmpeg decodes it
    assert all(np.array_equal(f, whole[i]) for i, f in got if i != 10)


def test_truncated_mjpeg_keeps_the_frames_before_the_break(tmp_path, video_writer):
    path = video_writer(tmp_path / "t.avi", smooth_colour_frames(30), fourcc="MJPG")
    whole = [f.copy() for _, f in VideoSource(path).frames()]
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 2 // 3 + 101])  # cut inside a frame
    v = VideoSource(path)
    with pytest.warns(VideoTrackWarning, match="decoding stopped at frame"):
        got = [(i, f.copy()) for i, f in v.frames()]
    assert 5 < len(got) < 30 and v.broken_at == len(got)
    assert all(np.array_equal(f, whole[i]) for i, f in got[:-1])


@pytest.mark.parametrize("ext", [".png", ".tif", ".jpg"])
def test_image_sequence_in_natural_order(tmp_path, sequence_writer, ext):
    frames = noise_frames(12)
    folder = sequence_writer(tmp_path / "seq", frames, ext=ext)
    (folder / "notes.txt").write_text("not an image")
    with VideoSource(folder, fps=100) as v:
        assert v.is_sequence and v.n_frames == 12 and v.fps == 100
        for i in [11, 2, 10, 0]:  # img10 after img9, not after img1
            f = v.read(i)
            assert abs(int(f[0, 0]) - frames[i][0, 0]) <= (0 if ext != ".jpg" else 3)
        assert [i for i, _ in v.frames(9)] == [9, 10, 11]
    assert VideoSource(folder).fps == 25.0  # sequences default to 25 fps
    assert sorted(["a10", "a2", "a1"], key=natural_key) == ["a1", "a2", "a10"]


def test_image_sequence_with_mismatched_sizes(tmp_path, sequence_writer):
    folder = sequence_writer(tmp_path / "s", noise_frames(2))
    cv2.imwrite(str(folder / "img2.png"), np.zeros((5, 5), np.uint8))
    v = VideoSource(folder)
    with pytest.raises(VideoTrackError, match="size"):
        v.read(2)


def test_truncated_video_keeps_frames_before_the_break(tmp_path, video_writer):
    frames = noise_frames(40)
    path = video_writer(tmp_path / "t.avi", frames)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    v = VideoSource(path)
    assert v.n_frames == 40  # the container's word, until decoding says otherwise
    with pytest.warns(VideoTrackWarning, match=r"t\.avi: decoding stopped at frame (\d+)"):
        got = [(i, f.copy()) for i, f in v.frames()]
    n = len(got)
    assert 5 < n < 40 and v.broken_at == n and v.n_frames == n
    assert all(np.array_equal(f, frames[i]) for i, f in got)
    with pytest.raises(VideoTrackError, match="outside"):
        v.read(n + 2)
    assert np.array_equal(v.read(n - 1), frames[n - 1])


def test_truncation_found_by_random_access_and_by_counting(tmp_path, video_writer):
    path = video_writer(tmp_path / "t.avi", noise_frames(40))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    v = VideoSource(path)
    with pytest.warns(VideoTrackWarning, match="decoding stopped"), \
            pytest.raises(VideoTrackError, match="cannot decode frame"):
        v.read(39)
    assert v.n_frames < 40
    with pytest.warns(VideoTrackWarning, match="container says 40 frames"):
        assert VideoSource(path).verify_frame_count() == v.n_frames


def test_missing_unreadable_and_empty_inputs(tmp_path):
    with pytest.raises(VideoTrackError, match="no such file") as err:
        VideoSource(tmp_path / "nope.avi")
    assert str(err.value).startswith(str(tmp_path / "nope.avi"))
    bad = tmp_path / "bad.avi"
    bad.write_bytes(b"RIFF" + bytes(range(256)) * 40)
    with pytest.raises(VideoTrackError, match="cannot open as a video"):
        VideoSource(bad)
    (tmp_path / "empty").mkdir()
    with pytest.raises(VideoTrackError, match="no images"):
        VideoSource(tmp_path / "empty")


def test_synchronised_videos_share_the_shorter_count(tmp_path, video_writer):
    a = video_writer(tmp_path / "a.avi", noise_frames(8, seed=1))
    b = video_writer(tmp_path / "b.avi", noise_frames(6, seed=2))
    with pytest.warns(VideoTrackWarning, match="different frame counts"):
        videos = open_videos([a, b])
    assert videos.n_frames == 6 and len(videos) == 6
    seen = [(i, fa.copy(), fb.copy()) for i, (fa, fb) in videos.frames()]
    assert [s[0] for s in seen] == list(range(6))
    assert np.array_equal(seen[5][2], videos.read(5)[1])
    assert [d["name"] for d in videos.identity()] == ["a.avi", "b.avi"]
    with pytest.raises(VideoTrackError):
        VideoSet([])


def test_frame_ranges():
    assert parse_frame_range("") == (0, None)
    assert parse_frame_range("3:10") == (3, 10)
    assert parse_frame_range(":7") == (0, 7)
    assert parse_frame_range("4:") == (4, None)
    for bad in ("a:b", "5", "5:5", "-1:4"):
        with pytest.raises(ValueError):
            parse_frame_range(bad)
    assert resolve_frames(None, 10) == range(10)
    assert resolve_frames("2:5", 10) == range(2, 5)
    assert resolve_frames((1, None), 10) == range(1, 10)
    with pytest.warns(VideoTrackWarning, match="has 10 frames"):
        assert resolve_frames("5:50", 10) == range(5, 10)
    with pytest.raises(VideoTrackError, match="starts at 12"):
        resolve_frames("12:", 10)


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="CPU affinity is Linux's")
def test_decode_threads_follow_the_cpu_affinity_not_the_machine():
    # a container or taskset may allow one core of many: the decoder must not start four
    code = ("import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); "
            "import videotrack.detect.video as v; from videotrack.batch import available_cores; "
            "print(v.DECODE_THREADS, available_cores())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["1", "1"]
