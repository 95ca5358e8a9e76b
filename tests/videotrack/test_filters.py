"""The filter chain: every step type, kinds, masks, background, validation, determinism."""

import cv2
import numpy as np
import pytest

from videotrack.detect.deinterlace import NO_DEINTERLACE, Deinterlace
from videotrack.detect.filters import FilterChain
from videotrack.detect.markers import find_regions
from videotrack.detect.views import Plane, View
from videotrack.errors import VideoTrackError
from videotrack.synth.render import render_markers


def plane_for(image, view=None, deint=NO_DEINTERLACE, parity=None):
    h, w = image.shape[:2]
    return Plane(view or View("v", (0, 0, w, h)), parity, deint)


def run(steps, image, samples=None, **plane_kw):
    plane = plane_for(image, **plane_kw)
    compiled = FilterChain(steps).compile(plane, (lambda n: samples[:n]) if samples else None)
    return compiled.run(plane.extract(image))


def centroids(steps, image, **kw):
    """Marker centroids in view coordinates."""
    mask, weights = run(steps, image, **kw)
    return plane_for(image, **kw).to_view(find_regions(mask, weights).xy)


GREY = render_markers((40, 60), [(10.2, 10.7), (40.6, 25.3)], 4.0, 200.0, 20.0)


def test_threshold_mask_and_weights():
    mask, weights = run([{"type": "threshold", "value": 100}], GREY)
    assert set(np.unique(mask)) == {0, 255}
    assert np.array_equal(mask, cv2.threshold(GREY, 100, 255, cv2.THRESH_BINARY)[1])
    assert np.array_equal(weights, GREY) and np.shares_memory(weights, GREY)  # no copy
    np.testing.assert_allclose(find_regions(mask, weights).xy,
                               [(10.2, 10.7), (40.6, 25.3)], atol=0.05)


def test_otsu_and_adaptive_thresholds():
    np.testing.assert_allclose(centroids([{"type": "otsu"}], GREY), [(10.2, 10.7), (40.6, 25.3)],
                               atol=0.05)
    # A brightness ramp defeats any global threshold, not the local one.
    ramp = np.clip(GREY.astype(int) + np.linspace(0, 150, 60)[None, :].astype(int), 0, 255)
    ramp = ramp.astype(np.uint8)
    mask, _ = run([{"type": "threshold", "value": 120}], ramp)
    assert find_regions(mask).area.max() > 100  # the bright end of the ramp
    xy = centroids([{"type": "adaptive", "block_size": 11, "offset": 40}], ramp)
    assert len(xy) == 2
    xy = centroids([{"type": "adaptive", "block_size": 11, "offset": 40, "method": "gaussian"}],
                   ramp)
    assert len(xy) == 2


def test_invert_finds_dark_markers():
    dark = 255 - GREY
    assert len(centroids([{"type": "threshold", "value": 100}], dark)) == 1  # the background
    np.testing.assert_allclose(
        centroids([{"type": "invert"}, {"type": "threshold", "value": 100}], dark),
        [(10.2, 10.7), (40.6, 25.3)], atol=0.05)


def test_colour_channel_grey_and_hsv_range():
    red_blue = render_markers((40, 60, 3), [(10.2, 10.7), (40.6, 25.3)], 4.0,
                              [[0, 0, 200], [200, 0, 0]], 10.0)  # BGR: a red and a blue marker
    red = [{"type": "channel", "channel": "red"}, {"type": "threshold", "value": 100}]
    np.testing.assert_allclose(centroids(red, red_blue), [(10.2, 10.7)], atol=0.05)
    blue = [{"type": "channel", "channel": "blue"}, {"type": "threshold", "value": 100}]
    np.testing.assert_allclose(centroids(blue, red_blue), [(40.6, 25.3)], atol=0.05)
    grey = [{"type": "grey"}, {"type": "threshold", "value": 30}]
    assert len(centroids(grey, red_blue)) == 2
    # Red hue wraps around 0: 170..179 and 0..10.
    hsv_red = [{"type": "hsv_range", "lower": [170, 100, 100], "upper": [10, 255, 255]}]
    mask, weights = run(hsv_red, red_blue)
    assert weights.ndim == 2  # grey of the colour image for the centroids
    np.testing.assert_allclose(find_regions(mask, weights).xy, [(10.2, 10.7)], atol=0.1)
    hsv_blue = [{"type": "hsv_range", "lower": [110, 100, 100], "upper": [130, 255, 255]}]
    np.testing.assert_allclose(centroids(hsv_blue, red_blue), [(40.6, 25.3)], atol=0.1)


