"""2D keypoint filters (Anipose's set): a likelihood threshold, a median filter with an
offset threshold, and a Viterbi filter over candidate positions.

All take and return :class:`~videotrack.io.keypoints.KeypointTracks`; a filter never moves a
point, it only drops it (NaN) or, for the Viterbi filter, picks another candidate. The temporal
filters follow the frame numbers: frames a file skips are gaps, not neighbours.
:func:`apply_filters` runs the configured ones in the order threshold -> Viterbi -> median
(the Viterbi filter needs the scores the threshold leaves, the median filter then cleans what
the Viterbi path still holds).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from videotrack.errors import VideoTrackError
from videotrack.io.keypoints import KeypointTracks

#: Emission and transition probability of the "missing" candidate (Anipose's 0.001).
MISSING_P = 1e-3
_TRANS_FLOOR = -100.0  # log-probability floor of a transition (Anipose's)
_BAND = 2.0  # px: a transition's probability is that of a step within +-2 px of its length


@dataclass(frozen=True)
class KeypointFilterSettings:
    """The ``[keypoints.filter]`` settings; every filter is off by default."""

    score_threshold: float = field(default=0.0, metadata={
        "doc": "drop keypoints scored below this (0 = keep all)", "min": 0.0, "max": 1.0})
    median: int = field(default=0, metadata={
        "doc": "median filter window in frames, odd (0 = off)", "min": 0})
    offset_threshold: float = field(default=25.0, metadata={
        "doc": "median filter: drop points farther than this (px, |dx|+|dy|) from the "
               "median-filtered trajectory", "min": 0.0})
    viterbi: bool = field(default=False, metadata={
        "doc": "pick each keypoint's most likely path through its candidates"})
    n_back: int = field(default=4, metadata={
        "doc": "Viterbi: candidates include a keypoint's detections of this many frames "
               "(this one and earlier ones)", "min": 1})
    sigma: float = field(default=30.0, metadata={
        "doc": "Viterbi: spread (px) of a keypoint's step from one frame to the next",
        "min": 0.0})
    candidates: bool = field(default=True, metadata={
        "doc": "Viterbi: also consider other animals'/people's detections of the keypoint"})

    def __post_init__(self):
        if self.median and self.median % 2 == 0:
            raise VideoTrackError(f"must be odd, got {self.median}", field="median")
        if self.sigma <= 0:
            raise VideoTrackError("must be > 0", field="sigma")
        if self.n_back < 1:
            raise VideoTrackError("must be >= 1", field="n_back")

    @property
    def active(self) -> bool:
        return bool(self.score_threshold > 0 or self.median or self.viterbi)


def apply_filters(tracks: KeypointTracks, settings: KeypointFilterSettings) -> KeypointTracks:
    """Run the filters ``settings`` turns on (see the module doc for the order). The
    temporal ones (median, Viterbi) are refused on labelled images, which are not a video."""
    if tracks.images and (settings.median or settings.viterbi):
        which = "the median filter" if settings.median else "the Viterbi filter"
        raise VideoTrackError(
            f"{which} needs a video's consecutive frames, and these rows are labelled images "
            "(hand labels of frames picked from a video): filter by score only",
            file=tracks.source, field="median" if settings.median else "viterbi")
    if settings.score_threshold > 0:
        tracks = threshold(tracks, settings.score_threshold)
    if settings.viterbi:
        tracks = viterbi(tracks, n_back=settings.n_back, sigma=settings.sigma,
                         candidates=settings.candidates, min_score=settings.score_threshold)
    if settings.median:
        tracks = median(tracks, settings.median, settings.offset_threshold)
    return tracks


def _drop(tracks: KeypointTracks, bad: np.ndarray) -> KeypointTracks:
    xy, score = tracks.xy.copy(), tracks.score.copy()
    xy[bad] = np.nan
    score[bad] = np.nan
    return tracks.replace(xy=xy, score=score)


def threshold(tracks: KeypointTracks, min_score: float) -> KeypointTracks:
    """Drop keypoints scored below ``min_score``."""
    return _drop(tracks, ~(tracks.score >= min_score))


def rolling_median(values: np.ndarray, window: int) -> np.ndarray:
    """NaN-ignoring centred running median along axis 0 (the window shrinks at the ends);
    NaN where a window holds no value."""
    if window < 1 or window % 2 == 0:
        raise VideoTrackError(f"median window must be odd and >= 1, got {window}",
                              field="median")
    half = window // 2
    pad = [(half, half)] + [(0, 0)] * (values.ndim - 1)
    padded = np.pad(values, pad, constant_values=np.nan)
    windows = np.lib.stride_tricks.sliding_window_view(padded, window, axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows give NaN
        return np.nanmedian(windows, axis=-1)


def median(tracks: KeypointTracks, window: int = 13, offset_threshold: float = 25.0
           ) -> KeypointTracks:
    """Anipose's median filter: drop points whose distance |dx| + |dy| from the
    median-filtered trajectory of their keypoint is ``offset_threshold`` px or more."""
    rows, full = _on_all_frames(tracks)
    med = rolling_median(full.xy, window)[rows]
    err = np.abs(tracks.xy - med).sum(axis=2)
    return _drop(tracks, err >= offset_threshold)


def _on_all_frames(tracks: KeypointTracks) -> tuple[np.ndarray, KeypointTracks]:
    """The tracks on every frame from their first to their last, missing in the frames they
    skip (labelled images, dropped frames), so that the temporal filters never take two rows
    a gap apart for neighbours; and the rows of the original frames in them."""
    rows = tracks.frames - tracks.frames[0] if tracks.n_frames else tracks.frames
    if tracks.n_frames == 0 or rows[-1] == tracks.n_frames - 1:
        return np.arange(tracks.n_frames), tracks

    def spread(values):
        full = np.full((rows[-1] + 1, *values.shape[1:]), np.nan)
        full[rows] = values
        return full

    cand = None if tracks.candidates is None else spread(tracks.candidates)
    return rows, tracks.replace(xy=spread(tracks.xy), score=spread(tracks.score),
                                frames=tracks.frames[0] + np.arange(rows[-1] + 1),
                                candidates=cand)


# -- Viterbi ---------------------------------------------------------------------------------


def viterbi_candidates(tracks: KeypointTracks, n_back: int = 4, candidates: bool = True,
                       min_score: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Each keypoint's candidate positions per frame, as Anipose builds them.

    Candidates of frame i: every detection (the tracked individual's and, with
    ``candidates``, the others') of frames i, i-1, ..., i-n_back+1, a detection j frames old
    with its score halved j times (holding a position costs); slot 0 is "missing".

    Returns ``pxy`` (n_frames, n_kp, n_slots, 2) and ``plog`` (n_frames, n_kp, n_slots), the
    log score of each candidate, -inf for empty slots.
    """
    det = np.concatenate([tracks.xy, tracks.score[..., None]], axis=2)[:, None]
    if candidates and tracks.candidates is not None:
        det = np.concatenate([det, tracks.candidates], axis=1)  # (n, n_det, kp, 3)
    n, n_det, k, _ = det.shape
    ok = np.isfinite(det).all(axis=3) & (det[..., 2] > 0) & (det[..., 2] >= min_score)
    pxy = np.zeros((n, k, 1 + n_back * n_det, 2))
    plog = np.full((n, k, 1 + n_back * n_det), -np.inf)
    plog[:, :, 0] = math.log(MISSING_P)
    for j in range(min(n_back, n)):
        lag = det[: n - j]  # detections j frames earlier, for frames j..n-1
        good = ok[: n - j]
        slots = slice(1 + j * n_det, 1 + (j + 1) * n_det)
        pxy[j:, :, slots] = np.where(good[..., None], lag[..., :2], 0.0).transpose(0, 2, 1, 3)
        with np.errstate(divide="ignore"):
            lp = np.where(good, np.log(np.where(good, lag[..., 2], 1.0)) - j * math.log(2.0),
                          -np.inf)
        plog[j:, :, slots] = lp.transpose(0, 2, 1)
    return pxy, plog


