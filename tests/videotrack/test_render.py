"""The marker renderer: pixel convention, anti-aliasing, colour, noise."""

import numpy as np
import pytest

from videotrack.synth.render import render_markers


def weighted_centroid(img, background):
    w = np.clip(img.astype(float) - background, 0, None)
    ys, xs = np.mgrid[: img.shape[0], : img.shape[1]]
    return np.array([(w * xs).sum(), (w * ys).sum()]) / w.sum()


def test_pixel_centres_are_integer_coordinates():
    # A marker centred on pixel (x=5, y=3) lights that pixel fully and symmetrically.
    img = render_markers((9, 11), [[5.0, 3.0]], diameter=3.0, intensity=100, background=0)
    assert img[3, 5] == 100
    assert img[3, 4] == img[3, 6] and img[2, 5] == img[4, 5]
    np.testing.assert_allclose(weighted_centroid(img, 0), [5.0, 3.0], atol=1e-9)


@pytest.mark.parametrize("profile", ["disc", "gaussian"])
def test_anti_aliased_centroid_follows_sub_pixel_position(profile):
    for x, y in [(10.25, 8.5), (9.8, 11.33), (12.0, 7.1)]:
        img = render_markers((20, 24), [[x, y]], 5.0, 200.0, 10.0, profile=profile)
        np.testing.assert_allclose(weighted_centroid(img, 10.0), [x, y], atol=0.04)


def test_coverage_sums_to_disc_area():
    img = render_markers((30, 30), [[14.3, 15.7]], diameter=8.0, intensity=250, background=0)
    assert abs(img.sum() / 250 - np.pi * 16) < 0.5  # area of the disc, up to rounding


def test_colour_per_channel_and_per_marker():
    img = render_markers((20, 40, 3), [[5, 5], [30, 10]], 4, intensity=[[0, 0, 200], [0, 150, 0]],
                         background=(1, 2, 3))
    assert img.shape == (20, 40, 3) and img.dtype == np.uint8
    assert tuple(img[0, 0]) == (1, 2, 3)
    assert img[5, 5, 2] == 203 and img[5, 5, 1] == 2
    assert img[10, 30, 1] == 152 and img[10, 30, 2] == 3
    grey = render_markers((10, 10), [[2, 2], [7, 7]], 3, intensity=[50, 100], background=0)
    assert grey[2, 2] == 50 and grey[7, 7] == 100


def test_nan_markers_are_skipped_and_outside_markers_clipped():
    img = render_markers((10, 10), [[np.nan, 3], [-20, 4], [9.5, 5]], 4, 100, 0)
    assert img[:, :7].max() == 0 and img[:, 9].max() > 0  # only the disc at x=9.5 shows


def test_noise_needs_an_explicit_seed_and_is_reproducible():
    with pytest.raises(ValueError, match="rng"):
        render_markers((5, 5), [], noise_sigma=2.0)
    a = render_markers((50, 50), [[20, 20]], noise_sigma=2.0, rng=4)
    b = render_markers((50, 50), [[20, 20]], noise_sigma=2.0, rng=np.random.default_rng(4))
    assert np.array_equal(a, b)
    assert 1.5 < a[40:, 40:].std() < 2.5


def test_bad_arguments():
    with pytest.raises(ValueError, match="profile"):
        render_markers((5, 5), [], profile="square")
    with pytest.raises(ValueError, match="intensity"):
        render_markers((5, 5), [[1, 1], [2, 2]], intensity=[1, 2, 3])
