"""Scoring fitted results against ground truth: angle errors per axis, 3D errors per point.

The truth is a CSV table with a ``frame`` column — the record index, as the detections and
results number records — and columns named like the results file's: ``joint.axis`` in
degrees and ``point.x/y/z`` in chain units, such as the ``truth.csv`` of
``videotrack synth``. Rows are matched by frame; frames the fit could not do (no
detections: NaN angles) are left out of the scores and counted.

Angle differences are wrapped into [-180°, 180°), so 359° against 1° is an error of 2°.
Derived axes (the paper's α+β) are given as sums of axes, ``J0.alpha+J1.beta``; a sum is
compared with the same sum of the true angles, then wrapped.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinematics.fileio import atomic_write_text
from videotrack.errors import VideoTrackError
from videotrack.results.files import Results, read_results
from videotrack.results.tables import format_cell, read_table, text_table

#: Default threshold of the "% frames off" column, degrees.
DEFAULT_THRESHOLD_DEG = 5.0


@dataclass(frozen=True)
class ErrorStats:
    """Errors of one axis, sum of axes or 3D point over the scored frames.

    ``kind`` is ``"angle"``, ``"sum"`` (degrees) or ``"point"`` (Euclidean distance, chain
    units); ``over`` is the percentage of frames off by more than the threshold (angles
    and sums; NaN for points).
    """

    name: str
    kind: str
    n: int
    rmse: float
    median: float
    max: float
    over: float


@dataclass(frozen=True)
class Evaluation:
    """Every score of a results file against its truth.

    Attributes
    ----------
    rows : tuple of ErrorStats
        Free axes (in the results' order), then the sums, then markers and joint centres.
    threshold_deg : float
    n_frames : int
        Results rows that have a truth row.
    n_scored : int
        Of them, the rows with a fit (finite angles).
    frames_over : float
        Percentage of scored frames where any axis or sum is off by more than the threshold.
    unmatched : int
        Results rows without a truth row (not scored).
    """

    rows: tuple[ErrorStats, ...]
    threshold_deg: float
    n_frames: int
    n_scored: int
    frames_over: float
    unmatched: int

    def row(self, name: str) -> ErrorStats:
        """The scores of one axis, sum or point by name."""
        for r in self.rows:
            if r.name == name:
                return r
        raise KeyError(name)


def wrap_deg(diff):
    """Angle differences wrapped into [-180, 180) degrees."""
    return (np.asarray(diff, dtype=float) + 180.0) % 360.0 - 180.0


def parse_sum(text: str, labels: Sequence[str]) -> np.ndarray:
    """Coefficients (+1/-1 per term) over ``labels`` of a sum like ``J0.alpha+J1.beta``.

    Terms are axis labels joined by ``+`` or ``-`` (labels may themselves contain ``-``:
    the longest label that fits is taken).

    Raises
    ------
    VideoTrackError
        A term that is no axis label (field ``--sum``).
    """
    coef = np.zeros(len(labels))
    s = text.replace(" ", "")
    pos, sign, terms = 0, 1.0, 0
    if s[:1] in "+-" and s:
        sign, pos = (-1.0 if s[0] == "-" else 1.0), 1
    while pos < len(s):
        match = max((lb for lb in labels if s.startswith(lb, pos)), key=len, default=None)
        if match is None:
            raise VideoTrackError(f"{text!r}: no axis named like {s[pos:]!r} (axes: "
                                  f"{', '.join(labels)})", field="--sum")
        coef[list(labels).index(match)] += sign
        terms += 1
        pos += len(match)
        if pos < len(s):
            if s[pos] not in "+-":
                raise VideoTrackError(f"{text!r}: expected + or - after {match!r}",
                                      field="--sum")
            sign, pos = (-1.0 if s[pos] == "-" else 1.0), pos + 1
            if pos == len(s):
                raise VideoTrackError(f"{text!r}: ends with an operator", field="--sum")
    if not terms:
        raise VideoTrackError("empty sum", field="--sum")
    return coef


def evaluate(results: Results, truth_columns: Sequence[str], truth: np.ndarray,
             sums: Sequence[str] = (), threshold_deg: float = DEFAULT_THRESHOLD_DEG
             ) -> Evaluation:
    """Score ``results`` against a truth table.

    Parameters
    ----------
    results : Results
    truth_columns : sequence of str
        Column names of ``truth``; must include ``frame``.
    truth : ndarray, shape (n_rows, n_columns)
    sums : sequence of str
        Derived axes, e.g. ``"J0.alpha+J1.beta"`` (see :func:`parse_sum`).
    threshold_deg : float
        An angle off by more than this counts as off.

    Raises
    ------
    VideoTrackError
        No ``frame`` column, no axis in common, a bad sum.
    """
    cols = _columns(truth_columns)
    labels = list(results.axis_labels)
    if not any(lb in cols for lb in labels):
        raise VideoTrackError(f"no axis of the results ({', '.join(labels)}) is a column of "
                              "the truth table")
    rows_t = _truth_rows(results, cols, truth)
    found = rows_t >= 0
    rows_t = rows_t[found]
    fit = results.angles_deg[found]
    # Axes missing from the truth count as exact, so a sum over them still works.
    true = np.column_stack([truth[rows_t, cols[lb]] if lb in cols else fit[:, i]
                            for i, lb in enumerate(labels)])
    scored = np.isfinite(fit).all(axis=1) & np.isfinite(true).all(axis=1)
    fit, true = fit[scored], true[scored]
    stats, off = [], np.zeros(len(fit), dtype=bool)

    def angle_row(name: str, kind: str, err: np.ndarray) -> None:
        nonlocal off
        a = np.abs(err)
        off |= a > threshold_deg
        stats.append(ErrorStats(name, kind, len(a), _rms(a), _median(a), _max(a),
                                100.0 * float((a > threshold_deg).mean()) if len(a) else
                                float("nan")))

    for i, lb in enumerate(labels):
        locked = np.array_equal(fit[:, i], true[:, i]) and (
            len(true) == 0 or np.ptp(true[:, i]) == 0)
        if lb in cols and not locked:  # locked axes (hinge joints) are exact by construction
            angle_row(lb, "angle", wrap_deg(fit[:, i] - true[:, i]))
    for text in sums:
        coef = parse_sum(text, labels)
        angle_row(text, "sum", wrap_deg(fit @ coef - true @ coef))
    sel = np.flatnonzero(found)[scored]
    for names, points in ((results.marker_names, results.markers),
                          (results.joint_names, results.joints)):
        for m, name in enumerate(names):
            keys = [f"{name}.{a}" for a in "xyz"]
            if not all(k in cols for k in keys):
                continue
            t = truth[rows_t[scored]][:, [cols[k] for k in keys]]
            d = np.linalg.norm(points[sel, m] - t, axis=1)
            d = d[np.isfinite(d)]
            stats.append(ErrorStats(name, "point", len(d), _rms(d), _median(d), _max(d),
                                    float("nan")))
    return Evaluation(tuple(stats), float(threshold_deg), int(found.sum()), int(scored.sum()),
                      100.0 * float(off.mean()) if len(off) else float("nan"),
                      int((~found).sum()))


def truth_angles(results: Results, truth_columns: Sequence[str], truth: np.ndarray
                 ) -> np.ndarray:
    """The true angles of each results row, shape (n_rows, n_axes), degrees; NaN where the
    truth has no such frame or axis (e.g. to draw beside the fit)."""
    cols = _columns(truth_columns)
    rows_t = _truth_rows(results, cols, truth)
    out = np.full(results.angles_deg.shape, np.nan)
    for i, lb in enumerate(results.axis_labels):
        if lb in cols:
            out[rows_t >= 0, i] = truth[rows_t[rows_t >= 0], cols[lb]]
    return out


def _columns(truth_columns: Sequence[str]) -> dict:
    """Column index by name (names are unique: axes may not be called x, y or z)."""
    cols = {c: i for i, c in enumerate(truth_columns)}
    if len(cols) != len(truth_columns):
        dup = next(c for c in truth_columns if list(truth_columns).count(c) > 1)
        raise VideoTrackError(f"column '{dup}' appears twice", field=dup)
    if "frame" not in cols:
        raise VideoTrackError("the truth table needs a 'frame' column", field="frame")
    return cols


def _truth_rows(results: Results, cols: dict, truth: np.ndarray) -> np.ndarray:
    """Truth row of each results row by frame number, -1 where there is none."""
    row_of = {int(f): i for i, f in enumerate(truth[:, cols["frame"]]) if f == f}
    return np.array([row_of.get(int(f), -1) for f in results.frames], dtype=np.int64)


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a)))) if len(a) else float("nan")


def _median(a: np.ndarray) -> float:
    return float(np.median(a)) if len(a) else float("nan")


def _max(a: np.ndarray) -> float:
    return float(np.max(a)) if len(a) else float("nan")


def evaluate_files(results_path: str | os.PathLike, truth_path: str | os.PathLike,
                   sums: Sequence[str] = (), threshold_deg: float = DEFAULT_THRESHOLD_DEG
                   ) -> Evaluation:
    """:func:`evaluate` of a results CSV against a truth CSV (errors name the file)."""
    results = read_results(results_path)
    columns, truth = read_table(truth_path)
    try:
        return evaluate(results, columns, truth, sums, threshold_deg)
    except VideoTrackError as err:
        raise err.located(file=None if err.field == "--sum" else truth_path) from None


def format_evaluation(ev: Evaluation) -> str:
    """Plain-text tables: angles (degrees), then 3D points (chain units)."""
    lines = [f"{ev.n_scored} frames scored ({ev.n_frames - ev.n_scored} without a fit"
             + (f", {ev.unmatched} without truth" if ev.unmatched else "") + ")"]
    angles = [r for r in ev.rows if r.kind != "point"]
    if angles:
        lines += ["", text_table(("axis", "RMSE (°)", "median |err| (°)", "max (°)",
                              f"> {ev.threshold_deg:g}° (%)"),
                             [(r.name, _f(r.rmse), _f(r.median), _f(r.max), _f(r.over, 1))
                              for r in angles]),
                  f"frames with any axis off by more than {ev.threshold_deg:g}°: "
                  f"{_f(ev.frames_over, 1)} %"]
    points = [r for r in ev.rows if r.kind == "point"]
    if points:
        lines += ["", text_table(("point", "RMSE", "median", "max"),
                             [(r.name, _f(r.rmse), _f(r.median), _f(r.max)) for r in points]),
                  "3D distances in the chain's units."]
    return "\n".join(lines)


def evaluation_csv(ev: Evaluation) -> str:
    """CSV text: one row per axis, sum and point (numbers in their shortest exact form)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["quantity", "kind", "frames", "rmse", "median_abs", "max_abs",
                     "over_threshold_pct", "threshold_deg"])
    for r in ev.rows:
        writer.writerow([r.name, r.kind, r.n, format_cell(r.rmse), format_cell(r.median),
                         format_cell(r.max), format_cell(r.over),
                         format_cell(ev.threshold_deg) if r.kind != "point" else ""])
    return buf.getvalue()


def write_evaluation(ev: Evaluation, path: str | os.PathLike) -> Path:
    """Write :func:`evaluation_csv` atomically."""
    atomic_write_text(path, evaluation_csv(ev))
    return Path(path)


def _f(value: float, digits: int = 2) -> str:
    return "-" if value != value else f"{value:.{digits}f}"
