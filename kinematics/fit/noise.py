"""The noise model: each view's detection noise σ, absolute, and the test of a frame's marker
residuals against it.

σ is measured once per video, on a sample of its frames: under a right posture and set-up a
matched marker lies about σ from its detection (a 2D residual of Rayleigh distribution, whose
q-quantile is σ √(-2 ln(1 - q))). σ is read at the quantile ``Tuning.noise_sigma_quantile``
(0.9) of the sample's matched residuals, and at least at their median: on a real animal the
residuals are detection noise plus the chain's misfit (skin markers slide), whose tail is
heavier than a Gaussian's, and a median-based σ failed 55 % of a mouse's right frames (the 0.9
quantile: 4 %); a quantile is still robust to the frames that went wrong as long as they give
fewer than a tenth of the matched residuals. The fit absorbed the free axes of the m marker
coordinates, so the residuals' σ is made unbiased by √(m / (m - free axes)); σ is then bounded
below by ``noise_floor_px`` (a detector's centroid is never exact to better than that; renders
are). A σ far above what the detections allow is a set-up fault
(:mod:`kinematics.fit.setup_check`), not noise, so a wrong camera or chain cannot raise σ
until garbage passes.

A marker the chain fits worse than the others (a coxa marker the rigid chain misplaces by
0.1-0.2 mm on a fly, a sliding skin marker) has residuals wider than its view's σ on every
frame: its σ is its view's times its own scale (:func:`measure_marker_scale`, at least 1),
measured on the same sample, so that one marker's misfit does not fail most frames.

A frame passes when its residuals are what σ allows:

* each marker image within k σ of its detection is matched, k such that all n marker images of
  a right frame fall within it with probability 1 - ``Tuning.noise_p`` (:func:`gate_k`, at
  least ``Tuning.noise_gate_k``: a fly's 180 images need 4.9 σ, where 4 σ put one of them
  outside on 6 % of right frames); one farther off (or without one) is unmatched, and is
  allowed only where its view shows fewer detections than it has markers plus the video's
  usual extras (an occluded marker), less the detections that are fused blobs (two markers
  matched to one detection account for one missing detection, not for a third marker far
  off); any unmatched marker beyond those fails the frame;
* labelled keypoints are measured to their own label, so a missing one has no residual; a
  labeller mislabels a share of them, so a frame may have as many off their label per view as
  ``Tuning.noise_outlier_share`` of the sample frames have at most (:func:`usual_outliers`);
* the matched residuals' Σ (r/σ)² must lie below the χ² quantile ``1 - Tuning.noise_p`` of
  2 · matched − free axes degrees of freedom: a posture off by a little at every marker fails
  as surely as one off by much at one.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from scipy.stats import chi2


class NoiseModel(NamedTuple):
    """σ per view (pixels), how it was found, (labelled keypoints) the keypoints per view a
    frame may have off their label, and each marker's σ as a multiple of its view's."""

    sigma_px: np.ndarray  # (n_views,)
    source: str  # "measured" (on a sample of the video's frames) or "given"
    outliers: np.ndarray | None = None  # (n_views,) int, labelled keypoints only
    marker_scale: np.ndarray | None = None  # (n_markers,) >= 1; None: 1 for every marker

    def per_image(self, n_markers: int) -> np.ndarray:
        """(n_views, n_markers) σ of each marker image."""
        scale = np.ones(n_markers) if self.marker_scale is None else self.marker_scale
        return self.sigma_px[:, None] * scale[None, :]

    def to_record(self) -> dict:
        """As plain numbers (a results sidecar keeps it)."""
        # full precision: a resumed fit must judge and give sds as the uninterrupted one
        out = {"sigma_px": [float(s) for s in self.sigma_px], "source": self.source}
        if self.outliers is not None:
            out["outliers"] = [int(k) for k in self.outliers]
        if self.marker_scale is not None:
            out["marker_scale"] = [float(w) for w in self.marker_scale]
        return out

    @classmethod
    def from_record(cls, record, n_views: int, n_markers: int) -> NoiseModel | None:
        """:meth:`to_record`'s record read back, or None where it is not one of ``n_views``
        views and ``n_markers`` markers (a sidecar of other views, or edited by hand)."""
        try:
            sigma = np.array([float(s) for s in record["sigma_px"]])
            outliers = record.get("outliers")
            outliers = None if outliers is None else np.array([int(k) for k in outliers])
            scale = record.get("marker_scale")
            scale = None if scale is None else np.array([float(w) for w in scale])
        except (KeyError, TypeError, ValueError, AttributeError):
            return None
        if (sigma.shape != (n_views,) or not (np.isfinite(sigma) & (sigma > 0)).all()
                or (outliers is not None and outliers.shape != (n_views,))
                or (scale is not None and (scale.shape != (n_markers,)
                                           or not (np.isfinite(scale) & (scale >= 1)).all()))):
            return None
        return cls(sigma, str(record.get("source", "measured")), outliers, scale)


class FrameCounts(NamedTuple):
    """What a frame's verdict needs beside its residuals, per view: detections shown, markers
    the view is expected to show, and the extra detections the video usually has."""

    detections: np.ndarray  # (n_frames, n_views) int
    shown: np.ndarray  # (n_frames, n_views) int
    extras: np.ndarray  # (n_views,) int


def measure_sigma(residuals: Sequence[np.ndarray], floor: float, gate: float,
                  least: int = 8, quantile: float = 0.9, free_axes: int = 0
                  ) -> np.ndarray | None:
    """σ per view from the residuals (each (n_views, n_markers), NaN: none) of fitted frames:
    the Rayleigh σ whose ``quantile`` their matched residuals (within ``gate``) in that view
    have (at least their median's), unbiased for the ``free_axes`` the fit absorbed from
    each frame's coordinates, at least ``floor`` (a view without any: the other views'
    median). None with fewer than ``least`` frames (a fit of a few frames cannot measure
    its video)."""
    frames = [np.asarray(r, float) for r in residuals if r is not None and np.isfinite(r).any()]
    if len(frames) < least:
        return None
    stack = np.stack(frames)  # (n, n_views, n_markers)
    sigma = np.full(stack.shape[1], np.nan)
    matched = np.isfinite(stack) & (stack <= gate)
    for v in range(stack.shape[1]):
        vals = stack[:, v][matched[:, v]]
        if vals.size:  # the median's σ at least: a tail lighter than a Gaussian's lowers
            sigma[v] = max(float(np.quantile(vals, q)) / rayleigh_quantile(q)  # nothing
                           for q in (0.5, quantile))
    if not np.isfinite(sigma).any():
        return None
    coords = 2.0 * float(np.median(matched.sum(axis=(1, 2))))  # a frame's, typically
    if coords > free_axes:
        sigma = sigma * np.sqrt(coords / (coords - free_axes))
    sigma = np.where(np.isfinite(sigma), sigma, np.nanmedian(sigma))
    return np.maximum(sigma, floor)


def rayleigh_quantile(q: float) -> float:
    """The ``q``-quantile of a 2D Gaussian residual's length, in σ (0.5: the median,
    1.177 σ)."""
    return float(np.sqrt(-2.0 * np.log1p(-q)))


def measure_marker_scale(residuals: Sequence[np.ndarray], sigma: np.ndarray, gate: float,
                         quantile: float = 0.9, least: int = 16, cap: float = 3.0
                         ) -> np.ndarray | None:
    """Each marker's σ as a multiple of its view's (``sigma``) from the residuals (each
    (n_views, n_markers)) of a sample's fitted frames: the ``quantile`` of its matched
    residuals (within ``gate``) in units of their view's σ, over the Rayleigh quantile,
    between 1 and ``cap``; 1 for a marker with fewer than ``least`` of them. None where every
    marker's is 1."""
    frames = [np.asarray(r, float) for r in residuals if r is not None and np.isfinite(r).any()]
    if not frames:
        return None
    stack = np.stack(frames)  # (n, n_views, n_markers)
    matched = np.isfinite(stack) & (stack <= gate)
    z = stack / np.asarray(sigma, float)[None, :, None]
    scale = np.ones(stack.shape[2])
    for m in range(stack.shape[2]):
        vals = z[:, :, m][matched[:, :, m]]
        if vals.size >= least:
            scale[m] = float(np.quantile(vals, quantile)) / rayleigh_quantile(quantile)
    scale = np.clip(scale, 1.0, cap)
    return None if (scale == 1.0).all() else scale


