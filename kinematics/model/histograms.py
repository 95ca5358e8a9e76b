"""Joint-angle histograms: constraints and priors of one rotation axis (paper Sect. 2.2).

A histogram ``H`` has ``n_bins`` equal bins over the full circle; bin ``k`` covers
``[-180 + k·w, -180 + (k+1)·w)`` degrees with ``w = 360 / n_bins`` (one degree by default).
Values are probabilities (they sum to 1) and ``n_trials`` is the trial count ``N`` of Eq. 4.

The mean and the standard deviation ``s(H)`` (the step scale of Eq. 6) are computed on the
circle cut at the widest empty gap, so a range such as φ ∈ [120°, 220°], which wraps through
±180°, has mean 170° and the spread of a 100°-wide uniform distribution.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from kinematics.errors import KinematicsError

N_BINS_DEFAULT = 360

#: Largest bin value accepted. Values are normalised to sum 1, so any scale up to this will do
#: (probabilities, percentages, counts); beyond it sums overflow and the scale is a mistake.
MAX_BIN_VALUE = 1e12


def wrap_deg(angle_deg):
    """Wrap angles (degrees) into [-180, 180)."""
    return (np.asarray(angle_deg, dtype=float) + 180.0) % 360.0 - 180.0


@dataclass(frozen=True, eq=False)
class Histogram:
    """Discrete angle distribution of one axis.

    Parameters
    ----------
    values : ndarray, shape (n_bins,)
        Non-negative bin probabilities summing to 1.
    n_trials : int
        Trial count ``N`` of Eq. 4 (how many observations the histogram stands for).
    """

    values: np.ndarray
    n_trials: int = 1

    def __post_init__(self) -> None:
        values = np.array(self.values, dtype=float)
        if values.ndim != 1 or values.size < 1:
            raise KinematicsError("histogram needs a 1-D array of bin values")
        if not np.all(np.isfinite(values)) or np.any(values < 0):
            raise KinematicsError("histogram bin values must be finite and non-negative")
        if values.max() > MAX_BIN_VALUE:
            raise KinematicsError(
                f"histogram bin value {values.max():g} is too large (at most "
                f"{MAX_BIN_VALUE:g}; values are normalised to sum 1, so probabilities or "
                "counts will do)")
        total = values.sum()
        if total <= 0:
            raise KinematicsError("histogram is empty (all bins are zero)")
        if int(self.n_trials) < 1:
            raise KinematicsError(f"histogram trial count must be >= 1, got {self.n_trials}")
        if abs(total - 1.0) > 1e-12:  # keep stored values bit-exact (lossless round trips)
            values = values / total
        values.setflags(write=False)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "n_trials", int(self.n_trials))

    # -- construction -----------------------------------------------------------------
    @classmethod
    def uniform(
        cls, min_deg: float, max_deg: float, n_bins: int = N_BINS_DEFAULT, n_trials: int = 1
    ) -> Histogram:
        """Uniform over [min_deg, max_deg] and zero elsewhere (the paper's initial state).

        Bins whose centre lies in the closed range are set; a range narrower than one bin
        sets the bin that holds its midpoint. Ranges may exceed ±180° (they wrap).
        """
        if not (np.isfinite(min_deg) and np.isfinite(max_deg)):
            raise KinematicsError("histogram range must be finite")
        if min_deg > max_deg:
            raise KinematicsError(f"range min {min_deg:g} is greater than max {max_deg:g}")
        width = 360.0 / n_bins
        values = np.zeros(n_bins)
        if max_deg - min_deg >= 360.0:
            values[:] = 1.0
        else:
            centres = bin_centres(n_bins)
            offset = (centres - min_deg) % 360.0
            values[offset <= (max_deg - min_deg) + 1e-9] = 1.0
            if not values.any() or max_deg - min_deg < width:
                values[:] = 0.0
                values[bin_index(0.5 * (min_deg + max_deg), n_bins)] = 1.0
        return cls(values, n_trials)

    @classmethod
    def locked(cls, value_deg: float, n_bins: int = N_BINS_DEFAULT) -> Histogram:
        """A single bin set to 1: the paper's way of locking a hinge joint's axis."""
        values = np.zeros(n_bins)
        values[bin_index(value_deg, n_bins)] = 1.0
        return cls(values, 1)

    # -- queries ----------------------------------------------------------------------
    @property
    def n_bins(self) -> int:
        return self.values.size

    @property
    def bin_width_deg(self) -> float:
        return 360.0 / self.n_bins

    def bin_of(self, angle_deg):
        """Index of the bin holding each angle (degrees, any range)."""
        return bin_index(angle_deg, self.n_bins)

    def at(self, angle_deg):
        """H(x): the probability of the bin holding each angle."""
        return self.values[self.bin_of(angle_deg)]

    def plausible(self, angle_deg, threshold: float):
        """The plausibility test of Sect. 2.3: ``H(x) >= T_h``."""
        return self.at(angle_deg) >= threshold

    def _unwrapped_centres(self) -> np.ndarray:
        """Bin centres unwrapped so that the widest run of empty bins lies at the cut."""
        centres = bin_centres(self.n_bins)
        occupied = self.values > 0
        if occupied.all():
            # No gap: cut opposite the circular mean.
            ang = np.deg2rad(centres)
            s, c = self.values @ np.sin(ang), self.values @ np.cos(ang)
            cut = np.rad2deg(np.arctan2(s, c)) + 180.0 if np.hypot(s, c) > 1e-9 else -180.0
        else:
            # Longest circular run of empty bins; the cut sits at its middle.
            empty = ~occupied
            doubled = np.concatenate([empty, empty])
            best_len, best_end, run = 0, 0, 0
            for i, e in enumerate(doubled):
                run = run + 1 if e else 0
                if run > best_len:
                    best_len, best_end = min(run, self.n_bins), i
            mid = best_end - (best_len - 1) / 2.0
            cut = -180.0 + (mid + 0.5) * self.bin_width_deg
        return cut + (centres - cut) % 360.0

    def mean_deg(self) -> float:
        """Mean angle in [-180, 180), robust to ranges that wrap through ±180°."""
        x = self._unwrapped_centres()
        return float(wrap_deg(self.values @ x))

    def std_deg(self) -> float:
        """The standard deviation s(H) in degrees (step scale of Eq. 6); 0 for a single bin."""
        x = self._unwrapped_centres()
        m = self.values @ x
        return float(np.sqrt(max(self.values @ (x - m) ** 2, 0.0)))

    def mass_in_range(self, min_deg: float, max_deg: float) -> float:
        """Probability of the bins that overlap ``[min_deg, max_deg]`` (degrees; the range may
        pass ±180°): the share of the histogram an axis with that range can reach."""
        span = max_deg - min_deg
        if not span < 360.0:
            return float(self.values.sum())
        w = self.bin_width_deg
        starts = -180.0 + np.arange(self.n_bins) * w
        inside = ((starts - min_deg) % 360.0 <= span + 1e-9) | (
            (min_deg - starts) % 360.0 < w - 1e-9)
        return float(self.values[inside].sum())

    def support_deg(self) -> tuple[float, float]:
        """Smallest (lo, hi) interval covering all non-zero bins, lo in [-180, 180)."""
        x = self._unwrapped_centres()[self.values > 0]
        half = 0.5 * self.bin_width_deg
        lo = float(x.min() - half)
        hi = float(x.max() + half)
        shift = float(wrap_deg(lo)) - lo
        return lo + shift, hi + shift

    # -- learning (Eq. 4) and merging -------------------------------------------------
    def updated(self, angles_deg: Iterable[float]) -> Histogram:
        """Apply Eq. 4 once per measured angle ξ and return the new histogram.

        ``H_N(x) = ((N-1)·H_{N-1}(x) + Δ) / N`` with Δ = 1 in the bin holding ξ, applied for
        each angle in turn; the closed form is ``(N0·H + counts) / (N0 + k)``.
        """
        angles = np.fromiter(angles_deg, dtype=float) if not isinstance(
            angles_deg, np.ndarray) else np.asarray(angles_deg, dtype=float).ravel()
        angles = angles[np.isfinite(angles)]
        if angles.size == 0:
            return self
        counts = np.bincount(self.bin_of(angles), minlength=self.n_bins)
        n0 = self.n_trials
        return Histogram((n0 * self.values + counts) / (n0 + angles.size), n0 + angles.size)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Histogram):
            return NotImplemented
        return self.n_trials == other.n_trials and np.array_equal(self.values, other.values)

    __hash__ = None  # mutable-looking array payload; compare by value only


def merge_histograms(histograms: Sequence[Histogram]) -> Histogram:
    """Combine histograms of one axis from several experiments, weighted by their N."""
    if not histograms:
        raise KinematicsError("nothing to merge")
    n_bins = {h.n_bins for h in histograms}
    if len(n_bins) != 1:
        raise KinematicsError(f"cannot merge histograms with different bin counts {sorted(n_bins)}")
    weights = np.array([h.n_trials for h in histograms], dtype=float)
    values = sum(w * h.values for w, h in zip(weights, histograms, strict=True))
    return Histogram(values / weights.sum(), int(weights.sum()))


def bin_centres(n_bins: int = N_BINS_DEFAULT) -> np.ndarray:
    """Centres of the bins in degrees, shape (n_bins,)."""
    return -180.0 + (np.arange(n_bins) + 0.5) * (360.0 / n_bins)


def bin_index(angle_deg, n_bins: int = N_BINS_DEFAULT):
    """Bin holding each angle; works for any real angle (wraps)."""
    a = np.asarray(angle_deg, dtype=float)
    idx = np.floor((a + 180.0) % 360.0 / (360.0 / n_bins)).astype(np.int64)
    return np.minimum(idx, n_bins - 1)
