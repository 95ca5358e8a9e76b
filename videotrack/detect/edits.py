"""Hand edits of the detections: ghost detections removed, missing ones added or moved, and
model markers marked hidden in a view.

The edits are kept apart from the detections file, which stays what the filters made (a new
detection run keeps the edits): a sidecar beside the results,
``<results stem>.detection-edits.json``, written atomically::

    {"format": "videotrack-detection-edits", "version": 2, "views": ["side", "top"],
     "edits": [{"record": 3, "view": "side", "removed": [[x, y], ...],
                "added": [[x, y], ...], "hidden": ["M3"]}, ...]}

A removed point takes away the detection within :data:`MATCH_PX` of it (none left: the
edit is void, e.g. after detecting again with other filters); added points join the
record's detections in that view. Coordinates are view image pixels, as in the detections
file. ``hidden`` names model markers the user saw to be hidden in that view of the record
(occluded, or merged with another's blob): the fit leaves them out of that view
(:meth:`kinematics.observe.observations.Observations.with_hidden`); a name the chain no longer has
is void. Files without marks are written as version 1 (no ``hidden``), as before, and
version 1 files are read as they are. Everything here is pure (no
Qt): the GUI edits, fits and computes E with :func:`edited_detections` and
:func:`hidden_marks`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from kinematics.fileio import atomic_write_text
from videotrack.errors import VideoTrackError

FORMAT = "videotrack-detection-edits"
VERSION = 2
READS = (1, 2)  # versions read
#: A removed point matches a detection this close (pixels): file coordinates round-trip
#: exactly through JSON, so only the same detection is this close.
MATCH_PX = 1e-3
#: Half-width (pixels) of the window searched for the intensity centroid of a click.
SNAP_RADIUS = 6


@dataclass(frozen=True)
class ViewEdit:
    """The edits of one record in one view: points removed and added, and the names of the
    model markers hidden there."""

    removed: tuple[tuple[float, float], ...] = ()
    added: tuple[tuple[float, float], ...] = ()
    hidden: tuple[str, ...] = ()

    def __bool__(self) -> bool:
        return bool(self.removed or self.added or self.hidden)

    @property
    def moves_points(self) -> bool:
        return bool(self.removed or self.added)


#: Edits by ``(record, view index)``.
Edits = Mapping[tuple[int, int], ViewEdit]


def edits_path(results_path: str | os.PathLike) -> Path:
    """The sidecar of a results file: ``<stem>.detection-edits.json`` beside it."""
    path = Path(results_path)
    return path.with_name(f"{path.stem}.detection-edits.json")


def _near(points: np.ndarray, xy) -> np.ndarray:
    if len(points) == 0:
        return np.zeros(0, bool)
    return np.hypot(*(np.asarray(points, float) - np.asarray(xy, float)).T) <= MATCH_PX


def apply_edit(points, edit: ViewEdit | None) -> np.ndarray:
    """One record's detections in one view, shape (n, 2), with ``edit`` applied."""
    pts = np.asarray(points, float).reshape(-1, 2)
    if not edit:
        return pts
    keep = np.ones(len(pts), bool)
    for xy in edit.removed:
        keep &= ~_near(pts, xy)
    return np.concatenate([pts[keep], np.asarray(edit.added, float).reshape(-1, 2)])


def edited_detections(detections, edits: Edits):
    """A :class:`~videotrack.detect.detections.Detections` with the edits applied (added points
    have area 0); the detections themselves when there are none."""
    edits = {k: e for k, e in edits.items() if e.moves_points and
             0 <= k[0] < detections.n_records and 0 <= k[1] < detections.n_views}
    if not edits:
        return detections
    nv = detections.n_views
    points, areas = [], []
    counts = np.diff(detections.offsets).copy()
    cut = np.asarray(detections.offsets)
    for k in range(len(counts)):
        p = detections.points[cut[k]:cut[k + 1]]
        a = detections.areas[cut[k]:cut[k + 1]]
        edit = edits.get(divmod(k, nv))
        if edit is not None:
            keep = np.ones(len(p), bool)
            for xy in edit.removed:
                keep &= ~_near(p, xy)
            added = np.asarray(edit.added, float).reshape(-1, 2)
            p = np.concatenate([p[keep], added])
            a = np.concatenate([a[keep], np.zeros(len(added), a.dtype)])
        points.append(p)
        areas.append(a)
        counts[k] = len(p)
    offsets = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    return replace(detections, points=np.concatenate(points).astype(np.float64).reshape(-1, 2),
                   areas=np.concatenate(areas), offsets=offsets)


# -- making edits (each returns new edits) --------------------------------------------------
def _with(edits: Edits, key, edit: ViewEdit) -> dict:
    out = dict(edits)
    if edit:
        out[key] = edit
    else:
        out.pop(key, None)
    return out


def add_point(edits: Edits, record: int, view: int, xy) -> dict:
    """Add a detection at ``xy``."""
    key = (int(record), int(view))
    old = edits.get(key, ViewEdit())
    return _with(edits, key, replace(old, added=(*old.added, _pt(xy))))


def remove_point(edits: Edits, record: int, view: int, xy) -> dict:
    """Remove the detection at ``xy`` (an added one is simply dropped)."""
    key = (int(record), int(view))
    old = edits.get(key, ViewEdit())
    added = np.asarray(old.added, float).reshape(-1, 2)
    hit = _near(added, xy)
    if hit.any():
        first = int(np.flatnonzero(hit)[0])
        return _with(edits, key, replace(old, added=old.added[:first] + old.added[first + 1:]))
    return _with(edits, key, replace(old, removed=(*old.removed, _pt(xy))))


