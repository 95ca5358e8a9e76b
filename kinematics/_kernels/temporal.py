"""numba kernel of the path through time (private; see :mod:`kinematics.fit.temporal`).

Its NumPy twin ``_path_numpy`` in :mod:`kinematics.fit.temporal` is the readable specification
and the test oracle: the kernel makes the same additions in the same order and breaks ties
as ``np.argmin`` does (the first minimum), so choice and costs equal the twin's to the bit.
A window of 64 frames took ~1.4 ms of Python loops over frames (16 % of a fit with two
candidates per frame and a short schedule, docs/benchmarks.md "Lanes"); this takes µs.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def path_dp(unary, trans, bounds, start0, use_start0, choice, cost):
    """The Viterbi pass of :func:`kinematics.fit.temporal.solve_path` over each stretch
    ``bounds[s]:bounds[s + 1]`` (cuts between): ``unary`` (n, K) per-frame costs (inf: no
    candidate), ``trans`` (n, K, K) the weighted transition from frame t-1's candidate i to
    frame t's j (row 0 unused), ``start0`` (K,) the cost from the anchor into frame 0 (if
    ``use_start0``). Fills ``choice`` (n,) (left -1 where a stretch has no candidate) and
    ``cost`` (n, K), the least cost of a path through each candidate over its stretch."""
    n, k = unary.shape
    ahead = np.empty((n, k))
    back = np.zeros((n, k), np.int64)
    rest = np.empty(k)
    nxt = np.empty(k)
    for s in range(bounds.shape[0] - 1):
        a, b = bounds[s], bounds[s + 1]
        has = False
        for j in range(k):
            has = has or unary[a, j] < np.inf
        if not has:
            continue
        # forward: least cost of a path ending at each candidate
        for j in range(k):
            ahead[a, j] = unary[a, j] + (start0[j] if a == 0 and use_start0 else 0.0)
        for t in range(a + 1, b):
            for j in range(k):
                best = ahead[t - 1, 0] + trans[t, 0, j]
                arg = 0
                for i in range(1, k):
                    v = ahead[t - 1, i] + trans[t, i, j]
                    if v < best:
                        best = v
                        arg = i
                back[t, j] = arg
                ahead[t, j] = best + unary[t, j]
        # backward: least cost of the rest of the stretch after each candidate
        for j in range(k):
            rest[j] = 0.0
        for t in range(b - 1, a - 1, -1):
            for j in range(k):
                cost[t, j] = ahead[t, j] + rest[j]
            if t > a:
                for i in range(k):
                    m = np.inf
                    for j in range(k):
                        m = min(m, trans[t, i, j] + (unary[t, j] + rest[j]))
                    nxt[i] = m
                for i in range(k):
                    rest[i] = nxt[i]
        j = 0
        for i in range(1, k):
            if ahead[b - 1, i] < ahead[b - 1, j]:
                j = i
        choice[b - 1] = j
        for t in range(b - 1, a, -1):
            j = back[t, j]
            choice[t - 1] = j
