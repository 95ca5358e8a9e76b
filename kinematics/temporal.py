"""Ambiguous postures resolved over time: candidate postures per frame and the most plausible
path through them (paper Sect. 3.2-4: mirror postures and γ flips fit a frame as well as the
truth; the movement's continuity tells them apart).

Fitting stays frame-independent: every frame is annealed on its own random streams and keeps
its distinct results (:func:`distinct`); the path (:func:`choose_path`) only chooses one
candidate per frame. It is a Viterbi pass minimising

    sum_t  u_t(c_t)  +  w · sum_t  T(c_{t-1}, c_t)

with ``u`` the candidate's E per marker image in excess of the frame's best (pixels) and
``T`` the squared posture change between consecutive frames, each axis in units of its
histogram spread s(H) (a flip by one spread costs 1), truncated at :data:`JUMP_CAP` (a
robust loss: at a cut in the movement nobody announced, a wrong candidate that happens to
lie between the two sequences saves nothing). A change that no pair of candidates
explains (every T above :data:`BREAK_COST`) is a cut in the movement (concatenated
sequences, a gap): the path restarts there, so sequences stay independent.

Everything works on *postures*: a flat vector per candidate (joint angles in degrees, then
root positions), with a per-entry scale; :func:`posture_scale` builds the scale of a body.
"""

from __future__ import annotations

import itertools

import numpy as np

#: A transition costing more than this for every pair of candidates is a cut (5 spreads).
BREAK_COST = 25.0
#: The most one transition costs the path (2 spreads squared): beyond it a jump is a jump.
JUMP_CAP = 4.0
#: A jump of the best candidates larger than CUT_RATIO x the typical change (at least
#: CUT_MIN) between stretches that each move by at most STILL_RATIO x it is a cut.
CUT_RATIO, CUT_MIN, STILL_RATIO, STILL_MIN = 50.0, 1.0, 4.0, 0.05


def angle_difference(a, b, n_angles: int) -> np.ndarray:
    """``a - b`` over the last axis, the first ``n_angles`` entries (degrees) wrapped into
    [-180, 180)."""
    d = np.asarray(a, float) - np.asarray(b, float)
    d[..., :n_angles] = (d[..., :n_angles] + 180.0) % 360.0 - 180.0
    return d


def distinct(postures, errors, tolerance, n_angles: int, keep: int) -> np.ndarray:
    """Indices of up to ``keep`` distinct candidates of one frame, lowest error first.

    Parameters
    ----------
    postures : (R, d) candidate postures (NaN rows: runs not made)
    errors : (R,) their E (NaN: not made)
    tolerance : (d,) candidates nearer than this on every entry are the same posture (the
        lower E is kept)
    n_angles : leading entries that are angles in degrees (compared modulo 360)
    keep : how many to keep at most
    """
    postures = np.asarray(postures, float)
    errors = np.asarray(errors, float)
    order = [int(i) for i in np.argsort(errors, kind="stable") if np.isfinite(errors[i])]
    kept: list[int] = []
    for i in order:
        if len(kept) >= keep:
            break
        if all((np.abs(angle_difference(postures[i], postures[j], n_angles))
                > tolerance).any() for j in kept):
            kept.append(i)
    return np.array(kept, np.int64)


def transition_costs(prev, cur, scale, n_angles: int) -> np.ndarray:
    """(K_prev, K_cur) squared posture change in units of ``scale`` (NaN rows -> inf)."""
    d = angle_difference(cur[None, :, :], prev[:, None, :], n_angles) / scale
    cost = np.sum(d * d, axis=-1)
    return np.where(np.isfinite(cost), cost, np.inf)


def cuts(best, scale, n_angles: int) -> np.ndarray:
    """Where the movement itself jumps (concatenated sequences): ``(n,)`` bool, True where
    frame t starts a new stretch. ``best`` (n, d) is each frame's lowest-E posture (NaN rows:
    none). A cut needs a jump from t-1 to t much larger than the typical frame-to-frame change
    while the two frames before and the three from t on move little: an isolated wrong frame,
    or a short run of them, is not a cut (the path is what sorts those out)."""
    best = np.asarray(best, float)
    n = best.shape[0]
    out = np.zeros(n, bool)
    if n < 5:
        return out
    d = angle_difference(best[1:], best[:-1], n_angles) / scale
    jump = np.r_[np.nan, np.sum(d * d, axis=1)]  # jump[t]: from t-1 to t
    typical = np.nanmedian(jump) if np.isfinite(jump).any() else 0.0
    hi = max(CUT_MIN, CUT_RATIO * typical)
    lo = max(STILL_MIN, STILL_RATIO * typical)
    for t in range(2, n - 2):
        if jump[t] > hi and jump[t - 1] <= lo and jump[t + 1] <= lo and jump[t + 2] <= lo:
            out[t] = True
    return out


def choose_path(unary, postures, scale, n_angles: int, weight: float = 1.0,
                breaks=None, anchor=None) -> np.ndarray:
    """One candidate per frame minimising the summed cost (module doc).

    Parameters
    ----------
    unary : (n, K) per-frame cost of each candidate (inf or NaN: no such candidate)
    postures : (n, K, d) candidate postures
    scale : (d,) per-entry scale of a posture change (e.g. :func:`posture_scale`)
    n_angles : leading posture entries that are angles (degrees, compared modulo 360)
    weight : weight of continuity against the per-frame cost; 0 keeps every frame's best
    breaks : (n,) bool, optional: frame t starts a new sequence (no transition from t-1)
    anchor : (d,) optional posture chosen just before frame 0 (the left end of a window)

    Returns
    -------
    (n,) index of the chosen candidate per frame (-1 for a frame without any)
    """
    unary = np.asarray(unary, float)
    unary = np.where(np.isfinite(unary), unary, np.inf)
    postures = np.asarray(postures, float)
    n = unary.shape[0]
    scale = np.asarray(scale, float)
    choice = np.full(n, -1, np.int64)
    raw = [None] + [transition_costs(postures[t - 1], postures[t], scale, n_angles)
                    for t in range(1, n)]
    trans = [None] + [np.minimum(c, JUMP_CAP) for c in raw[1:]]
    cut = np.zeros(n, bool) if breaks is None else np.asarray(breaks, bool).copy()
    has = np.isfinite(unary).any(axis=1)
    for t in range(n):
        cut[t] |= (t == 0 or weight == 0 or not (has[t] and has[t - 1])
                   or np.min(raw[t]) > BREAK_COST)
    start0 = None
    if anchor is not None and weight > 0 and n and not (breaks is not None and breaks[0]):
        t0 = transition_costs(np.asarray(anchor, float)[None], postures[0], scale, n_angles)[0]
        if np.min(t0) <= BREAK_COST:
            start0 = weight * np.minimum(t0, JUMP_CAP)
    bounds = np.r_[np.flatnonzero(cut), n]
    for a, b in itertools.pairwise(bounds):
        if not has[a]:
            continue
        total = unary[a] + (start0 if a == 0 and start0 is not None else 0.0)
        back = []
        for t in range(a + 1, b):
            step = total[:, None] + weight * trans[t]
            arg = np.argmin(step, axis=0)
            back.append(arg)
            total = step[arg, np.arange(step.shape[1])] + unary[t]
        j = int(np.argmin(total))
        choice[b - 1] = j
        for t in range(b - 1, a, -1):
            j = int(back[t - a - 1][j])
            choice[t - 1] = j
    return choice
