"""Histogram archives: lossless XML, Eq. 4 learning, merging by N, applying to a body."""

from __future__ import annotations

import difflib
from dataclasses import replace

import numpy as np
import pytest

from kinematics.errors import KinematicsError
from kinematics.model.histogram_xml import (
    HistogramArchive,
    apply_archive,
    archive_from_body,
    archive_to_string,
    load_archive,
    loads_archive,
    merge_archives,
    save_archive,
    update_archive,
)
from kinematics.model.histograms import Histogram

PHI = ("hindleg", "J0", "phi")
BETA = ("hindleg", "J1", "beta")


def random_archive(seed: int = 3) -> HistogramArchive:
    rng = np.random.default_rng(seed)
    hists = {}
    for i, n_bins in enumerate([360, 7, 1, 36000, 360]):
        values = rng.random(n_bins) ** 3 * (rng.random(n_bins) > 0.4)
        values[rng.integers(n_bins)] = 1 / 3  # never all zero
        values[:: max(n_bins // 5, 1)] = 5e-324  # subnormal survives too
        hists[("c", f"J{i}", "a")] = Histogram(values, n_trials=int(rng.integers(1, 10**6)))
    hists[("c", "J9", "u")] = Histogram.uniform(120, 220)
    return HistogramArchive(hists, body="rand", description="random & <odd> text")


def test_xml_round_trip_is_bit_exact(tmp_path):
    archive = random_archive()
    path = tmp_path / "h.xml"
    save_archive(path, archive)
    loaded = load_archive(path)
    assert loaded == archive
    assert list(loaded) == list(archive)  # order kept
    for key in archive:
        assert loaded[key].values.tobytes() == archive[key].values.tobytes()
    assert loaded.body == "rand" and loaded.description == "random & <odd> text"


def test_runs_are_readable():
    text = archive_to_string(HistogramArchive({PHI: Histogram.uniform(120, 220)}))
    assert text.splitlines()[2:6] == [
        '  <histogram chain="hindleg" joint="J0" axis="phi" trials="1">',
        '    <run from="-180" to="-140" value="0.01"/>',
        '    <run from="120" to="180" value="0.01"/>',
        "  </histogram>",
    ]


def test_one_learning_step_is_a_small_diff(locust):
    before = archive_from_body(locust)
    posture = np.zeros(locust.n_axes)
    posture[0] = 150.0
    after = update_archive(before, locust, posture)
    diff = [line for line in difflib.unified_diff(
        archive_to_string(before).splitlines(), archive_to_string(after).splitlines(), n=0)
        if line[:1] in "+-" and line[:3] not in ("+++", "---")]
    # Each updated axis: one changed trials line and a few run lines, not 360 bins.
    assert 0 < len(diff) < 40


def test_eq4_update_matches_hand_arithmetic(locust):
    # phi: uniform over 4 bins [-180,-90) [-90,0) [0,90) [90,180), N = 1; two frames at
    # 10 and 100 degrees.  Eq. 4 by hand:
    #   N=2, xi=10:  H = (1*H + Δ)/2  = [1/8, 1/8, 5/8, 1/8]
    #   N=3, xi=100: H = (2*H + Δ)/3  = [1/12, 1/12, 5/12, 5/12]
    archive = HistogramArchive({PHI: Histogram(np.full(4, 0.25))})
    angles = np.zeros((3, locust.n_axes))
    angles[:, 0] = [10.0, 100.0, np.nan]  # the NaN frame was not fitted: skipped
    angles[:, 5] = [15.0, 15.5, 16.0]  # beta
    out = update_archive(archive, locust, angles)
    np.testing.assert_allclose(out[PHI].values, [1 / 12, 1 / 12, 5 / 12, 5 / 12], rtol=1e-15)
    assert out[PHI].n_trials == 3
    # beta was not in the archive: it starts from the body's uniform [-30, 60] (90 bins, N=1)
    # and sees three angles in bin [15, 16) (two) and [16, 17) (one).
    beta = out[BETA]
    assert beta.n_trials == 4
    assert beta.at(15.2) == pytest.approx((1 / 90 + 2) / 4)
    assert beta.at(16.5) == pytest.approx((1 / 90 + 1) / 4)
    assert beta.at(0.0) == pytest.approx((1 / 90) / 4)
    # Locked axes are never updated or added.
    assert ("hindleg", "J1", "ry") not in out
    assert out.body == locust.name


def test_update_leaves_locked_axes_unchanged(locust):
    archive = archive_from_body(locust)
    out = update_archive(archive, locust, np.full((5, locust.n_axes), 7.0))
    for key, axis in ((k, r.axis) for k, r in zip(archive, locust.axis_refs(), strict=True)):
        assert (out[key] == archive[key]) == axis.locked


def test_update_checks_the_shape(locust):
    with pytest.raises(KinematicsError, match=r"shape \(n_frames, 9\)"):
        update_archive(archive_from_body(locust), locust, np.zeros((2, 8)))


def test_merge_is_weighted_by_trials():
    a = HistogramArchive({PHI: Histogram([0.5, 0.5, 0.0, 0.0], 3),
                          BETA: Histogram([1.0, 0.0], 2)}, body="locust")
    b = HistogramArchive({PHI: Histogram([0.0, 0.0, 1.0, 0.0], 1)}, body="locust")
    merged = merge_archives([a, b])
    # (3·[.5, .5, 0, 0] + 1·[0, 0, 1, 0]) / 4
    np.testing.assert_allclose(merged[PHI].values, [0.375, 0.375, 0.25, 0.0], rtol=1e-15)
    assert merged[PHI].n_trials == 4
    assert merged[BETA] == a[BETA]  # only in one archive
    assert merged.body == "locust"
    assert merge_archives([a, replace(b, body="other")]).body is None


def test_merge_errors_name_the_axis():
    a = HistogramArchive({PHI: Histogram(np.ones(4))})
    b = HistogramArchive({PHI: Histogram(np.ones(8))})
    with pytest.raises(KinematicsError, match="chain 'hindleg' joint 'J0' axis 'phi'"):
        merge_archives([a, b])
    with pytest.raises(KinematicsError):
        merge_archives([])
    other = HistogramArchive({("frontleg", "J0", "phi"): Histogram(np.ones(4))},
                             source="front.xml")  # another chain: no union of the two
    with pytest.raises(KinematicsError, match=r"front.xml: holds chains \['frontleg'\]"):
        merge_archives([a, other])


def test_apply_archive_onto_a_body(locust):
    learned = Histogram.uniform(120, 220).updated([150.0, 151.0])
    body = apply_archive(locust, HistogramArchive({PHI: learned}))
    axes = {r.label: r.axis for r in body.axis_refs()}
    assert axes["J0.phi"].histogram == learned
    assert axes["J1.beta"].histogram == Histogram.uniform(-30, 60)
    assert apply_archive(locust, archive_from_body(locust)) == locust
    assert archive_from_body(body)[PHI] == learned


@pytest.mark.parametrize(("archive", "words"), [
    (HistogramArchive({("hindleg", "J0", "theta"): Histogram.uniform(0, 1)}), "axis 'theta'"),
    (HistogramArchive({("foreleg", "J0", "phi"): Histogram.uniform(0, 1)}), "chain 'foreleg'"),
    (HistogramArchive({PHI: Histogram(np.ones(36))}), "36 bins"),
])
def test_apply_archive_errors(locust, archive, words):
    with pytest.raises(KinematicsError) as info:
        apply_archive(locust, archive)
    assert words in str(info.value)


def test_archive_keys_are_checked():
    with pytest.raises(KinematicsError):
        HistogramArchive({"J0.phi": Histogram.uniform(0, 1)})


def entry(runs: str, attrs: str = "") -> str:
    return ('<histogram-archive format="1">\n'
            f'  <histogram chain="c" joint="j" axis="a"{attrs}>\n{runs}\n  </histogram>\n'
            "</histogram-archive>\n")


def test_hand_written_runs_are_normalised():
    archive = loads_archive(entry('<run from="-180" to="-90" value="1"/>'
                                  '<run from="90" to="180" value="3"/>', ' bins="4" trials="7"'))
    h = archive[("c", "j", "a")]
    assert np.array_equal(h.values, [0.25, 0.0, 0.0, 0.75]) and h.n_trials == 7


@pytest.mark.parametrize(("runs", "attrs", "line", "words"), [
    ('<run from="0.5" to="2" value="1"/>', "", 3, "not a bin edge"),
    ('<run from="0" to="400" value="1"/>', "", 3, "not a bin edge"),
    ('<run from="-1e308" to="10" value="1"/>', "", 3, "-1e+308 is not a bin edge"),
    ('<run from="0" to="1e308" value="1"/>', "", 3, "1e+308 is not a bin edge"),
    ('<run from="10" to="0" value="1"/>', "", 3, "from < to"),
    ('<run from="0" to="10" value="-1"/>', "", 3, "must be >= 0"),
    ('<run from="0" to="10" value="NaN"/>', "", 3, "not a finite number"),
    ('<run from="0" to="10" value="1"/>\n<run from="5" to="20" value="1"/>', "", 4, "overlaps"),
    ('<run from="0" to="10" value="0"/>', "", 2, "empty"),
    ("", "", 2, "empty"),
    ('<run from="0" to="10" value="1"/>', ' bins="0"', 2, "whole number"),
    ('<run from="0" to="10" value="1"/>', ' bins="100000"', 2, "greater than 36000"),
    ('<run from="0" to="10" value="1"/>', ' trials="0"', 2, "whole number >= 1"),
    ('<run from="0" to="10"/>', "", 3, "attribute 'value' is missing"),
])
def test_broken_archive_names_line(runs, attrs, line, words):
    with pytest.raises(KinematicsError) as info:
        loads_archive(entry(runs, attrs), "h.xml")
    msg = str(info.value)
    assert msg.startswith(f"h.xml:{line}: ") and words in msg and "\n" not in msg


def test_duplicate_entry_names_both_lines(tmp_path):
    one = '  <histogram chain="c" joint="j" axis="a"><run from="0" to="1" value="1"/></histogram>'
    path = tmp_path / "dup.xml"
    path.write_text(f'<histogram-archive format="1">\n{one}\n{one}\n</histogram-archive>\n')
    with pytest.raises(KinematicsError) as info:
        load_archive(path)
    assert str(info.value).startswith(f"{path}:3: ")
    assert "duplicate histogram (first on line 2)" in str(info.value)