def _trans_numpy(a: np.ndarray, b: np.ndarray, sigma: float) -> np.ndarray:
    """Log-probability (..., n_b, n_a) of a step from each candidate a to each candidate b:
    that a normal step of spread ``sigma`` has a length within +-2 px of |b - a|."""
    from scipy.special import erfc

    d = np.sqrt(((b[..., :, None, :] - a[..., None, :, :]) ** 2).sum(axis=-1))
    s = sigma * math.sqrt(2.0)
    p = 0.5 * (erfc((d - _BAND) / s) - erfc((d + _BAND) / s))
    with np.errstate(divide="ignore"):
        return np.maximum(np.log(p), _TRANS_FLOOR)


def viterbi_path_numpy(pxy: np.ndarray, plog: np.ndarray, sigma: float) -> np.ndarray:
    """The most likely candidate slot per frame and keypoint (n_frames, n_kp); vectorised
    over keypoints, a loop over frames. Twin of :func:`viterbi_path_numba`."""
    n, k, m = plog.shape
    miss = math.log(MISSING_P)
    back = np.zeros((n, k, m), np.int64)
    cost = plog[0].copy()
    for i in range(1, n):
        trans = _trans_numpy(pxy[i - 1], pxy[i], sigma)  # (k, m_b, m_a)
        trans[:, 0, :] = miss  # to or from "missing"
        trans[:, :, 0] = miss
        possible = cost[:, None, :] + trans
        back[i] = np.argmax(possible, axis=2)
        cost = np.take_along_axis(possible, back[i][..., None], axis=2)[..., 0] + plog[i]
    out = np.zeros((n, k), np.int64)
    out[-1] = np.argmax(cost, axis=1)
    for i in range(n - 1, 0, -1):
        out[i - 1] = np.take_along_axis(back[i], out[i][:, None], axis=1)[:, 0]
    return out


