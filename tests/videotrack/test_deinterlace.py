"""De-interlacing: field images, parity, order, line doubling and the y mapping."""

import cv2
import numpy as np
import pytest

from videotrack.detect.deinterlace import NO_DEINTERLACE, Deinterlace
from videotrack.detect.markers import find_regions
from videotrack.errors import VideoTrackError
from videotrack.synth.render import render_markers


def test_parities_rate_and_field_rows():
    assert NO_DEINTERLACE.parities == (None,) and NO_DEINTERLACE.frame_rate(25) == 25
    top, bottom = Deinterlace("fields", "top"), Deinterlace("fields", "bottom")
    assert top.parities == (0, 1) and bottom.parities == (1, 0)
    assert top.frame_rate(25) == 50 and top.fields_per_frame == 2
    img = np.arange(7)[:, None].repeat(3, axis=1)
    np.testing.assert_array_equal(top.field_image(img, 0)[:, 0], [0, 2, 4, 6])
    np.testing.assert_array_equal(top.field_image(img, 1)[:, 0], [1, 3, 5])
    # An image starting at odd full-frame row 3: its first even row is its second row.
    np.testing.assert_array_equal(top.field_image(img, 0, row0=3)[:, 0], [1, 3, 5])
    assert NO_DEINTERLACE.field_image(img, None) is img


@pytest.mark.parametrize("doubling", ["none", "repeat", "linear"])
@pytest.mark.parametrize("parity", [0, 1])
def test_half_frame_y_maps_to_full_frame_y(doubling, parity):
    d = Deinterlace("fields", "top", doubling)
    y_half = np.array([0.0, 2.5, 7.25])
    full = d.to_full_y(y_half, parity)
    np.testing.assert_allclose(d.from_full_y(full, parity), y_half)
    if doubling == "none":
        np.testing.assert_allclose(full, 2 * y_half + parity)
    else:
        np.testing.assert_allclose(full, y_half - 0.5 + parity)
    assert d.field_image(np.zeros((9, 4)), parity).shape[0] == (
        (9 - parity + 1) // 2 * (1 if doubling == "none" else 2))


@pytest.mark.parametrize("doubling", ["none", "repeat", "linear"])
def test_marker_in_a_field_is_found_at_its_full_frame_position(doubling):
    # A smooth spot, so that keeping every other row does not bias its centroid.
    truth = (20.3, 31.4)
    frame = render_markers((64, 48), [truth], 8.0, 200.0, 20.0, profile="gaussian")
    d = Deinterlace("fields", "top", doubling)
    for parity in (0, 1):
        img = d.field_image(frame, parity)
        mask = cv2.threshold(img, 40, 255, cv2.THRESH_BINARY)[1]
        (xy,) = find_regions(mask, np.ascontiguousarray(img)).xy
        assert xy[0] == pytest.approx(truth[0], abs=0.05)
        assert d.to_full_y(xy[1], parity) == pytest.approx(truth[1], abs=0.05)


def test_invalid_modes():
    with pytest.raises(VideoTrackError, match="deinterlace"):
        Deinterlace("weave")
    with pytest.raises(VideoTrackError, match="field_order"):
        Deinterlace("fields", "left")
    with pytest.raises(VideoTrackError, match="line_doubling"):
        Deinterlace("fields", "top", "cubic")