def gate_k(n_images: int, p: float, least: float) -> float:
    """The gate in σ that all ``n_images`` marker images of a right frame fall within with
    probability about 1 - ``p`` (each 2D Gaussian residual lies beyond k σ with probability
    exp(-k²/2)), at least ``least``."""
    return max(float(least), float(np.sqrt(2.0 * np.log(max(n_images, 1) / p))))


def usual_extras(detections: np.ndarray, shown: np.ndarray, share: float = 0.9) -> np.ndarray:
    """Per view, the extra detections (beyond the markers shown) that ``share`` of the frames
    have at most: static and flickering ghosts the video always has are no sign of an
    occluded marker."""
    if len(detections) == 0:
        return np.zeros(detections.shape[1], np.int64)
    extra = np.maximum(detections - shown, 0)
    return np.ceil(np.quantile(extra, share, axis=0)).astype(np.int64)


def usual_outliers(residuals: Sequence[np.ndarray], sigma: np.ndarray, least_k: float,
                   p: float, share: float = 0.9) -> np.ndarray:
    """Per view, the labelled keypoints off their label (beyond :func:`gate_k` σ; ``sigma``
    (n_views, n_markers) or per view) that ``share`` of the frames (residuals of a sample,
    each (n_views, n_markers)) have at most: the labeller's mislabels, no sign of a wrong
    posture."""
    sigma = _per_image(sigma, np.asarray(residuals[0]).shape[1])
    off = np.stack([(np.isfinite(r) & (r > gate_k(int(np.isfinite(r).sum()), p, least_k)
                                       * sigma)).sum(axis=1) for r in residuals])
    return np.ceil(np.quantile(off, share, axis=0)).astype(np.int64)


