"""Plots a person would rather look at than read: angle time courses with bad frames."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinematics.fileio import atomic_write_bytes
from videotrack.results.files import Results


def plot_angles(results: Results, path: str | os.PathLike, locked=None, truth=None) -> Path:
    """PNG of every free axis over time and the error E below; frames whose fit failed or
    had no detections are marked red. ``truth`` (n, n_axes) is drawn dashed if given."""
    plt = _pyplot()
    free = [i for i in range(len(results.axis_labels)) if locked is None or not locked[i]]
    bad = ~results.ok_mask()
    t = results.times
    fig, axes = plt.subplots(len(free) + 1, 1, figsize=(10, 1.6 * (len(free) + 1) + 0.6),
                             sharex=True, squeeze=False)
    axes = axes[:, 0]
    for ax, i in zip(axes, free, strict=False):
        ax.plot(t, results.angles_deg[:, i], lw=1.2, color="tab:blue", label="fitted")
        if truth is not None:
            ax.plot(t, truth[:, i], "--", lw=1, color="0.3", label="truth")
        if bad.any():
            ax.plot(t[bad], results.angles_deg[bad, i], "x", color="tab:red", label="bad")
        ax.set_ylabel(f"{results.axis_labels[i]} (°)", fontsize=8)
        ax.grid(alpha=0.3)
    if free:
        axes[0].legend(loc="upper right", fontsize=7, ncol=3)
    ax = axes[-1]
    ax.plot(t, results.error, lw=1, color="k")
    if bad.any():
        ax.plot(t[bad], np.nan_to_num(results.error[bad]), "x", color="tab:red")
    unit = "px" if results.view_names else "length units"  # 3D points: no views
    ax.set_ylabel(f"error E ({unit})", fontsize=8)
    ax.set_xlabel("time (s)")
    ax.grid(alpha=0.3)
    n_bad = int(bad.sum())
    fig.suptitle(f"{len(results)} frames, {n_bad} bad ({100 * n_bad / max(len(results), 1):.1f} %)"
                 f", median E {median_text(results.error, unit)}")
    return _save_png(fig, path, dpi=90)


def median_text(values, unit: str = "px") -> str:
    """``"1.23 px"``: the median of the finite values, or ``"n/a (no fitted frame)"`` (not
    numpy's "All-NaN slice" warning) when there are none."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return f"{np.median(v):.2f} {unit}" if v.size else "n/a (no fitted frame)"


def plot_histograms(items, path: str | os.PathLike) -> Path:
    """PNG of bar plots, one per (name, Histogram) in ``items``, zoomed on each support."""
    from kinematics.model.histograms import bin_centres

    plt = _pyplot()

    n = max(len(items), 1)
    cols = min(3, n)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 2.6 * rows), squeeze=False)
    for ax, (name, h) in zip(axes.ravel(), items, strict=False):
        lo, hi = h.support_deg()
        centres = bin_centres(h.n_bins)
        x = lo + (centres - lo) % 360.0  # unwrap so the support is contiguous
        pad = max(5.0, 0.1 * (hi - lo))
        keep = (x >= lo - pad) & (x <= hi + pad)
        ax.bar(x[keep], h.values[keep], width=h.bin_width_deg, color="tab:blue")
        ax.axvline(lo + (h.mean_deg() - lo) % 360.0, color="tab:red", lw=1)
        ax.set_title(f"{name}  N={h.n_trials}  s(H)={h.std_deg():.1f}°", fontsize=9)
        ax.set_xlabel("angle (°)", fontsize=8)
    for ax in axes.ravel()[len(items):]:
        ax.set_visible(False)
    return _save_png(fig, path, dpi=80)


def _pyplot():
    """matplotlib's pyplot on the file-only Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save_png(fig, path: str | os.PathLike, dpi: int) -> Path:
    """Lay out, render and write ``fig`` as a PNG atomically, then free it."""
    import io

    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    _pyplot().close(fig)
    atomic_write_bytes(path, buf.getvalue())
    return Path(path)
