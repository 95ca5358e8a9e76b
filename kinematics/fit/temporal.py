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
root positions), with a per-entry scale; the fitter builds the scale of a body
(``Fitter._posture_scale``).

For the status (the fitter's ``ambiguous``): :func:`solve_path` also gives each candidate's
min-marginal cost (the least cost of a path through it), which says how surely the path
rules an alternative out, and :func:`kinks` finds frames off the line through their
neighbours (a wrong frame that fits better than the truth but breaks the movement).
"""

from __future__ import annotations

import itertools

import numpy as np

from kinematics._kernels.temporal import path_dp

#: A transition costing more than this for every pair of candidates is a cut (5 spreads).
BREAK_COST = 25.0
#: The most one transition costs the path (2 spreads squared): beyond it a jump is a jump.
JUMP_CAP = 4.0
#: A jump of the best candidates larger than CUT_RATIO x the typical change (at least
#: CUT_MIN) between stretches that each move by at most STILL_RATIO x it is a cut.
CUT_RATIO, CUT_MIN, STILL_RATIO, STILL_MIN = 50.0, 1.0, 4.0, 0.05
#: ... or where the stretch before it moves more, by at most 1 / CUT_DWARF of the jump (a
#: wrong frame's return just before the cut: a cut that went unseen flagged both its sides)
CUT_DWARF = 10.0
#: A large jump is no cut when within WRONG_STRETCH frames after it, on two frames running, a
#: candidate lies within RETURN_RATIO x the jump of where the movement before it was heading
#: (or, before it, of where the movement after it came from): a wrong stretch. Two jumps at
#: most WRONG_STRETCH apart also bound a stretch the status flags whole.
WRONG_STRETCH, RETURN_RATIO = 16, 0.1
#: A frame kinks the path when it lies farther from the midpoint of its two neighbours than
#: KINK_RATIO x the typical such distance (squared, in spreads; at least KINK_MIN) and more
#: than KINK_OWN x its neighbours' own kinks (a wrong frame's neighbours kink by a quarter).
KINK_RATIO, KINK_MIN, KINK_OWN = 500.0, 0.05, 0.5
#: ... and the frames between two kinks at most this many frames apart.
KINK_GAP = 1


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
    """(..., K_prev, K_cur) squared posture change in units of ``scale`` (NaN rows -> inf)
    from ``prev`` (..., K_prev, d) to ``cur`` (..., K_cur, d)."""
    prev, cur = np.asarray(prev, float), np.asarray(cur, float)
    d = angle_difference(cur[..., None, :, :], prev[..., :, None, :], n_angles) / scale
    cost = np.sum(d * d, axis=-1)
    return np.where(np.isfinite(cost), cost, np.inf)


def transitions(postures, scale, n_angles: int) -> np.ndarray:
    """(n - 1, K, K): :func:`transition_costs` from every frame of ``postures`` (n, K, d) to
    the next, in one array operation (a call per frame was most of the path's time)."""
    postures = np.asarray(postures, float)
    return transition_costs(postures[:-1], postures[1:], scale, n_angles)


def cuts(postures, scale, n_angles: int, before: int = 0) -> np.ndarray:
    """Where the movement itself jumps (concatenated sequences): ``(n,)`` bool, True where
    frame t starts a new stretch.

    ``postures`` is (n, d), each frame's posture, or (n, K, d), its candidates (NaN rows:
    none); the change from t-1 to t is the smallest over pairs of candidates, so a frame whose
    lowest-E candidate is wrong but another is right does not hide a cut next to it. The
    first ``before`` frames are context only (frames decided earlier): they are never cuts,
    but let a cut be found at the first frames after them. A cut needs a jump from t-1 to t
    much larger than the typical frame-to-frame change while the two frames before (or, a
    wrong frame's return, by at most 1 / :data:`CUT_DWARF` of the jump) and the three from
    t on move little: an isolated wrong frame, or a short run of them, is not a
    cut (the path is what sorts those out); nor is a jump after which, within
    :data:`WRONG_STRETCH` frames, two frames running have a candidate where the movement
    before the jump was heading (a longer wrong stretch, e.g. a marker lost for a while)."""
    postures = np.asarray(postures, float)
    if postures.ndim == 2:
        postures = postures[:, None]
    n = postures.shape[0]
    out = np.zeros(n, bool)
    if n < 5:
        return out[before:]
    jump = np.full(n, np.nan)  # jump[t]: from t-1 to t
    least = transitions(postures, scale, n_angles).min(axis=(1, 2))
    jump[1:] = np.where(np.isfinite(least), least, np.nan)
    typical = np.nanmedian(jump) if np.isfinite(jump).any() else 0.0
    hi = max(CUT_MIN, CUT_RATIO * typical)
    lo = max(STILL_MIN, STILL_RATIO * typical)
    for t in range(max(2, before), n - 2):
        # the step before may be a wrong frame's return, where the cut dwarfs it
        before_t = jump[t - 1] <= lo or jump[t - 1] * CUT_DWARF <= jump[t]
        if jump[t] > hi and before_t and jump[t + 1] <= lo and jump[t + 2] <= lo:
            out[t] = True
    # a jump into (or out of) a wrong stretch, e.g. a marker lost for a while, is no cut:
    # within WRONG_STRETCH frames after (before) it, two frames running have a candidate
    # where the movement before (after) it was heading
    for t in np.flatnonzero(out):
        if _resumes(postures, t - 1, -1, jump[t], scale, n_angles) or _resumes(
                postures, t, 1, jump[t], scale, n_angles):
            out[t] = False
    return out[before:]


def kinks(postures, scale, n_angles: int, breaks=None, seen=None) -> np.ndarray:
    """Frames where a chosen path kinks: ``(n,)`` bool (constants :data:`KINK_RATIO`, ...).

    Smooth movement passes close to the midpoint of its neighbours; a wrong frame in a right
    stretch (a marker taken by a ghost for a frame or two) does not, however small the jump
    it makes, so this finds wrong frames that the first difference, which carries the
    movement itself, misses. ``postures`` (n, d) is one posture per frame (NaN rows: none);
    ``breaks`` marks frames that start a new stretch (no kink is measured across one);
    ``seen`` (n,) bool, where given, the frames whose kink may count (before the frames
    between two kinks are added)."""
    postures = np.asarray(postures, float)
    n = postures.shape[0]
    cut = np.zeros(n, bool) if breaks is None else np.asarray(breaks, bool)
    kink = np.full(n, np.nan)
    if n > 2:  # every frame at once (a call per frame was most of this function's time)
        mid = postures[:-2] + angle_difference(postures[2:], postures[:-2], n_angles) / 2.0
        d = angle_difference(postures[1:-1], mid, n_angles) / scale
        kink[1:-1] = np.where(cut[1:-1] | cut[2:], np.nan, np.sum(d * d, axis=-1))
    if not np.isfinite(kink).any():
        return np.zeros(n, bool)
    limit = max(KINK_MIN, KINK_RATIO * np.nanmedian(kink))
    side = np.fmax(np.r_[np.nan, kink[:-1]], np.r_[kink[1:], np.nan])
    with np.errstate(invalid="ignore"):
        out = (kink > limit) & ~(kink < KINK_OWN * side)
    if seen is not None:
        out &= np.asarray(seen, bool)
    # a short wrong stretch kinks where it starts and ends, not inside: the frames between
    # two kinks at most KINK_GAP apart go with them
    at = np.flatnonzero(out)
    for a, b in itertools.pairwise(at):
        if 1 < b - a <= KINK_GAP + 1 and not cut[a + 1:b + 1].any():
            out[a + 1:b] = True
    return out


def _resumes(postures, t: int, back: int, size: float, scale, n_angles: int) -> bool:
    """Whether the movement at frame ``t`` (its lowest-E candidate, heading away from frame
    ``t + back``) is found again, on two frames running, within :data:`WRONG_STRETCH` frames
    on the other side of a jump of ``size`` (within :data:`RETURN_RATIO` x ``size``)."""
    n = postures.shape[0]
    here = postures[t, 0]
    if not (0 <= t + back < n):
        return False
    pair = transition_costs(postures[t + back], here[None], scale, n_angles)[:, 0]
    if not np.isfinite(pair).any():
        return False
    step = angle_difference(here, postures[t + back, np.argmin(pair)], n_angles)
    ahead = -back
    found = [np.min(transition_costs((here + k * step)[None], postures[t + ahead * k], scale,
                                     n_angles)) < RETURN_RATIO * size
             for k in range(2, WRONG_STRETCH + 3) if 0 <= t + ahead * k < n]
    return any(a and b for a, b in itertools.pairwise(found))


def _path_numpy(unary, trans, bounds, start0, use_start0, choice, cost) -> None:
    """NumPy twin of :func:`kinematics._kernels.temporal.path_dp` (its test oracle): the
    same arguments, the same outputs to the bit."""
    for a, b in itertools.pairwise(bounds):
        if not np.isfinite(unary[a]).any():
            continue
        # forward: least cost of a path ending at each candidate; backward: least cost of
        # the rest of the stretch after it
        ahead = [unary[a] + (start0 if a == 0 and use_start0 else 0.0)]
        back = []
        for t in range(a + 1, b):
            step = ahead[-1][:, None] + trans[t]
            arg = np.argmin(step, axis=0)
            back.append(arg)
            ahead.append(step[arg, np.arange(step.shape[1])] + unary[t])
        rest = np.zeros(unary.shape[1])
        for t in range(b - 1, a - 1, -1):
            cost[t] = ahead[t - a] + rest
            if t > a:
                rest = np.min(trans[t] + (unary[t] + rest)[None, :], axis=1)
        j = int(np.argmin(ahead[-1]))
        choice[b - 1] = j
        for t in range(b - 1, a, -1):
            j = int(back[t - a - 1][j])
            choice[t - 1] = j


def choose_path(unary, postures, scale, n_angles: int, weight: float = 1.0,
                breaks=None, anchor=None) -> np.ndarray:
    """One candidate per frame minimising the summed cost (module doc): the choice of
    :func:`solve_path`."""
    return solve_path(unary, postures, scale, n_angles, weight, breaks, anchor)[0]


def solve_path(unary, postures, scale, n_angles: int, weight: float = 1.0,
               breaks=None, anchor=None) -> tuple[np.ndarray, np.ndarray]:
    """The path of least summed cost (module doc) and what each candidate would cost it.

    Parameters
    ----------
    unary : (n, K) per-frame cost of each candidate (inf or NaN: no such candidate)
    postures : (n, K, d) candidate postures
    scale : (d,) per-entry scale of a posture change (e.g. ``Fitter._posture_scale()``)
    n_angles : leading posture entries that are angles (degrees, compared modulo 360)
    weight : weight of continuity against the per-frame cost; 0 keeps every frame's best
    breaks : (n,) bool, optional: frame t starts a new sequence (no transition from t-1)
    anchor : (d,) optional posture chosen just before frame 0 (the left end of a window)

    Returns
    -------
    choice : (n,) index of the chosen candidate per frame (-1 for a frame without any)
    cost : (n, K) per candidate, the least cost of a path through it over its stretch
        (between cuts; inf where no candidate). Its minimum in a frame is the chosen
        path's cost; another candidate's excess over it is what choosing that candidate
        costs the movement and the fit together (a min-marginal: the neighbours may change
        with it), the measure of how surely the path rules it out.
    """
    unary = np.asarray(unary, float)
    unary = np.where(np.isfinite(unary), unary, np.inf)
    postures = np.asarray(postures, float)
    n = unary.shape[0]
    scale = np.asarray(scale, float)
    raw = transitions(postures, scale, n_angles)  # (n - 1, K, K)
    k = unary.shape[1]
    trans = np.zeros((n, k, k))
    trans[1:] = weight * np.minimum(raw, JUMP_CAP)
    cut = np.zeros(n, bool) if breaks is None else np.asarray(breaks, bool).copy()
    has = np.isfinite(unary).any(axis=1)
    cut[:1] = True
    if weight == 0:
        cut[:] = True
    elif n > 1:
        cut[1:] |= ~(has[1:] & has[:-1]) | (raw.min(axis=(1, 2), initial=np.inf) > BREAK_COST)
    start0 = np.zeros(unary.shape[1])
    use_start0 = False
    if anchor is not None and weight > 0 and n and not (breaks is not None and breaks[0]):
        t0 = transition_costs(np.asarray(anchor, float)[None], postures[0], scale, n_angles)[0]
        if np.min(t0) <= BREAK_COST:
            start0, use_start0 = weight * np.minimum(t0, JUMP_CAP), True
    bounds = np.r_[np.flatnonzero(cut), n].astype(np.int64)
    choice = np.full(n, -1, np.int64)
    cost = np.full(unary.shape, np.inf)
    if k:
        path_dp(np.ascontiguousarray(unary), trans, bounds, start0, use_start0, choice, cost)
    return choice, np.where(np.isfinite(unary), cost, np.inf)
