"""Numeric CSV tables (ground truth, results): a header row, then one row per frame.

Values are written in the shortest form that reads back to the same float (``repr``), so
tables round-trip exactly; NaN is written as an empty cell. Writes are atomic.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Sequence

import numpy as np

from kinematics.fileio import atomic_write_text
from videotrack.errors import VideoTrackError


def format_cell(v: float) -> str:
    """A number as a CSV cell: shortest exact form, integers without a point, NaN empty,
    infinities as ``inf``."""
    if v != v:  # NaN
        return ""
    if abs(v) < 1e15 and v == int(v):
        return str(int(v))
    return repr(float(v))


def format_table(columns: Sequence[str], values: np.ndarray) -> str:
    """CSV text of a (n_rows, n_columns) array with the given header."""
    values = np.asarray(values, dtype=float)
    if values.ndim != 2 or values.shape[1] != len(columns):
        raise ValueError(f"{len(columns)} columns but values of shape {values.shape}")
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in values.tolist():
        writer.writerow([format_cell(v) for v in row])
    return buf.getvalue()


def text_table(head: Sequence[str], body: Sequence[Sequence[str]], left: int = 1) -> str:
    """A plain-text table for the terminal: the first ``left`` columns left-aligned, the
    others (numbers) right-aligned, a rule under the header."""
    widths = [max(len(x) for x in col) for col in zip(head, *body, strict=True)]
    lines = ["  ".join(x.ljust(w) if i < left else x.rjust(w)
                       for i, (x, w) in enumerate(zip(line, widths, strict=True)))
             for line in (head, *body)]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def write_table(path: str | os.PathLike, columns: Sequence[str], values: np.ndarray) -> None:
    """Write a numeric table as CSV, atomically."""
    atomic_write_text(path, format_table(columns, values))


def read_table(path: str | os.PathLike) -> tuple[list[str], np.ndarray]:
    """Read a numeric CSV table (:func:`write_table`'s, or another tool's: a byte-order mark
    and blank cells, read as NaN, are accepted): (columns, values (n_rows, n_columns))."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except OSError as err:
        raise VideoTrackError(f"cannot read table: {err.strerror}", file=path) from None
    except (UnicodeDecodeError, csv.Error) as err:
        raise VideoTrackError(f"not a CSV table ({err})", file=path) from None
    if not rows:
        raise VideoTrackError("file is empty", file=path)
    columns = rows[0]
    out = np.full((len(rows) - 1, len(columns)), np.nan)
    for i, row in enumerate(rows[1:]):
        if len(row) != len(columns):
            raise VideoTrackError(f"row has {len(row)} cells, header has {len(columns)}",
                                  file=path, line=i + 2)
        for j, cell in enumerate(row):
            if cell.strip() == "":
                continue
            try:
                out[i, j] = float(cell)
            except ValueError:
                raise VideoTrackError(f"'{cell}' is not a number", file=path, line=i + 2,
                                      field=columns[j]) from None
    return columns, out