@njit(cache=True, nogil=True, parallel=True)
def viterbi_path_numba(pxy, plog, sigma):  # pragma: no cover - compiled
    """Numba twin of :func:`viterbi_path_numpy` (same arithmetic, loops; keypoints run in
    parallel)."""
    n, k, m = plog.shape
    miss = math.log(MISSING_P)
    s = sigma * math.sqrt(2.0)
    far2 = (_BAND + 10.0 * s) ** 2  # beyond: 0.5 erfc(10) < 1e-45, below exp(_TRANS_FLOOR)
    out = np.zeros((n, k), np.int64)
    for kp in prange(k):
        back = np.zeros((n, m), np.int64)
        cost = np.empty(m)
        new = np.empty(m)
        for b in range(m):
            cost[b] = plog[0, kp, b]
        for i in range(1, n):
            for b in range(m):
                best, arg = -np.inf, 0
                if plog[i, kp, b] == -np.inf:  # an empty slot: no path ends here
                    new[b] = -np.inf
                    continue
                for a in range(m):
                    if cost[a] == -np.inf:
                        continue
                    if b == 0 or a == 0:
                        t = miss
                    else:
                        dx = pxy[i, kp, b, 0] - pxy[i - 1, kp, a, 0]
                        dy = pxy[i, kp, b, 1] - pxy[i - 1, kp, a, 1]
                        d2 = dx * dx + dy * dy
                        if d2 > far2:  # p < 1e-45: the floor, as in the NumPy twin
                            t = _TRANS_FLOOR
                        else:
                            d = math.sqrt(d2)
                            p = 0.5 * (math.erfc((d - _BAND) / s)
                                       - math.erfc((d + _BAND) / s))
                            t = math.log(p) if p > 0 else -np.inf
                            if t < _TRANS_FLOOR:
                                t = _TRANS_FLOOR
                    v = cost[a] + t
                    if v > best:
                        best, arg = v, a
                back[i, b] = arg
                new[b] = best + plog[i, kp, b]
            cost[:] = new
        arg, best = 0, -np.inf
        for b in range(m):
            if cost[b] > best:
                best, arg = cost[b], b
        out[n - 1, kp] = arg
        for i in range(n - 1, 0, -1):
            out[i - 1, kp] = back[i, out[i, kp]]
    return out


def viterbi(tracks: KeypointTracks, n_back: int = 4, sigma: float = 30.0,
            candidates: bool = True, min_score: float = 0.0, engine: str = "numba"
            ) -> KeypointTracks:
    """Anipose's Viterbi filter: per keypoint, the path through the candidates of
    :func:`viterbi_candidates` that maximises the product of the candidates' scores and the
    probabilities of the steps between them. Frames whose best candidate is "missing" are
    dropped; the kept points carry their candidate's (possibly halved) score."""
    if tracks.n_frames == 0:
        return tracks
    rows, full = _on_all_frames(tracks)
    pxy, plog = viterbi_candidates(full, n_back, candidates, min_score)
    if engine == "numba":
        path = viterbi_path_numba(np.ascontiguousarray(pxy), np.ascontiguousarray(plog),
                                  float(sigma))
    elif engine == "numpy":
        path = viterbi_path_numpy(pxy, plog, float(sigma))
    else:
        raise ValueError(f"unknown engine {engine!r}")
    path, pxy, plog = path[rows], pxy[rows], plog[rows]
    xy = np.take_along_axis(pxy, path[..., None, None], axis=2)[:, :, 0]
    score = np.exp(np.take_along_axis(plog, path[..., None], axis=2)[..., 0])
    missing = path == 0
    xy[missing] = np.nan
    score[missing] = np.nan
    return tracks.replace(xy=xy, score=np.clip(score, 0.0, 1.0))
