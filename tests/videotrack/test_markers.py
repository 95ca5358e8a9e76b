"""Marker regions: kernels against their OpenCV twin, planted-centroid accuracy, gates."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from videotrack.detect.markers import (
    MarkerSettings,
    RegionFinder,
    find_regions,
    find_regions_reference,
)
from videotrack.errors import VideoTrackError
from videotrack.synth.render import render_markers

SETTINGS = [
    MarkerSettings(),
    MarkerSettings(connectivity=4, window_pad=2, min_area=2, max_area=30),
    MarkerSettings(weighting="binary", max_aspect=2.0, min_circularity=0.5),
    MarkerSettings(window_pad=0),
]


def assert_same(a, b):
    assert len(a) == len(b) and a.n_rejected == b.n_rejected
    np.testing.assert_allclose(a.xy, b.xy, atol=1e-9)
    np.testing.assert_array_equal(a.area, b.area)
    np.testing.assert_array_equal(a.bbox, b.bbox)
    np.testing.assert_allclose(a.total, b.total, rtol=1e-12)
    np.testing.assert_allclose(a.aspect, b.aspect, rtol=1e-9)
    np.testing.assert_allclose(a.circularity, b.circularity, rtol=1e-9)


@settings(max_examples=60, deadline=None)
@given(arrays(np.bool_, st.tuples(st.integers(1, 40), st.integers(1, 40))),
       st.integers(0, 2**32 - 1), st.sampled_from(range(len(SETTINGS))))
def test_kernel_matches_opencv_twin(mask, seed, which):
    weights = np.random.default_rng(seed).integers(0, 256, mask.shape).astype(np.uint8)
    mask = mask.astype(np.uint8) * 255
    s = SETTINGS[which]
    assert_same(find_regions(mask, weights, s), find_regions_reference(mask, weights, s))


def test_kernel_matches_twin_on_non_contiguous_views():
    rng = np.random.default_rng(1)
    big = (rng.random((60, 70)) < 0.3).astype(np.uint8) * 255
    g = rng.integers(0, 256, big.shape).astype(np.uint8)
    mask, weights = big[1::2, 3:50], g[1::2, 3:50]  # a field of an ROI, as detection passes
    assert_same(find_regions(mask, weights), find_regions_reference(mask, weights))


def test_planted_centroids_recovered_sub_pixel():
    rng = np.random.default_rng(0)
    truth = rng.uniform(8, 40, (300, 2))
    err = []
    for p in truth:
        img = render_markers((48, 48), [p], 4.0, 200.0, 20.0, 2.0, rng)
        mask = cv2.threshold(img, 100, 255, cv2.THRESH_BINARY)[1]
        r = find_regions(mask, img)
        assert len(r) == 1
        err.append(r.xy[0] - p)
    rms = np.sqrt((np.square(err).sum(axis=1)).mean())
    assert rms < 0.05  # the goal is 0.15 px; the paper had 0.43 px


def test_noiseless_centroids_are_exact_to_quantisation():
    for p in [(10.0, 10.0), (10.5, 12.25), (20.13, 9.77)]:
        img = render_markers((30, 30), [p], 6.0, 230.0, 10.0)
        mask = cv2.threshold(img, 100, 255, cv2.THRESH_BINARY)[1]
        np.testing.assert_allclose(find_regions(mask, img).xy[0], p, atol=0.02)


def test_binary_centroid_is_the_pixel_mean_and_worse():
    img = render_markers((30, 30), [(10.4, 12.3)], 4.0, 200.0, 20.0)
    mask = cv2.threshold(img, 100, 255, cv2.THRESH_BINARY)[1]
    r = find_regions(mask, img, MarkerSettings(weighting="binary"))
    ys, xs = np.nonzero(mask)
    np.testing.assert_allclose(r.xy[0], [xs.mean(), ys.mean()])
    assert r.total[0] == 0
    assert find_regions(mask, None).xy[0] == pytest.approx(r.xy[0])  # no weights: binary


def test_area_bbox_and_order():
    mask = np.zeros((20, 30), np.uint8)
    mask[12:15, 2:6] = 255  # area 12, first pixel (2, 12)
    mask[3:5, 20:21] = 255  # area 2, first pixel (20, 3): comes first in raster order
    r = find_regions(mask)
    np.testing.assert_array_equal(r.area, [2, 12])
    np.testing.assert_array_equal(r.bbox, [[20, 3, 1, 2], [2, 12, 4, 3]])
    np.testing.assert_allclose(r.xy, [[20, 3.5], [3.5, 13]])


def test_area_gates():
    mask = np.zeros((20, 30), np.uint8)
    mask[1, 1] = 255
    mask[5:8, 5:8] = 255
    mask[10:19, 10:19] = 255
    r = find_regions(mask, settings=MarkerSettings(min_area=2, max_area=50))
    np.testing.assert_array_equal(r.area, [9])
    assert r.n_rejected == 2


def test_shape_gates():
    mask = np.zeros((40, 40), np.uint8)
    cv2.circle(mask, (10, 10), 4, 255, -1)
    mask[30:32, 5:35] = 255  # a bar, 15:1
    cv2.circle(mask, (30, 12), 6, 255, 1)  # a ring: round but hollow
    r = find_regions(mask)
    assert len(r) == 3
    disc = np.argmin(np.hypot(*(r.xy - [10, 10]).T))
    assert r.circularity[disc] == pytest.approx(1.0, abs=0.05)
    assert r.aspect[disc] == pytest.approx(1.0, abs=0.05)
    bar = np.argmax(r.aspect)
    assert r.aspect[bar] > 10
    only_round = find_regions(mask, settings=MarkerSettings(max_aspect=2.0))
    assert len(only_round) == 2 and only_round.n_rejected == 1
    only_disc = find_regions(mask, settings=MarkerSettings(min_circularity=0.8))
    np.testing.assert_allclose(only_disc.xy, [[10, 10]], atol=1e-9)


def test_connectivity():
    mask = np.zeros((5, 5), np.uint8)
    mask[1, 1] = mask[2, 2] = 255  # diagonal neighbours
    assert len(find_regions(mask)) == 1
    assert len(find_regions(mask, settings=MarkerSettings(connectivity=4))) == 2


def test_neighbouring_regions_stay_out_of_each_others_window():
    img = render_markers((20, 40), [(10.3, 10.0), (16.6, 10.2)], 4.0, 200.0, 20.0)
    mask = cv2.threshold(img, 100, 255, cv2.THRESH_BINARY)[1]
    r = find_regions(mask, img, MarkerSettings(window_pad=3))
    assert len(r) == 2
    np.testing.assert_allclose(r.xy, [(10.3, 10.0), (16.6, 10.2)], atol=0.12)


def test_empty_mask_and_border_regions():
    assert len(find_regions(np.zeros((10, 10), np.uint8))) == 0
    img = render_markers((12, 12), [(0.0, 11.0)], 3.0, 200.0, 20.0)
    mask = cv2.threshold(img, 100, 255, cv2.THRESH_BINARY)[1]
    assert_same(find_regions(mask, img), find_regions_reference(mask, img))


def test_finder_reuses_a_clean_scratch_image():
    find = RegionFinder()
    img = render_markers((30, 30), [(10.2, 11.7)], 4.0, 200.0, 20.0)
    mask = cv2.threshold(img, 100, 255, cv2.THRESH_BINARY)[1]
    first = find(mask, img)
    assert not find._scratch[mask.shape].any()
    np.testing.assert_array_equal(find(mask, img).xy, first.xy)


@pytest.mark.parametrize("kwargs, field", [
    ({"min_area": 0}, "markers.min_area"),
    ({"max_aspect": 0.5}, "markers.max_aspect"),
    ({"min_circularity": 1.5}, "markers.min_circularity"),
    ({"weighting": "peak"}, "markers.weighting"),
    ({"connectivity": 6}, "markers.connectivity"),
    ({"min_area": 50, "max_area": 10}, "markers.min_area"),
])
def test_absurd_marker_settings(kwargs, field):
    with pytest.raises(VideoTrackError) as err:
        MarkerSettings(**kwargs)
    assert err.value.field == field


def test_bad_images():
    with pytest.raises(ValueError, match="uint8"):
        find_regions(np.zeros((4, 4), np.float32))
    with pytest.raises(ValueError, match="weights"):
        find_regions(np.zeros((4, 4), np.uint8), np.zeros((4, 5), np.uint8))