def test_morphology():
    mask = np.zeros((30, 30), np.uint8)
    mask[5:12, 5:12] = 255
    mask[20, 20] = 255  # a speck
    mask[8, 8] = 0  # a hole
    grey_to_mask = [{"type": "threshold", "value": 100}]
    opened, _ = run([*grey_to_mask, {"type": "open", "size": 3, "shape": "rect"}], mask)
    assert opened[20, 20] == 0 and opened[6, 6] == 255
    closed, _ = run([*grey_to_mask, {"type": "close", "size": 3, "shape": "rect"}], mask)
    assert closed[8, 8] == 255 and closed[20, 20] == 255
    eroded, _ = run([*grey_to_mask, {"type": "erode", "size": 3, "iterations": 2}], mask)
    assert eroded[20, 20] == 0 and eroded[6, 6] == 0 and eroded[10, 10] == 0
    dilated, _ = run([*grey_to_mask, {"type": "dilate", "size": 5, "shape": "cross"}], mask)
    assert dilated[20, 22] == 255 and dilated[22, 22] == 0
    assert np.array_equal(eroded, cv2.erode(mask, cv2.getStructuringElement(
        cv2.MORPH_ELLIPSE, (3, 3)), iterations=2))


def test_background_subtraction_removes_static_reflections():
    rng = np.random.default_rng(0)
    frames = [render_markers((40, 60), [(50.0, 8.0), (10 + 3 * i, 30.4)], 4.0, 200.0, 20.0,
                             1.0, rng) for i in range(10)]
    steps = [{"type": "background", "frames": 9}, {"type": "threshold", "value": 80}]
    mask, weights = run(steps, frames[4], samples=frames)
    xy = find_regions(mask, weights).xy
    np.testing.assert_allclose(xy, [(22.0, 30.4)], atol=0.1)  # the moving marker only
    assert weights[8, 50] < 10  # the reflection is gone from the weights too
    dark = [255 - f for f in frames]
    steps[0]["polarity"] = "darker"
    assert len(find_regions(*run(steps, dark[4], samples=dark))) == 1
    steps[0]["polarity"] = "both"
    assert len(find_regions(*run(steps, frames[4], samples=frames))) == 1
    with pytest.raises(ValueError, match="sample_frames"):
        FilterChain(steps).compile(plane_for(GREY))


def test_masks_in_view_coordinates(tmp_path):
    # Right half of the frame, mirrored: view x = 29 - (frame x - 30).
    frame = render_markers((40, 60), [(35.0, 10.0), (55.0, 30.0)], 4.0, 200.0, 20.0)
    view = View("m", (30, 0, 30, 40), flip_x=True)
    thr = {"type": "threshold", "value": 100}
    both = centroids([thr], frame, view=view)
    assert len(both) == 2
    rect = {"type": "mask", "rects": [[20, 5, 8, 10]]}  # view x 20..27 holds frame x 35
    assert len(centroids([rect, thr], frame, view=view)) == 1
    poly = {"type": "mask", "polygons": [[[0, 25], [9, 25], [9, 35], [0, 35]]]}
    kept = centroids([{**poly, "keep": True}, thr], frame, view=view)
    np.testing.assert_allclose(view.to_frame(kept), [(55.0, 30.0)], atol=0.05)
    image = np.zeros((40, 30), np.uint8)
    image[25:35, 0:9] = 1
    cv2.imwrite(str(tmp_path / "m.png"), image)
    from_image = centroids([{"type": "mask", "image": str(tmp_path / "m.png")}, thr], frame,
                           view=view)
    np.testing.assert_allclose(view.to_frame(from_image), [(35.0, 10.0)], atol=0.05)
    other_view = {"type": "mask", "rects": [[0, 0, 30, 40]], "view": "other"}
    assert len(centroids([other_view, thr], frame, view=view)) == 2
    cv2.imwrite(str(tmp_path / "small.png"), np.zeros((5, 5), np.uint8))
    with pytest.raises(VideoTrackError, match="mask image is 5x5") as err:
        run([{"type": "mask", "image": str(tmp_path / "small.png")}, thr], frame, view=view)
    assert err.value.field == "filters.steps[0].image"
    with pytest.raises(VideoTrackError, match="cannot read"):
        run([{"type": "mask", "image": str(tmp_path / "none.png")}, thr], frame, view=view)
    with pytest.raises(VideoTrackError, match="no view named 'other'"):
        FilterChain([other_view, thr]).check_views(["m"])


