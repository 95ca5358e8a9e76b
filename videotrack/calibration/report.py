"""How good and how repeatable a calibration is: figures, warnings, a PNG.

- reprojection error per camera and overall (median, 95th percentile) over all corners;
- board geometry: the corners triangulated from all cameras, the distance between neighbours
  against the true square size (the marker side on an ArUco grid);
- views used per camera and how much of the image the corners cover;
- repeatability: the spread of camera centres and focal lengths over the starts.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from kinematics.cameras.calibration_math import triangulate
from videotrack.calibration.boards import Board
from videotrack.calibration.bundle import Calibration
from videotrack.calibration.detect import Corners

__all__ = ["Report", "make_report", "save_png"]

#: A camera with fewer views in the adjustment is poorly constrained.
MIN_GOOD_VIEWS = 8
#: ... or one whose corners cover less of the image than this fraction.
MIN_COVERAGE = 0.25
#: A start whose median error exceeds the best's by this factor (+0.5 px) has diverged.
DIVERGED = 2.0


@dataclass
class Report:
    rows: list[dict]  # per camera
    overall: dict
    square: dict | None  # square (marker) side: median, p95 of |measured - true| ... in mm
    repeat: dict | None  # centre_mm, focal_rel, starts, diverged; None: one start
    warnings: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        out = [f"{'camera':<12} {'views':>5} {'used':>5} {'corners':>7} {'median px':>9} "
               f"{'p95 px':>7} {'outliers':>8} {'coverage':>8}"]
        for r in self.rows:
            out.append(f"{r['camera']:<12} {r['views']:>5} {r['used']:>5} {r['corners']:>7} "
                       f"{r['median']:>9.3f} {r['p95']:>7.3f} {r['outliers']:>8} "
                       f"{r['coverage']:>7.0%}")
        o = self.overall
        out.append(f"{'all':<12} {'':>5} {'':>5} {o['corners']:>7} {o['median']:>9.3f} "
                   f"{o['p95']:>7.3f} {o['outliers']:>8}")
        if self.square:
            s = self.square
            out.append(f"{s['what']} size: {s['measured']:.3f} mm measured (median of "
                       f"{s['pairs']} neighbouring corners triangulated), true {s['true']:g} "
                       f"mm, error {s['error']:+.3f} mm")
        if self.repeat:
            r = self.repeat
            out.append(f"repeatability over {r['starts']} starts: camera centres within "
                       f"{r['centre_mm']:.3f} mm, focal lengths within "
                       f"{100 * r['focal_rel']:.3f} %, {r['diverged']} diverged")
        out += [f"warning: {w}" for w in self.warnings]
        return out


def _coverage(uv: np.ndarray, size) -> float:
    """Fraction of the image inside the convex hull of all corners seen."""
    import cv2

    pts = uv.reshape(-1, 2)
    pts = pts[np.isfinite(pts[:, 0])].astype(np.float32)
    if len(pts) < 3:
        return 0.0
    return float(cv2.contourArea(cv2.convexHull(pts))) / (size[0] * size[1])


def _square(cal: Calibration, corners: list[Corners], board: Board) -> dict | None:
    uv = np.array([c.uv for c in corners])  # (c, v, n, 2)
    pairs, true, what = board.edges()
    measured = []
    for v in range(uv.shape[1]):
        if np.isfinite(uv[:, v, :, 0]).any(axis=1).sum() < 2:
            continue
        X = triangulate(cal.cameras, uv[:, v])
        measured.append(np.linalg.norm(X[pairs[:, 0]] - X[pairs[:, 1]], axis=-1))
    d = np.concatenate(measured) if measured else np.zeros(0)
    d = d[np.isfinite(d)]
    if len(d) == 0:
        return None
    med = float(np.median(d))
    return {"what": what, "measured": med, "true": true, "error": med - true,
            "p95_abs": float(np.percentile(np.abs(d - true), 95)), "pairs": len(d)}


def _repeat(cal: Calibration) -> dict | None:
    if len(cal.restarts) < 2:
        return None
    best = next(r for r in cal.restarts if r["best"])
    centre, focal = 0.0, 0.0
    diverged = 0
    for r in cal.restarts:
        if r["median"] > DIVERGED * best["median"] + 0.5:
            diverged += 1
            continue
        for a, b in zip(r["cameras"], best["cameras"], strict=True):
            centre = max(centre, float(np.linalg.norm(a.centre - b.centre)))
            focal = max(focal, float(np.max(np.abs(np.diag(a.K)[:2] / np.diag(b.K)[:2] - 1))))
    return {"starts": len(cal.restarts), "centre_mm": centre, "focal_rel": focal,
            "diverged": diverged}


def make_report(cal: Calibration, corners: list[Corners], board: Board | None) -> Report:
    rows, warnings = [], []
    for i, c in enumerate(corners):
        e = cal.errors[i][np.isfinite(cal.errors[i])]
        n_out = int((np.isfinite(cal.errors[i]) & ~cal.inlier[i]).sum())
        cov = _coverage(c.uv, c.size)
        rows.append({"camera": c.name, "views": c.views_found, "used": int(cal.views_used[i]),
                     "corners": int(e.size),
                     "median": float(np.median(e)) if e.size else float("nan"),
                     "p95": float(np.percentile(e, 95)) if e.size else float("nan"),
                     "outliers": n_out, "coverage": cov})
        if cal.views_used[i] < MIN_GOOD_VIEWS:
            warnings.append(f"{c.name} is poorly constrained: the board is used in only "
                            f"{cal.views_used[i]} view(s); record more")
        if cov < MIN_COVERAGE:
            warnings.append(f"{c.name}: the board covers only {cov:.0%} of the image; "
                            "distortion is extrapolated elsewhere (move the board to the "
                            "edges and corners)")
    e = cal.errors[np.isfinite(cal.errors)]
    overall = {"corners": int(e.size), "median": float(np.median(e)),
               "p95": float(np.percentile(e, 95)),
               "outliers": int((np.isfinite(cal.errors) & ~cal.inlier).sum())}
    for r in rows:
        if r["median"] > 2.0 * overall["median"] + 0.5:
            warnings.append(f"{r['camera']}: reprojection error {r['median']:.2f} px is far "
                            "above the others' (wrong board config, unsynchronised video, "
                            "moving camera?)")
    square = _square(cal, corners, board) if board is not None and cal.tree else None
    repeat = _repeat(cal)
    if repeat and repeat["diverged"]:
        warnings.append(f"{repeat['diverged']} of {repeat['starts']} starts ended in a worse "
                        "minimum; the best was kept (more views seen by several cameras help)")
    return Report(rows, overall, square, repeat, warnings)


def save_png(path: str | os.PathLike, cal: Calibration, corners: list[Corners]) -> None:
    """Per camera: a histogram of reprojection errors and the corners coloured by error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from kinematics.fileio import atomic_write

    n = len(corners)
    fig, axes = plt.subplots(n, 2, figsize=(9, 2.6 * n), squeeze=False)
    finite = cal.errors[np.isfinite(cal.errors)]
    top = max(float(np.percentile(finite, 99)), 1e-3) if finite.size else 1.0
    for i, c in enumerate(corners):
        err = cal.errors[i, : len(c.uv)]  # (cameras may have fewer views: intrinsics only)
        ok = np.isfinite(err)
        ax = axes[i, 0]
        ax.hist(np.minimum(err[ok], top), bins=40, color="0.3")
        if ok.any():
            for q, style in ((50, "-"), (95, "--")):
                ax.axvline(np.percentile(err[ok], q), color="C3", ls=style, label=f"p{q}")
        ax.set_title(f"{c.name}: reprojection error (px)", fontsize=9)
        ax.legend(fontsize=7)
        ax = axes[i, 1]
        uv = c.uv[ok]
        sc = ax.scatter(uv[:, 0], uv[:, 1], c=np.minimum(err[ok], top), s=3, cmap="viridis",
                        vmin=0, vmax=top)
        ax.set_xlim(0, c.size[0])
        ax.set_ylim(c.size[1], 0)
        ax.set_aspect("equal")
        ax.set_title(f"{c.name}: corners by error", fontsize=9)
        fig.colorbar(sc, ax=ax, label="px")
    fig.tight_layout()
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=80)
    plt.close(fig)
