"""numba kernels of marker detection: run-length connected components and centroids.

Private: use :func:`videotrack.detect.markers.find_regions`. The readable twin, which is the
specification and the test oracle, is :func:`videotrack.detect.markers.find_regions_reference`
(OpenCV's ``connectedComponentsWithStats`` plus NumPy). Why a kernel at all: OpenCV's labelling
with statistics costs about 1 ms per half PAL frame, while marker masks are nearly empty; scanning
for runs of foreground pixels and labelling the runs costs a few microseconds.

Pixel (row i, column j) has centre (x, y) = (j, i). Regions are numbered in raster order of their
first pixel, as OpenCV numbers its labels. The kernels release the GIL (``nogil``): a run fits
earlier records in another thread while it detects (``videotrack.workflow.streaming.FitAlongside``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Columns of the per-region statistics array returned by :func:`region_moments`.
AREA, X0, Y0, X1, Y1, SX, SY, SXX, SYY, SXY = range(10)
N_STATS = 10


@njit(cache=True, nogil=True)
def find_runs(mask):
    """Horizontal runs of non-zero pixels in raster order.

    Returns ``(n, rows, starts, ends)``: int32 arrays of length n; a run covers columns
    ``starts[k] <= x < ends[k]`` of row ``rows[k]``.
    """
    # Fixed arrays and a second pass when they overflow: growing arrays inside the scan
    # would make numba reference-count them on every pixel (10x slower).
    cap = 256
    while True:
        rows = np.empty(cap, np.int32)
        starts = np.empty(cap, np.int32)
        ends = np.empty(cap, np.int32)
        n = _scan_runs(mask, rows, starts, ends)
        if n <= cap:
            return n, rows[:n], starts[:n], ends[:n]
        cap = n


@njit(cache=True, nogil=True)
def _row_max(row):
    m = np.uint8(0)
    for x in range(row.size):
        m = max(m, row[x])  # vectorised: skips empty rows, nearly all of them
    return m


@njit(cache=True, nogil=True)
def _scan_runs(mask, rows, starts, ends):
    """Store runs while the arrays have room; return how many runs there are."""
    h, w = mask.shape
    cap = rows.size
    n = 0
    for y in range(h):
        row = mask[y]
        if _row_max(row) == 0:
            continue
        x = 0
        while x < w:
            if row[x] == 0:
                x += 1
                continue
            x0 = x
            while x < w and row[x] != 0:
                x += 1
            if n < cap:
                rows[n] = y
                starts[n] = x0
                ends[n] = x
            n += 1
    return n


@njit(cache=True, nogil=True)
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@njit(cache=True, nogil=True)
def label_runs(n, rows, starts, ends, diagonal):
    """Connected components of the first ``n`` runs (union-find over adjacent rows).

    ``diagonal`` True gives 8-connectivity, False 4-connectivity. Returns ``(labels, n_regions)``
    with ``labels[k]`` in ``0..n_regions-1`` numbered in raster order of each region's first run.
    """
    parent = np.arange(n)
    reach = 1 if diagonal else 0
    prev_lo = 0  # first run of the previous non-empty row
    prev_hi = 0  # one past its last run
    k = 0
    while k < n:
        y = rows[k]
        cur_lo = k
        while k < n and rows[k] == y:
            k += 1
        cur_hi = k
        if prev_hi > prev_lo and rows[prev_lo] == y - 1:
            i = prev_lo
            for j in range(cur_lo, cur_hi):
                # Runs of the previous row that end left of run j touch no later run either.
                while i < prev_hi and ends[i] - 1 + reach < starts[j]:
                    i += 1
                m = i
                while m < prev_hi and starts[m] <= ends[j] - 1 + reach:
                    a = _root(parent, m)
                    b = _root(parent, j)
                    if a != b:  # keep the earlier run as root
                        if a < b:
                            parent[b] = a
                        else:
                            parent[a] = b
                    m += 1
        prev_lo = cur_lo
        prev_hi = cur_hi
    labels = np.empty(n, np.int32)
    new_id = np.full(n, -1, np.int32)
    n_regions = 0
    for k in range(n):
        r = _root(parent, k)
        if new_id[r] < 0:
            new_id[r] = n_regions
            n_regions += 1
        labels[k] = new_id[r]
    return labels, n_regions


@njit(cache=True, nogil=True)
def region_moments(n, rows, starts, ends, labels, n_regions):
    """Area, inclusive bounding box and binary moment sums of each region.

    Returns float64 array, shape (n_regions, N_STATS), columns AREA, X0, Y0, X1, Y1 (inclusive
    bounds), SX, SY, SXX, SYY, SXY (sums of x, y, x², y², xy over the region's pixel centres).
    """
    st = np.zeros((n_regions, N_STATS))
    for r in range(n_regions):
        st[r, X0] = np.inf
        st[r, Y0] = np.inf
        st[r, X1] = -np.inf
        st[r, Y1] = -np.inf
    for k in range(n):
        r = labels[k]
        y = float(rows[k])
        s = float(starts[k])
        e = float(ends[k] - 1)  # last column of the run
        c = e - s + 1.0
        sx = (s + e) * c / 2.0
        # sum of x^2 for x = s..e, by the closed form of the sum of squares
        sxx = (e * (e + 1.0) * (2.0 * e + 1.0) - (s - 1.0) * s * (2.0 * s - 1.0)) / 6.0
        st[r, AREA] += c
        st[r, X0] = min(st[r, X0], s)
        st[r, X1] = max(st[r, X1], e)
        st[r, Y0] = min(st[r, Y0], y)
        st[r, Y1] = max(st[r, Y1], y)
        st[r, SX] += sx
        st[r, SY] += y * c
        st[r, SXX] += sxx
        st[r, SYY] += y * y * c
        st[r, SXY] += y * sx
    return st


@njit(cache=True, nogil=True)
def weighted_centroids(weights, label_img, n, rows, starts, ends, labels, stats, keep, pad):
    """Intensity-weighted centroids of the kept regions.

    For region r the window is its bounding box grown by ``pad`` pixels (clipped to the image).
    The local background is the mean of the window's border pixels that belong to no region;
    a pixel's weight is ``max(weights - background, 0)`` over the pixels of the window that
    belong to region r or to no region (other regions are left out). ``label_img`` is an int32
    scratch image of the mask's shape, all zero on entry and on return.

    Returns ``(cx, cy, total)`` for the regions listed in ``keep``; a region whose weights sum
    to zero gets its binary centroid and total 0.
    """
    h, w = label_img.shape
    for k in range(n):
        lab = labels[k] + 1
        for x in range(starts[k], ends[k]):
            label_img[rows[k], x] = lab
    m = keep.size
    cx = np.empty(m)
    cy = np.empty(m)
    total = np.zeros(m)
    for q in range(m):
        r = keep[q]
        own = r + 1
        x0 = max(int(stats[r, X0]) - pad, 0)
        x1 = min(int(stats[r, X1]) + pad, w - 1)
        y0 = max(int(stats[r, Y0]) - pad, 0)
        y1 = min(int(stats[r, Y1]) + pad, h - 1)
        bg = 0.0
        if pad > 0:
            ring_sum = 0.0
            ring_n = 0
            for y in range(y0, y1 + 1):
                for x in range(x0, x1 + 1):
                    inside = y0 < y < y1 and x0 < x < x1
                    if not inside and label_img[y, x] == 0:
                        ring_sum += weights[y, x]
                        ring_n += 1
            if ring_n > 0:
                bg = ring_sum / ring_n
        sw = 0.0
        swx = 0.0
        swy = 0.0
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                lab = label_img[y, x]
                if lab == 0 or lab == own:
                    v = weights[y, x] - bg
                    if v > 0.0:
                        sw += v
                        swx += v * x
                        swy += v * y
        if sw > 0.0:
            cx[q] = swx / sw
            cy[q] = swy / sw
            total[q] = sw
        else:
            cx[q] = stats[r, SX] / stats[r, AREA]
            cy[q] = stats[r, SY] / stats[r, AREA]
    for k in range(n):
        for x in range(starts[k], ends[k]):
            label_img[rows[k], x] = 0
    return cx, cy, total