def test_mask_follows_fields():
    frame = np.full((40, 30), 200, np.uint8)
    deint = Deinterlace("fields", "top")
    view = View("v", (0, 3, 30, 30))
    steps = [{"type": "mask", "rects": [[0, 0, 30, 10]], "keep": True},
             {"type": "threshold", "value": 100}]
    for parity in (0, 1):
        mask, _ = run(steps, frame, view=view, deint=deint, parity=parity)
        plane = Plane(view, parity, deint)
        ys = plane.to_view(np.c_[np.zeros(mask.shape[0]), np.arange(mask.shape[0])])[:, 1]
        assert np.all((mask[:, 0] > 0) == (ys < 10))


@pytest.mark.parametrize("step, field, message", [
    ({"type": "threshold", "value": 300}, "filters.steps[0].value", "at most 254"),
    ({"type": "threshold"}, "filters.steps[0].value", "missing"),
    ({"type": "threshold", "value": "high"}, "filters.steps[0].value", "an integer"),
    ({"type": "adaptive", "block_size": 10}, "filters.steps[0].block_size", "odd"),
    ({"type": "erode", "size": 4}, "filters.steps[0].size", "odd"),
    ({"type": "erode", "iterations": 0}, "filters.steps[0].iterations", "at least 1"),
    ({"type": "dilate", "shape": "star"}, "filters.steps[0].shape", "one of"),
    ({"type": "channel", "channel": "purple"}, "filters.steps[0].channel", "one of"),
    ({"type": "hsv_range", "lower": [200, 0, 0], "upper": [10, 255, 255]},
     "filters.steps[0].lower", "hue runs 0..179"),
    ({"type": "hsv_range", "lower": [0, 0], "upper": [10, 255, 255]},
     "filters.steps[0].lower", "3 entries"),
    ({"type": "background", "frames": 1}, "filters.steps[0].frames", "at least 3"),
    ({"type": "mask", "rects": [[0, 0, -5, 3]]}, "filters.steps[0].rects[0][2]", "at least 0"),
    ({"type": "mask", "polygons": [[[0, 0], [1, 1]]]}, "filters.steps[0].polygons", "3"),
    ({"type": "blur"}, "filters.steps[0].type", "unknown type 'blur'"),
    ({"type": "otsu", "level": 3}, "filters.steps[0].level", "unknown key"),
    ({"value": 3}, "filters.steps[0]", "missing 'type'"),
])
def test_absurd_filter_values_name_the_field(step, field, message):
    with pytest.raises(VideoTrackError, match=message) as err:
        FilterChain([step, {"type": "threshold", "value": 100}]
                    if step.get("type") in ("mask", "background") else [step])
    assert err.value.field == field


@pytest.mark.parametrize("steps, message", [
    ([], "no filter steps"),
    ([{"type": "invert"}], "must end with a mask"),
    ([{"type": "otsu"}, {"type": "threshold", "value": 3}], "already a mask"),
    ([{"type": "grey"}, {"type": "channel", "channel": "red"}, {"type": "otsu"}],
     "already grey"),
    ([{"type": "otsu"}, {"type": "background"}], "already a mask"),
    ([{"type": "channel", "channel": "red"}, {"type": "hsv_range", "lower": [0, 0, 0],
                                               "upper": [9, 9, 9]}], "already grey"),
])
def test_steps_in_an_impossible_order(steps, message):
    with pytest.raises(VideoTrackError, match=message):
        FilterChain(steps)


def test_same_settings_same_result_and_settings_record(tmp_path):
    image = np.zeros((4, 4), np.uint8)
    cv2.imwrite(str(tmp_path / "m.png"), image)
    steps = [{"type": "mask", "image": str(tmp_path / "m.png")},
             {"type": "adaptive", "block_size": 5}, {"type": "open"}]
    a, b = FilterChain(steps).to_settings(), FilterChain(steps).to_settings()
    assert a == b
    assert a[0]["image"] == "m.png" and len(a[0]["image_sha256"]) == 64
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (4, 4)).astype(np.uint8)
    assert np.array_equal(run(steps, img)[0], run(steps, img)[0])
    cv2.imwrite(str(tmp_path / "m.png"), image + 1)  # a changed mask changes the settings
    assert FilterChain(steps).to_settings() != a
    assert not FilterChain([{"type": "otsu"}]).needs_colour
    assert FilterChain([{"type": "grey"}, {"type": "otsu"}]).needs_colour
