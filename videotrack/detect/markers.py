"""Marker regions: connected components of a mask, their sub-pixel centroids, areas and boxes.

A region is a connected set of mask pixels (8- or 4-connected). Its centroid is, by default,
intensity weighted: over the region's bounding box grown by ``window_pad`` pixels, leaving out
pixels of other regions, each pixel weighs ``max(g - b, 0)``, where g is the weight (grey) image
and b the local background, the mean of the window's border pixels that belong to no region.
Including the sub-threshold rim of a marker this way is what makes the centroid sub-pixel
accurate (about 0.02 px RMS for 4-px markers with noise σ = 2, see ``docs/benchmarks.md``);
``weighting = "binary"`` gives the plain mean of the region's pixel centres instead.

Gates: ``min_area <= area <= max_area``, and optionally aspect (long/short axis of the region's
second moments) and circularity ``area / (2π (λ1 + λ2))``, with λ the second-moment
eigenvalues including each pixel's own 1/12 (1 for a disc, less for elongated or ragged shapes).

Coordinates are those of the image given (pixel centres at integers). :func:`find_regions`
runs the numba kernels of :mod:`videotrack.detect._kernels`; :func:`find_regions_reference`
is the readable OpenCV/NumPy twin they are tested against.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np

from videotrack.detect import _kernels as K
from videotrack.errors import VideoTrackError
from videotrack.project.config import MARKERS


@dataclass(frozen=True)
class MarkerSettings:
    """Gates and centroid rule for marker regions (the ``[markers]`` section)."""

    min_area: int = 1
    max_area: int = 10000
    max_aspect: float = 0.0
    min_circularity: float = 0.0
    weighting: str = "intensity"
    window_pad: int = 1
    connectivity: int = 8

    def __post_init__(self) -> None:
        MARKERS.validate(asdict(self))  # the schema is the one place the rules live
        if self.min_area > self.max_area:
            raise VideoTrackError(
                f"min_area {self.min_area} exceeds max_area {self.max_area}",
                field="markers.min_area")

    @classmethod
    def from_config(cls, config) -> MarkerSettings:
        try:
            return cls(**config["markers"])
        except VideoTrackError as err:
            raise err.located(file=config.path) from None

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True, eq=False)
class Regions:
    """Marker regions of one image, in raster order of each region's first pixel.

    Attributes
    ----------
    xy : ndarray, shape (n, 2)
        Centroids (x, y) in the image's pixel coordinates.
    area : ndarray of int64, shape (n,)
        Pixels in the region.
    bbox : ndarray of int32, shape (n, 4)
        Bounding boxes (x, y, width, height).
    total : ndarray, shape (n,)
        Summed weights above the local background (0 with binary weighting).
    aspect, circularity : ndarray, shape (n,)
        Shape measures of the region's pixels (see the module doc).
    n_rejected : int
        Regions the gates removed.
    """

    xy: np.ndarray
    area: np.ndarray
    bbox: np.ndarray
    total: np.ndarray
    aspect: np.ndarray
    circularity: np.ndarray
    n_rejected: int = 0

    def __len__(self) -> int:
        return len(self.area)


def _empty(n_rejected: int = 0) -> Regions:
    return Regions(np.empty((0, 2)), np.empty(0, np.int64), np.empty((0, 4), np.int32),
                   np.empty(0), np.empty(0), np.empty(0), n_rejected)


def shape_measures(area, sx, sy, sxx, syy, sxy) -> tuple[np.ndarray, np.ndarray]:
    """Aspect ratio and circularity from binary moment sums (arrays, one entry per region).

    Each pixel is a unit square, which adds 1/12 to both variances.
    """
    mx, my = sx / area, sy / area
    cxx = sxx / area - mx * mx + 1.0 / 12.0
    cyy = syy / area - my * my + 1.0 / 12.0
    cxy = sxy / area - mx * my
    half_trace = 0.5 * (cxx + cyy)
    root = np.sqrt(np.maximum(0.25 * (cxx - cyy) ** 2 + cxy * cxy, 0.0))
    aspect = np.sqrt((half_trace + root) / np.maximum(half_trace - root, 1e-12))
    circularity = area / (2.0 * np.pi * (cxx + cyy))
    return aspect, circularity


def _passes(area, aspect, circularity, settings: MarkerSettings) -> np.ndarray:
    ok = (area >= settings.min_area) & (area <= settings.max_area)
    if settings.max_aspect > 0:
        ok &= aspect <= settings.max_aspect
    if settings.min_circularity > 0:
        ok &= circularity >= settings.min_circularity
    return ok


def _check_inputs(mask, weights) -> None:
    if mask.ndim != 2 or mask.dtype != np.uint8:
        raise ValueError(f"mask must be a 2-D uint8 image, got {mask.dtype} {mask.shape}")
    if weights is not None and (weights.shape != mask.shape or weights.dtype != np.uint8):
        raise ValueError(f"weights must be uint8 of the mask's shape {mask.shape}, got "
                         f"{weights.dtype} {weights.shape}")


def find_regions(mask: np.ndarray, weights: np.ndarray | None = None,
                 settings: MarkerSettings | None = None, *,
                 scratch: np.ndarray | None = None) -> Regions:
    """Marker regions of a mask (fast path).

    Parameters
    ----------
    mask : ndarray of uint8, shape (h, w)
        Non-zero pixels are marker pixels.
    weights : ndarray of uint8, shape (h, w), optional
        Grey image for intensity-weighted centroids; None gives binary centroids.
    settings : MarkerSettings, optional
        Gates and centroid rule (defaults if None).
    scratch : ndarray of int32, shape (h, w), optional
        All-zero work image, reused between calls (it is zero again on return); allocated
        if None. :class:`RegionFinder` keeps one per image shape.

    Returns
    -------
    Regions
    """
    settings = settings or MarkerSettings()
    _check_inputs(mask, weights)
    n, rows, starts, ends = K.find_runs(mask)
    if n == 0:
        return _empty()
    labels, n_regions = K.label_runs(n, rows, starts, ends, settings.connectivity == 8)
    st = K.region_moments(n, rows, starts, ends, labels, n_regions)
    area = st[:, K.AREA]
    aspect, circularity = shape_measures(area, st[:, K.SX], st[:, K.SY], st[:, K.SXX],
                                         st[:, K.SYY], st[:, K.SXY])
    keep = np.flatnonzero(_passes(area, aspect, circularity, settings))
    if keep.size == 0:
        return _empty(n_regions)
    if settings.weighting == "intensity" and weights is not None:
        if scratch is None:
            scratch = np.zeros(mask.shape, np.int32)
        cx, cy, total = K.weighted_centroids(weights, scratch, n, rows, starts, ends, labels, st,
                                             keep, settings.window_pad)
    else:
        cx, cy = st[keep, K.SX] / area[keep], st[keep, K.SY] / area[keep]
        total = np.zeros(keep.size)
    s = st[keep]
    bbox = np.stack([s[:, K.X0], s[:, K.Y0], s[:, K.X1] - s[:, K.X0] + 1,
                     s[:, K.Y1] - s[:, K.Y0] + 1], axis=1).astype(np.int32)
    return Regions(np.stack([cx, cy], axis=1), area[keep].astype(np.int64), bbox, total,
                   aspect[keep], circularity[keep], n_regions - keep.size)


def find_regions_reference(mask: np.ndarray, weights: np.ndarray | None = None,
                           settings: MarkerSettings | None = None) -> Regions:
    """Readable twin of :func:`find_regions` (OpenCV connected components + NumPy); the
    specification the kernels are tested against. Slow: one pass over the image per region."""
    settings = settings or MarkerSettings()
    _check_inputs(mask, weights)
    n_labels, labels = cv2.connectedComponents((mask > 0).astype(np.uint8),
                                               connectivity=settings.connectivity,
                                               ltype=cv2.CV_32S)
    h, w = mask.shape
    found = []
    for lab in range(1, n_labels):
        ys, xs = np.nonzero(labels == lab)  # raster order: the first is the first pixel
        area = float(len(xs))
        x, y = xs.astype(float), ys.astype(float)
        aspect, circularity = shape_measures(area, x.sum(), y.sum(), (x * x).sum(),
                                             (y * y).sum(), (x * y).sum())
        bbox = (xs.min(), ys.min(), xs.max() - xs.min() + 1, ys.max() - ys.min() + 1)
        found.append(((ys[0], xs[0]), lab, area, aspect, circularity, bbox, x.mean(), y.mean()))
    found.sort(key=lambda f: f[0])
    kept = [f for f in found if _passes(f[2], f[3], f[4], settings)]
    if not kept:
        return _empty(len(found))
    xy, total = [], []
    for _, lab, _, _, _, (bx, by, bw, bh), mx, my in kept:
        if settings.weighting == "binary" or weights is None:
            xy.append((mx, my))
            total.append(0.0)
            continue
        pad = settings.window_pad
        x0, y0 = max(bx - pad, 0), max(by - pad, 0)
        x1, y1 = min(bx + bw - 1 + pad, w - 1), min(by + bh - 1 + pad, h - 1)
        win = weights[y0 : y1 + 1, x0 : x1 + 1].astype(float)
        lab_win = labels[y0 : y1 + 1, x0 : x1 + 1]
        free = lab_win == 0
        background = 0.0
        if pad > 0:
            border = np.zeros_like(free)
            border[[0, -1], :] = True
            border[:, [0, -1]] = True
            if (border & free).any():
                background = win[border & free].mean()
        weight = np.where(free | (lab_win == lab), np.maximum(win - background, 0.0), 0.0)
        if weight.sum() > 0:
            yy, xx = np.mgrid[y0 : y1 + 1, x0 : x1 + 1]
            xy.append(((weight * xx).sum() / weight.sum(), (weight * yy).sum() / weight.sum()))
            total.append(weight.sum())
        else:
            xy.append((mx, my))
            total.append(0.0)
    return Regions(
        np.array(xy, dtype=float).reshape(-1, 2),
        np.array([f[2] for f in kept], np.int64),
        np.array([f[5] for f in kept], np.int32).reshape(-1, 4),
        np.array(total),
        np.array([f[3] for f in kept]),
        np.array([f[4] for f in kept]),
        len(found) - len(kept),
    )


class RegionFinder:
    """:func:`find_regions` with fixed settings and a scratch image kept per image shape."""

    def __init__(self, settings: MarkerSettings | None = None) -> None:
        self.settings = settings or MarkerSettings()
        self._scratch: dict[tuple[int, int], np.ndarray] = {}

    def __call__(self, mask: np.ndarray, weights: np.ndarray | None = None) -> Regions:
        scratch = self._scratch.get(mask.shape)
        if scratch is None:
            scratch = self._scratch[mask.shape] = np.zeros(mask.shape, np.int32)
        return find_regions(mask, weights, self.settings, scratch=scratch)
