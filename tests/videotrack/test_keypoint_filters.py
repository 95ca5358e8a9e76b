"""The 2D keypoint filters on planted data: threshold, median with offset threshold, Viterbi
(numba kernel and its NumPy twin agree)."""

from __future__ import annotations

import numpy as np
import pytest

from videotrack.errors import VideoTrackError
from videotrack.io.keypoints import make_tracks
from videotrack.markerless import filters as kf


def smooth_truth(n=120, k=4):
    t = np.arange(n)[:, None]
    x = 300 + 80 * np.sin(t / 15 + np.arange(k))
    y = 250 + 60 * np.cos(t / 11 + 2 * np.arange(k))
    return np.stack([x, y], axis=2)


def planted(n=120, k=4, share=0.1, seed=0, jump=150.0):
    """Noisy keypoints with a share of outliers (far jumps, middling scores)."""
    rng = np.random.default_rng(seed)
    truth = smooth_truth(n, k)
    xy = truth + rng.normal(0, 1.0, truth.shape)
    score = rng.uniform(0.7, 1.0, (n, k))
    bad = rng.random((n, k)) < share
    bad[0] = False
    angle = rng.uniform(0, 2 * np.pi, bad.sum())
    xy[bad] += jump * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    score[bad] = rng.uniform(0.3, 0.7, bad.sum())
    return truth, make_tracks([f"k{i}" for i in range(k)], xy, score, np.arange(n), "p"), bad


def errors(tracks, truth):
    return np.linalg.norm(tracks.xy - truth, axis=2)


def test_threshold_drops_low_scores_only():
    _, t, _ = planted()
    out = kf.threshold(t, 0.5)
    assert np.array_equal(out.missing, t.missing | (t.score < 0.5))
    kept = ~out.missing
    np.testing.assert_array_equal(out.xy[kept], t.xy[kept])


def test_rolling_median_ignores_nan_and_shrinks_at_ends():
    v = np.array([1.0, 5.0, np.nan, 3.0, 100.0, 4.0, 2.0])
    np.testing.assert_allclose(kf.rolling_median(v, 3), [3, 3, 4, 51.5, 4, 4, 3])
    with pytest.raises(VideoTrackError, match="odd"):
        kf.rolling_median(v, 4)


def test_median_filter_drops_outliers_keeps_good_points():
    truth, t, bad = planted()
    out = kf.median(t, 7, 25.0)
    assert out.missing[bad].all()  # every 150 px jump dropped
    good = ~bad
    assert out.missing[good].mean() < 0.01  # good points stay
    np.testing.assert_array_equal(out.xy[~out.missing], t.xy[~out.missing])  # never moved
    assert np.nanmax(errors(out, truth)) < 5


def test_viterbi_replaces_outliers_by_a_held_position():
    truth, t, bad = planted()
    out = kf.viterbi(t, n_back=4, sigma=20.0)
    err = errors(out, truth)
    assert np.isnan(err).mean() < 0.01
    assert np.nanmax(err) < 15  # outliers replaced by a recent good detection
    assert np.all(out.score[bad] <= 0.5 + 1e-12)  # a held detection's score is halved


def test_viterbi_follows_the_right_animal_among_candidates():
    truth, _, _ = planted(share=0.0)
    rng = np.random.default_rng(5)
    n, k = truth.shape[:2]
    other = truth + np.array([200.0, 0.0])  # another animal
    xy, score = truth.copy(), np.full((n, k), 0.9)
    swap = rng.random((n, k)) < 0.15  # the tracker swapped the two animals here
    swap[0] = False
    xy[swap] = other[swap]
    cand = np.concatenate([np.where(swap[..., None], truth, other), np.full((n, k, 1), 0.9)],
                          axis=2)[:, None]
    t = make_tracks([f"k{i}" for i in range(k)], xy, score, np.arange(n), "p",
                    candidates=cand)
    out = kf.viterbi(t, n_back=1, sigma=20.0)
    np.testing.assert_allclose(out.xy, truth)  # swaps undone from the candidates
    alone = kf.viterbi(t, n_back=1, sigma=20.0, candidates=False)
    # without them no swapped point can come back: it is dropped or stays on the other animal
    assert not np.any(np.linalg.norm(alone.xy[swap] - truth[swap], axis=1) < 1)


def test_viterbi_numba_and_numpy_agree():
    _, t, _ = planted(n=80, k=3, share=0.2, seed=3)
    pxy, plog = kf.viterbi_candidates(t, n_back=3)
    a = kf.viterbi_path_numba(pxy, plog, 25.0)
    b = kf.viterbi_path_numpy(pxy, plog, 25.0)
    np.testing.assert_array_equal(a, b)
    assert len(np.unique(a)) > 2  # the path uses several kinds of candidates


def test_apply_filters_and_settings():
    truth, t, _ = planted()
    s = kf.KeypointFilterSettings(score_threshold=0.2, viterbi=True, median=7, sigma=20.0)
    out = kf.apply_filters(t, s)
    assert np.nanmax(errors(out, truth)) < 15
    assert kf.apply_filters(t, kf.KeypointFilterSettings()) is t  # all off by default
    with pytest.raises(VideoTrackError, match="median: must be odd"):
        kf.KeypointFilterSettings(median=4)


def test_temporal_filters_treat_skipped_frames_as_gaps():
    """A lone detection 20 frames from the others is no outlier of their trajectory: neither
    filter compares it with rows a gap away. Numbered as neighbours, both remove it."""
    n = 20
    xy = np.full((n, 1, 2), 100.0)
    xy[10, 0, 0] = 200.0
    frames = np.concatenate([np.arange(10), [30], np.arange(60, 69)])
    score = np.full((n, 1), 0.9)
    apart = make_tracks(["k"], xy, score, frames, "gaps")
    assert not kf.median(apart, 5, 25.0).missing.any()
    out = kf.viterbi(apart, n_back=4, sigma=5.0)
    np.testing.assert_array_equal(out.xy, xy)
    np.testing.assert_array_equal(out.frames, frames)
    together = make_tracks(["k"], xy, score, np.arange(n), "no gaps")
    assert kf.median(together, 5, 25.0).missing[:, 0].tolist() == [i == 10 for i in range(n)]
    assert kf.viterbi(together, n_back=4, sigma=5.0).xy[10, 0, 0] == 100.0  # held instead