@lru_cache(maxsize=4096)
def chi2_limit(p: float, dof: int) -> float:
    """The χ² quantile 1 - ``p`` of ``dof`` degrees of freedom (scipy's takes 0.3 ms: a
    frame's test asks for one of a few)."""
    return float(chi2.isf(p, dof))


class Verdict(NamedTuple):
    """A frame's test against the noise model."""

    passed: bool
    unmatched: int  # marker images beyond the gate that no absent detection excuses
    gross: int  # ... of them beyond ``gross_px`` (a marker far from every detection)
    measured: int  # marker images with a residual
    chi2: float  # Σ (r/σ)² of the matched residuals
    limit: float  # its χ² limit
    excused: int = 0  # marker images beyond the gate that missing detections excused


def _per_image(sigma: np.ndarray, n_markers: int) -> np.ndarray:
    sigma = np.asarray(sigma, float)
    return sigma if sigma.ndim == 2 else np.repeat(sigma[:, None], n_markers, axis=1)


def gate_px(residuals: np.ndarray, sigma: np.ndarray, least_k: float, p: float) -> np.ndarray:
    """(n_views, n_markers) gate of a frame's marker images in px: :func:`gate_k` σ for the
    images with a residual."""
    r = np.asarray(residuals, float)
    return gate_k(int(np.isfinite(r).sum()), p, least_k) * _per_image(sigma, r.shape[1])


def verdict(residuals: np.ndarray, sigma: np.ndarray, detections: np.ndarray,
            shown: np.ndarray, extras: np.ndarray, free_axes: int, least_k: float,
            p: float, outliers: np.ndarray | None, gross_px: float = np.inf,
            fused: np.ndarray | None = None) -> Verdict:
    """:class:`Verdict` of one frame: ``residuals`` (n_views, n_markers) in px (NaN: no
    detection to measure to), ``sigma`` (n_views, n_markers; or per view), and per view the
    ``detections`` shown, the markers ``shown``, the usual ``extras`` and the ``fused``
    detections' extra markers (:func:`fused_markers`; None: none). ``outliers`` (labelled
    keypoints, which are measured to their own label, so a missing one is NaN): per view, the
    keypoints off their label a frame may have; None for unlabelled detections. ``gross``
    counts the unmatched beyond ``gross_px`` the same way (what the set-up check reads)."""
    r = np.asarray(residuals, float)
    sigma = _per_image(sigma, r.shape[1])
    gate = gate_px(r, sigma, least_k, p)
    finite = np.isfinite(r)
    matched = finite & (r <= gate)
    off = (finite & ~matched).sum(axis=1)
    missing = shown + extras - detections - (0 if fused is None else fused)
    excused = np.asarray(outliers) if outliers is not None else np.maximum(missing, 0)
    unmatched = int(np.maximum(off - excused, 0).sum())
    excused_off = int(np.minimum(off, excused).sum())
    far = (finite & ~(r <= np.maximum(gate, gross_px))).sum(axis=1)
    gross = int(np.maximum(far - excused, 0).sum())
    n = int(matched.sum())
    stat = float(np.sum(np.where(matched, r / sigma, 0.0) ** 2))
    limit = chi2_limit(p, max(1, 2 * n - free_axes))
    return Verdict(unmatched == 0 and stat <= limit, unmatched, gross, int(finite.sum()), stat,
                   limit, excused_off)


def fused_markers(proj: np.ndarray, points: np.ndarray, view_off: np.ndarray,
                  gate: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """Per view, the ``seen`` markers within ``gate`` (n_views, n_markers, px) of a
    detection whose nearest detection is also another such marker's, less one per such
    detection: a blob of k fused markers stands for k - 1 missing detections (only a
    :class:`Verdict` with ``excused`` images can change with them). ``proj``
    (n_views, n_markers, 2) the projected markers, ``points`` the detections of all views,
    ``view_off`` each view's first."""
    out = np.zeros(proj.shape[0], np.int64)
    for v in range(proj.shape[0]):
        d = points[view_off[v]: view_off[v + 1], :2]
        if len(d) == 0:
            continue
        dist = np.linalg.norm(proj[v][:, None, :] - d[None], axis=2)
        near = dist.argmin(axis=1)
        within = seen[v] & (dist[np.arange(len(near)), near] <= gate[v])
        out[v] = int(within.sum()) - np.unique(near[within]).size
    return out