def move_point(edits: Edits, record: int, view: int, from_xy, to_xy) -> dict:
    """Move the detection at ``from_xy`` to ``to_xy``."""
    return add_point(remove_point(edits, record, view, from_xy), record, view, to_xy)


def toggle_hidden(edits: Edits, record: int, view: int, marker: str) -> dict:
    """Mark the model marker ``marker`` hidden in a view of a record, or seen again."""
    key = (int(record), int(view))
    old = edits.get(key, ViewEdit())
    hidden = tuple(m for m in old.hidden if m != marker)
    if len(hidden) == len(old.hidden):
        hidden = (*old.hidden, str(marker))
    return _with(edits, key, replace(old, hidden=hidden))


def is_hidden(edits: Edits, record: int, view: int, marker: str) -> bool:
    edit = edits.get((int(record), int(view)))
    return edit is not None and marker in edit.hidden


def hidden_marks(edits: Edits, n_records: int, n_views: int, marker_names: Sequence[str]
                 ) -> np.ndarray | None:
    """The hidden marks as the fitter takes them, (n_records, n_views, n_markers) of bool
    (:meth:`kinematics.observe.observations.Observations.with_hidden`); None when no mark names a
    marker of ``marker_names`` in a record and view that exist."""
    where = {m: k for k, m in enumerate(marker_names)}
    out = None
    for (r, v), edit in edits.items():
        cols = [where[m] for m in edit.hidden if m in where]
        if cols and 0 <= r < n_records and 0 <= v < n_views:
            if out is None:
                out = np.zeros((n_records, n_views, len(marker_names)), bool)
            out[r, v, cols] = True
    return out


def _pt(xy) -> tuple[float, float]:
    x, y = (float(v) for v in xy)
    return x, y


# -- snapping a click -----------------------------------------------------------------------
def snap_to_centroid(image: np.ndarray, xy, radius: int = SNAP_RADIUS) -> tuple[float, float]:
    """The intensity centroid of the marker nearest a click (view image pixels).

    In the square of half-width ``radius`` around ``xy`` the pixels are weighted by how far
    they stand out from the window's median, bright or dark (whichever stands out more),
    counting only the upper half of that contrast; the centroid is taken twice, the second
    time around the first. Without contrast the click itself is returned.
    """
    img = np.asarray(image, float)
    if img.ndim == 3:
        img = img.mean(axis=2)
    h, w = img.shape
    x, y = _pt(xy)
    for _ in range(2):
        cx, cy = round(x), round(y)
        x0, x1 = max(cx - radius, 0), min(cx + radius + 1, w)
        y0, y1 = max(cy - radius, 0), min(cy + radius + 1, h)
        win = img[y0:y1, x0:x1]
        if win.size == 0:
            break
        med = float(np.median(win))
        bright, dark = float(win.max()) - med, med - float(win.min())
        contrast = win - med if bright >= dark else med - win
        peak = max(bright, dark)
        if peak <= 0:
            break
        weight = np.clip(contrast - 0.5 * peak, 0.0, None)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        x, y = float((weight * xx).sum() / weight.sum()), float((weight * yy).sum() / weight.sum())
    return x, y


# -- the sidecar file -----------------------------------------------------------------------
def load_edits(path: str | os.PathLike, view_names: Sequence[str]) -> dict:
    """Read a sidecar (a missing file: no edits) for a project with these views.

    Raises
    ------
    VideoTrackError
        Unreadable JSON, another format, or views that are not the project's.
    """
    path = Path(path)
    if not path.exists():
        return {}
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise VideoTrackError(f"cannot read detection edits: {err}", file=path) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise VideoTrackError(f"not a detection edits file (format {FORMAT!r} expected)",
                              file=path)
    if doc.get("version") not in READS:
        raise VideoTrackError(f"version {doc.get('version')!r} is not supported (expected "
                              f"{' or '.join(map(str, READS))})", file=path, field="version")
    names = list(view_names)
    if doc.get("views") != names:
        raise VideoTrackError(f"edits are for the views {doc.get('views')}, the project has "
                              f"{names}", file=path, field="views")
    edits = {}
    for k, item in enumerate(doc.get("edits", [])):
        where = f"edits[{k}]"
        try:
            record, view = int(item["record"]), names.index(item["view"])
            hidden = item.get("hidden", [])
            if not isinstance(hidden, list) or not all(isinstance(m, str) for m in hidden):
                raise TypeError
            edit = ViewEdit(tuple(_pt(p) for p in item.get("removed", [])),
                            tuple(_pt(p) for p in item.get("added", [])), tuple(hidden))
        except (KeyError, TypeError, ValueError):
            raise VideoTrackError("each edit needs a record, one of the views, lists of "
                                  "[x, y] points and a list of hidden marker names",
                                  file=path, field=where) from None
        if record < 0 or not np.isfinite(np.asarray(edit.removed + edit.added, float)).all():
            raise VideoTrackError("record must be >= 0 and points finite", file=path,
                                  field=where)
        edits[(record, view)] = edit
    return edits


def save_edits(path: str | os.PathLike, edits: Edits, view_names: Sequence[str]) -> Path:
    """Write the sidecar atomically (records in order)."""
    names = list(view_names)
    marks = any(e.hidden for e in edits.values())  # without marks: version 1, as before
    doc = {"format": FORMAT, "version": VERSION if marks else 1, "views": names, "edits": [
        {"record": r, "view": names[v], "removed": [list(p) for p in e.removed],
         "added": [list(p) for p in e.added], **({"hidden": list(e.hidden)} if marks else {})}
        for (r, v), e in sorted(edits.items()) if e]}
    path = Path(path)
    atomic_write_text(path, json.dumps(doc, indent=1) + "\n")
    return path
