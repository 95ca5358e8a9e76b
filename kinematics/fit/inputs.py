"""Detections as the fitter takes them: ragged points per frame and view, cleaned;
the markers each view can show.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from kinematics.errors import KinematicsError
from kinematics.observe.observations import sorted_by_x


@dataclass(frozen=True)
class Ragged:
    """Detections of several frames, cleaned: NaN rows dropped, layout as the kernels'."""

    points: np.ndarray  # (n, 2) float64, finite
    offsets: np.ndarray  # (n_frames * n_views + 1,) int64
    dropped: np.ndarray  # (n_frames,) int64 rows dropped per frame
    n_views: int

    @property
    def n_frames(self) -> int:
        return (self.offsets.size - 1) // self.n_views

    def counts(self) -> np.ndarray:
        return np.diff(self.offsets).reshape(self.n_frames, self.n_views)

    def select(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points and frame-major offsets of the given frames only, in that order."""
        nv = self.n_views
        starts = self.offsets[frames * nv]
        stops = self.offsets[frames * nv + nv]
        pts = np.concatenate([self.points[a:b] for a, b in zip(starts, stops, strict=True)]
                             ) if len(frames) else np.empty((0, 2))
        counts = np.diff(self.offsets)[(frames[:, None] * nv + np.arange(nv)).ravel()]
        off = np.zeros(counts.size + 1, np.int64)
        np.cumsum(counts, out=off[1:])
        return np.ascontiguousarray(pts.reshape(-1, 2), dtype=np.float64), off


def as_ragged(detections, view_names: Sequence[str]) -> Ragged:
    """Accept a :class:`videotrack.detect.detections.Detections`-like object (``points`` (n, 2),
    ``offsets`` (n_frames * n_views + 1,), optional ``view_names``) or a sequence of frames,
    each a sequence of per-view (n_c, 2) arrays (or an object with such a ``points``)."""
    nv = len(view_names)
    if hasattr(detections, "offsets") and hasattr(detections, "points"):
        names = getattr(detections, "view_names", None)
        if names is not None and list(names) != list(view_names):
            raise KinematicsError(f"detections are for views {list(names)} but the cameras "
                                  f"are {list(view_names)}", field="detections")
        pts = np.asarray(detections.points, dtype=float).reshape(-1, 2)
        off = np.asarray(detections.offsets, dtype=np.int64).ravel()
        if off.size < 1 or (off.size - 1) % nv or off[0] != 0 or off[-1] != len(pts) or np.any(
                np.diff(off) < 0):
            raise KinematicsError(f"offsets must rise from 0 to {len(pts)} in (frames x "
                                  f"{nv} views + 1) entries", field="detections")
    else:
        rows, counts = [], []
        for f, frame in enumerate(detections):
            views = getattr(frame, "points", frame)
            views = list(views)
            if len(views) != nv:
                raise KinematicsError(f"frame {f} has detections for {len(views)} views but "
                                      f"there are {nv} cameras {list(view_names)}",
                                      field="detections")
            for v, det in enumerate(views):
                a = np.asarray(det, dtype=float)
                if a.size and (a.ndim != 2 or a.shape[1] != 2):
                    raise KinematicsError(f"frame {f} view {view_names[v]}: points must have "
                                          f"shape (n, 2), got {a.shape}", field="detections")
                rows.append(a.reshape(-1, 2))
                counts.append(len(rows[-1]))
        pts = np.concatenate(rows) if rows else np.empty((0, 2))
        off = np.zeros(len(counts) + 1, np.int64)
        np.cumsum(counts, out=off[1:])
    good = np.isfinite(pts).all(axis=1)
    n_frames = (off.size - 1) // nv
    if good.all():
        return Ragged(sorted_by_x(pts, off), off, np.zeros(n_frames, np.int64), nv)
    keep_before = np.concatenate([[0], np.cumsum(good)])
    new_off = keep_before[off].astype(np.int64)
    bad_per_cell = np.diff(off) - np.diff(new_off)
    dropped = bad_per_cell.reshape(n_frames, nv).sum(axis=1)
    return Ragged(sorted_by_x(pts[good], new_off), new_off, dropped.astype(np.int64), nv)


def unseen_markers(view_markers, view_names: Sequence[str], marker_names: Sequence[str]
                    ) -> np.ndarray | None:
    """(n_views, n_markers) bool: markers a view cannot show, from ``view_markers`` (view
    name -> the marker names it shows; views not named show all); None when every view
    shows every marker."""
    if not view_markers:
        return None
    if not isinstance(view_markers, Mapping):
        raise KinematicsError("view_markers must map view names to marker names",
                              field="view_markers")
    index = {m: k for k, m in enumerate(marker_names)}
    unseen = np.zeros((len(view_names), len(marker_names)), bool)
    for view, shown in view_markers.items():
        if view not in view_names:
            raise KinematicsError(f"no view named {view!r} (views: {', '.join(view_names)})",
                                  field="view_markers")
        if isinstance(shown, str):
            raise KinematicsError(f"view {view!r}: give a list of marker names, not one "
                                  f"string", field="view_markers")
        try:
            shown = [str(m) for m in shown]
        except TypeError:
            raise KinematicsError(f"view {view!r}: give a list of marker names, got "
                                  f"{shown!r}", field="view_markers") from None
        unknown = [m for m in shown if m not in index]
        if unknown:
            raise KinematicsError(f"view {view!r}: {unknown[0]!r} is not a marker of the "
                                  f"body (markers: {', '.join(marker_names)})",
                                  field="view_markers")
        v = view_names.index(view)
        unseen[v] = True
        unseen[v, [index[m] for m in shown]] = False
    return unseen if unseen.any() else None
