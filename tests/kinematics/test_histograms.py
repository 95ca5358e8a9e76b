"""Joint-angle histograms: ranges, wrap-around statistics, Eq. 4 learning, merging."""

import numpy as np
import pytest

from kinematics.errors import KinematicsError
from kinematics.model.histograms import Histogram, bin_index, merge_histograms


def test_uniform_sets_bins_of_the_range_only():
    h = Histogram.uniform(-30, 60)
    assert h.n_bins == 360 and h.n_trials == 1
    assert np.count_nonzero(h.values) == 90
    assert h.at(-30) == pytest.approx(1 / 90) and h.at(59.5) == pytest.approx(1 / 90)
    assert h.at(-31) == 0 and h.at(60.5) == 0
    assert h.values.sum() == pytest.approx(1.0)


def test_range_wrapping_through_180_has_correct_mean_and_sd():
    # phi of the locust: [120, 220] wraps through +-180.
    h = Histogram.uniform(120, 220)
    assert np.count_nonzero(h.values) == 100
    assert h.at(-150) > 0 and h.at(170) > 0 and h.at(0) == 0
    assert h.mean_deg() == pytest.approx(170.0)
    # s(H) of 100 one-degree bins: sqrt((100^2 - 1) / 12)
    assert h.std_deg() == pytest.approx(np.sqrt((100**2 - 1) / 12))
    assert h.support_deg() == pytest.approx((120.0, 220.0))


def test_locked_axis_is_one_bin_with_zero_sd():
    h = Histogram.locked(0.0)
    assert np.count_nonzero(h.values) == 1 and h.std_deg() == 0.0


def test_plausibility_threshold():
    h = Histogram.uniform(0, 10)
    assert h.plausible(5, 0.05) and not h.plausible(5, 0.2) and not h.plausible(20, 0.0001)


def test_eq4_update_by_hand():
    # Uniform over 4 one-degree bins (0.25 each), N = 1; observe 0.5 deg twice, then 2.5 deg.
    h = Histogram.uniform(0, 4)
    i0, i2 = bin_index(0.5), bin_index(2.5)
    h1 = h.updated([0.5])  # N = 2: ((2-1)*0.25 + 1) / 2 = 0.625 ; others 0.125
    assert h1.n_trials == 2
    assert h1.values[i0] == pytest.approx(0.625) and h1.values[i2] == pytest.approx(0.125)
    h2 = h1.updated([0.5])  # N = 3: (2*0.625 + 1) / 3 = 0.75 ; others 2*0.125/3
    assert h2.values[i0] == pytest.approx(0.75) and h2.values[i2] == pytest.approx(1 / 12)
    h3 = h2.updated([2.5])  # N = 4: 3*0.75/4 = 0.5625 ; (3/12 + 1)/4 = 0.3125
    assert h3.values[i0] == pytest.approx(0.5625) and h3.values[i2] == pytest.approx(0.3125)
    # Batch update equals the sequential one.
    batch = h.updated([0.5, 0.5, 2.5])
    np.testing.assert_allclose(batch.values, h3.values)
    assert batch.n_trials == 4
    assert batch.values.sum() == pytest.approx(1.0)


def test_merge_weighted_by_trials():
    a = Histogram.uniform(0, 2, n_trials=3)   # 0.5, 0.5 on bins of 0 and 1
    b = Histogram.uniform(1, 2, n_trials=1)   # 1.0 on bin of 1
    m = merge_histograms([a, b])
    assert m.n_trials == 4
    assert m.at(0.5) == pytest.approx(3 * 0.5 / 4)
    assert m.at(1.5) == pytest.approx((3 * 0.5 + 1.0) / 4)


@pytest.mark.parametrize("bad", [
    lambda: Histogram.uniform(10, -10),
    lambda: Histogram.uniform(0, np.nan),
    lambda: Histogram(np.zeros(360)),
    lambda: Histogram(-np.ones(360)),
    lambda: Histogram(np.ones(360), n_trials=0),
    lambda: merge_histograms([Histogram.uniform(0, 1), Histogram.uniform(0, 1, n_bins=72)]),
])
def test_bad_histograms_raise_our_error(bad):
    with pytest.raises(KinematicsError):
        bad()
