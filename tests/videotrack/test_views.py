"""Views: ROI cutting, mirroring, coordinate mapping, bad ROIs."""

import numpy as np
import pytest

from videotrack.detect.deinterlace import Deinterlace
from videotrack.detect.views import Plane, View, check_views
from videotrack.errors import VideoTrackError


def test_cut_and_mirror():
    frame = np.arange(12 * 20, dtype=np.uint8).reshape(12, 20)
    v = View("a", (5, 2, 8, 6))
    assert np.array_equal(v.cut(frame), frame[2:8, 5:13])
    assert np.shares_memory(v.cut(frame), frame)  # no copy
    m = View("m", (5, 2, 8, 6), flip_x=True, flip_y=True)
    assert np.array_equal(m.cut(frame), frame[2:8, 5:13][::-1, ::-1])


@pytest.mark.parametrize("flip_x, flip_y", [(False, False), (True, False), (False, True),
                                            (True, True)])
def test_points_follow_pixels_through_the_mirror(flip_x, flip_y):
    v = View("a", (7, 3, 10, 9), flip_x=flip_x, flip_y=flip_y)
    frame = np.zeros((20, 30), np.uint8)
    frame[5, 9] = 255  # frame pixel x=9, y=5
    ys, xs = np.nonzero(v.cut(frame))
    view_xy = np.array([[xs[0], ys[0]]], float)
    np.testing.assert_array_equal(v.to_frame(view_xy), [[9, 5]])
    np.testing.assert_array_equal(v.from_frame([[9, 5]]), view_xy)
    pts = np.random.default_rng(0).uniform(0, 8, (5, 2))
    np.testing.assert_allclose(v.from_frame(v.to_frame(pts)), pts)
    np.testing.assert_allclose(v.roi_to_view(v.roi_to_view(pts)), pts)


def test_camera_defaults_to_the_view_name():
    assert View("side").camera == "side"
    assert View("side", camera="cam2").camera == "cam2"


def test_roi_outside_the_frame_is_a_clear_error():
    with pytest.raises(VideoTrackError, match=r"outside the 100x50 frame") as err:
        check_views([View("a", (0, 0, 50, 50)), View("b", (60, 0, 50, 50))], [(100, 50)])
    assert err.value.field == "views[1].roi"
    with pytest.raises(VideoTrackError, match="empty"):
        View("a", (0, 0, 0, 5)).resolved(10, 10)
    with pytest.raises(VideoTrackError, match="used twice"):
        check_views([View("a"), View("a")], [(10, 10)])
    with pytest.raises(VideoTrackError, match="video 1"):
        check_views([View("a", video=1)], [(10, 10)])
    (whole,) = check_views([View("a")], [(10, 8)])
    assert whole.roi == (0, 0, 10, 8)


@pytest.mark.parametrize("mode, doubling", [("none", "none"), ("fields", "none"),
                                            ("fields", "repeat"), ("fields", "linear")])
@pytest.mark.parametrize("roi_y", [4, 5])  # even and odd ROI tops change the field's first row
@pytest.mark.parametrize("flip_y", [False, True])
def test_plane_coordinates_map_back_to_the_view(mode, doubling, roi_y, flip_y):
    deint = Deinterlace(mode, "top", doubling)
    view = View("a", (3, roi_y, 12, 11), flip_x=True, flip_y=flip_y)
    frame = np.zeros((20, 20), np.uint8)
    for parity in deint.parities:
        plane = Plane(view, parity, deint)
        rows = [y for y in range(roi_y, roi_y + 11) if parity is None or y % 2 == parity]
        if doubling == "linear":  # OpenCV's resize replicates the border rows
            rows = rows[1:-1]
        for fy in rows:
            frame[:] = 0
            frame[fy, 6] = 200
            img = plane.extract(frame).astype(float)
            ys, xs = np.mgrid[: img.shape[0], : img.shape[1]]
            found = np.array([[(img * xs).sum(), (img * ys).sum()]]) / img.sum()
            np.testing.assert_allclose(view.to_frame(plane.to_view(found)), [[6, fy]])
            np.testing.assert_allclose(plane.from_view(plane.to_view(found)), found)
