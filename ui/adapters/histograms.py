"""Histogram bars of the histogram dialog (no Qt)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinematics.model.histograms import Histogram, bin_centres


# -- histograms -----------------------------------------------------------------------------
@dataclass(frozen=True)
class HistogramBars:
    """Bars of one histogram on an unwrapped degree axis, and a value marked on it."""

    centres: np.ndarray  # (n_bins,) degrees, increasing, one turn from ``centres[0]``
    heights: np.ndarray  # (n_bins,)
    width: float
    value: float | None  # the marked value on the same axis, or None
    mean: float  # the histogram's mean on the same axis
    view_range: tuple[float, float]  # degrees worth showing (the support with a margin)


def histogram_bars(hist: Histogram, value_deg: float | None = None,
                   margin_deg: float = 10.0) -> HistogramBars:
    """Bin centres unwrapped so the occupied bins are contiguous (a range such as
    [120, 220] through ±180° shows as one block), with ``value_deg`` on the same axis."""
    lo, hi = hist.support_deg()
    start = lo - (360.0 - (hi - lo)) / 2.0  # the cut lies in the middle of the empty part
    centres = bin_centres(hist.n_bins)
    x = start + (centres - start) % 360.0
    order = np.argsort(x)
    def on_axis(angle: float) -> float:
        return float(start + (angle - start) % 360.0)

    value = on_axis(value_deg) if value_deg is not None and np.isfinite(value_deg) else None
    return HistogramBars(x[order], hist.values[order], hist.bin_width_deg, value,
                         on_axis(hist.mean_deg()), (lo - margin_deg, hi + margin_deg))


