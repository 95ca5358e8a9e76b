"""What a posture is fitted to: one :class:`Observations` type for three kinds of input.

``points``
    Unlabelled points per view (the paper's marker detections): any number per view and
    frame, matched to model markers by the objective (Eq. 5: nearest point).
``keypoints``
    Labelled 2D keypoints per view (DeepLabCut, SLEAP, …): for every model marker in every
    view an (x, y, confidence) triple, NaN (or confidence 0) when missing. Objective: the
    labelled reprojection error, each marker against its own keypoint, weighted by the
    confidence and capped (a robust loss against mislabelled frames).
``points3d``
    Labelled 3D points (Anipose, motion capture): for every model marker an (x, y, z, weight)
    row in the body's length units, NaN when missing. Objective: the 3D distance of each
    marker to its point, weighted and capped. No cameras are needed.
``cloud``
    Unlabelled points per view together with their triangulation across the views
    (:func:`kinematics.observe.cloud.triangulate_unlabelled`): per frame any number of 3D points
    ``(x, y, z, s)`` with ``s`` the pixels per length unit at the point (0 marks padding).
    Objective: each model marker's distance to its nearest 3D point times ``s`` (Eq. 5 in
    3D, in pixels), capped. The 2D points stay for residuals per view and for drawing.

Layout (the kernels'): 2D observations are ragged, frame-major: ``points`` (n, 2) pixels
with ``conf`` (n,) weights, view ``v`` of frame ``f`` owning rows
``offsets[f * n_views + v]:offsets[f * n_views + v + 1]``; for keypoints a view's rows are
the body's markers in order (``n_markers`` rows) or none. 3D points are ``points3d``
(n_frames, n_markers, 4), a cloud's (n_frames, most points in a frame, 4).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from kinematics._kernels import codes as _codes
from kinematics.errors import KinematicsError

KINDS = ("points", "keypoints", "points3d", "cloud")


class ObservationArrays(NamedTuple):
    """Observations of some frames as the kernels take them (see the module doc)."""

    objective: int
    points: np.ndarray  # (n_points, 2)
    conf: np.ndarray  # (n_points,)
    offsets: np.ndarray  # (n_frames * n_views + 1,) int64
    points3d: np.ndarray  # (n_frames, n_markers or 0, 4); a cloud's (n_frames, k, 4)

    def frame(self, k: int, n_views: int) -> ObservationArrays:
        """The arrays of the ``k``-th of these frames alone, as :meth:`Observations.arrays`
        gives them for that frame (views of these, no copy)."""
        off = self.offsets[k * n_views: (k + 1) * n_views + 1]
        a, b = int(off[0]), int(off[-1])
        return ObservationArrays(self.objective, self.points[a:b], self.conf[a:b], off - a,
                                 self.points3d[k: k + 1])


_OBJECTIVE = {"points": _codes.OBJ_NEAREST, "keypoints": _codes.OBJ_LABELLED,
              "points3d": _codes.OBJ_POINTS3D, "cloud": _codes.OBJ_CLOUD}


@dataclass(frozen=True, eq=False)
class Observations:
    """Observations of many frames in the kernels' layout (build with the class methods).

    Attributes
    ----------
    kind : {"points", "keypoints", "points3d", "cloud"}
    view_names : tuple of str (empty for 3D points)
    n_frames : int
    points : ndarray (n, 2); conf : ndarray (n,); offsets : ndarray (n_frames * n_views + 1,)
    points3d : ndarray (n_frames, n_markers, 4) (n_markers 0 for 2D kinds; for a cloud
        (n_frames, k, 4) x, y, z, pixels per length unit, 0 in padding rows)
    dropped : ndarray (n_frames,) unlabelled points dropped for a NaN coordinate
    hidden : ndarray (n_frames, n_views, n_markers) of bool, or None: model markers the user
        marked hidden in a view (unlabelled points only; :meth:`with_hidden`)
    unseen : ndarray (n_views, n_markers) of bool, or None: markers a view never shows, in
        every frame (unlabelled points only; :meth:`with_unseen`)
    """

    kind: str
    view_names: tuple[str, ...]
    n_frames: int
    points: np.ndarray
    conf: np.ndarray
    offsets: np.ndarray
    points3d: np.ndarray
    dropped: np.ndarray
    hidden: np.ndarray | None = None
    unseen: np.ndarray | None = None

    @property
    def n_views(self) -> int:
        return len(self.view_names)

    @property
    def objective(self) -> int:
        """The kernels' objective code for this kind."""
        return _OBJECTIVE[self.kind]

    @property
    def labelled(self) -> bool:
        return self.kind in ("keypoints", "points3d")

    # -- construction ------------------------------------------------------------------
    @classmethod
    def unlabelled(cls, points, offsets, view_names: Sequence[str], dropped=None
                   ) -> Observations:
        """Unlabelled points from the ragged layout (finite rows only), sorted by x within
        each view as the kernels search them (:func:`sorted_by_x`)."""
        off = np.ascontiguousarray(np.asarray(offsets, dtype=np.int64))
        pts = sorted_by_x(np.asarray(points, dtype=float).reshape(-1, 2), off)
        nv = len(view_names)
        n = (off.size - 1) // max(nv, 1)
        drop = np.zeros(n, np.int64) if dropped is None else np.asarray(dropped, np.int64)
        return cls("points", tuple(view_names), n, pts, np.ones(len(pts)), off,
                   np.zeros((n, 0, 4)), drop)

    def with_cloud(self, cloud) -> Observations:
        """These unlabelled points with their 3D cloud ``cloud`` (n_frames, k, 4): x, y, z
        and the pixels per length unit at each point (0 or NaN rows: padding); optionally
        followed by one column per model marker, nonzero where it may take the point
        (markers of several colours, :func:`kinematics.observe.cloud.cloud_observations`)."""
        if self.kind != "points":
            raise KinematicsError(f"a cloud is made of unlabelled points, not {self.kind}",
                                  field="observations")
        if self.hidden is not None or self.unseen is not None:
            raise KinematicsError("markers hidden in a view cannot be matched in 3D: set "
                                  "match = 'views'", field="hidden")
        c = np.array(cloud, dtype=float, copy=True)
        if c.ndim != 3 or c.shape[0] != self.n_frames or c.shape[2] < 4:
            raise KinematicsError(f"a cloud needs shape ({self.n_frames} frames, points, 4 "
                                  f"or 4 + markers), got {c.shape}", field="cloud")
        bad = ~np.isfinite(c).all(axis=2) | ~(c[..., 3] > 0)
        c[bad] = 0.0
        return Observations("cloud", self.view_names, self.n_frames, self.points, self.conf,
                            self.offsets, np.ascontiguousarray(c), self.dropped)

    def with_hidden(self, hidden) -> Observations:
        """These observations with model markers marked hidden in some views, ``hidden``
        (n_frames, n_views, n_markers) of bool, e.g. a marker occluded in one view, or whose
        blob merged with another's. For unlabelled points such a marker is left out of that
        view's E: it costs nothing and explains no point
        (:func:`kinematics._kernels.posture.hidden_in`). For labelled keypoints its keypoint
        there counts as missing. Not for 3D points or a cloud, which have no views to hide a
        marker in. Marks add to those already made; no mark at all gives these observations
        back."""
        h = np.asarray(hidden)
        if h.ndim != 3 or h.shape[:2] != (self.n_frames, self.n_views) or h.dtype != bool:
            raise KinematicsError(f"hidden marks need a boolean array of shape "
                                  f"({self.n_frames} frames, {self.n_views} views, markers), "
                                  f"got {h.dtype} {h.shape}", field="hidden")
        if not h.any():
            return self
        if self.kind not in ("points", "keypoints"):
            raise KinematicsError(f"a marker is hidden in a view of 2D points, not of "
                                  f"{self.kind} (matching in 3D: set match = 'views')",
                                  field="hidden")
        nm = h.shape[2]
        if self.kind == "points":
            if self.hidden is not None:
                if self.hidden.shape != h.shape:
                    raise KinematicsError(f"hidden marks are for {self.hidden.shape[2]} "
                                          f"markers, these for {nm}", field="hidden")
                h = h | self.hidden
            self._check_markers(nm, self.unseen)
            return replace(self, hidden=np.ascontiguousarray(h))
        return self._keypoints_without(lambda f, v, i: h[f, v, i], nm)

    def with_unseen(self, unseen) -> Observations:
        """These observations with markers some views never show, ``unseen`` (n_views,
        n_markers) of bool (a view of one colour of markers: the others; a camera that
        never sees the far side of the body): in every frame as :meth:`with_hidden` marks,
        kept per view, not per frame (long videos)."""
        u = np.asarray(unseen)
        if u.ndim != 2 or u.shape[0] != self.n_views or u.dtype != bool:
            raise KinematicsError(f"unseen markers need a boolean array of shape "
                                  f"({self.n_views} views, markers), got {u.dtype} {u.shape}",
                                  field="view_markers")
        if not u.any():
            return self
        if self.kind == "keypoints":
            return self._keypoints_without(lambda f, v, i: u[v, i], u.shape[1])
        if self.kind != "points":
            raise KinematicsError(f"a view shows some markers of 2D points, not of "
                                  f"{self.kind}", field="view_markers")
        self._check_markers(u.shape[1], self.hidden)
        if self.unseen is not None:
            self._check_markers(u.shape[1], self.unseen)
            u = u | self.unseen
        return replace(self, unseen=np.ascontiguousarray(u))

    @staticmethod
    def _check_markers(nm: int, marks) -> None:
        if marks is not None and marks.shape[-1] != nm:
            raise KinematicsError(f"hidden marks are for {marks.shape[-1]} markers, these for "
                                  f"{nm}", field="hidden")

    def marks(self, frames) -> np.ndarray | None:
        """(len(frames), n_views, n_markers) bool: markers hidden in each view of these
        frames (:meth:`with_hidden` and :meth:`with_unseen` together), or None."""
        if self.hidden is None and self.unseen is None:
            return None
        frames = np.asarray(frames, dtype=np.int64)
        if self.hidden is None:
            return np.broadcast_to(self.unseen, (len(frames), *self.unseen.shape)).copy()
        out = self.hidden[frames]
        return out | self.unseen if self.unseen is not None else out

    def _keypoints_without(self, hide, nm: int) -> Observations:
        """Keypoints with those ``hide(frame, view, marker)`` says (vectorised over rows)
        weighted 0; a view left without any keypoint holds no rows, as one that never had
        any."""
        counts = np.diff(self.offsets).reshape(self.n_frames, self.n_views)
        wrong = (counts != 0) & (counts != nm)
        if wrong.any():
            raise KinematicsError(f"hidden marks are for {nm} markers, the keypoints for "
                                  f"{counts[wrong][0]}", field="hidden")
        cell = np.repeat(np.arange(counts.size), counts.ravel())
        marker = np.arange(len(cell)) - self.offsets[cell]
        conf = np.where(hide(cell // self.n_views, cell % self.n_views, marker), 0.0,
                        self.conf)
        alive = np.zeros(counts.size, bool)
        np.logical_or.at(alive, cell, conf > 0)
        keep = alive[cell]
        if keep.all():
            return replace(self, conf=conf)
        off = np.zeros(counts.size + 1, np.int64)
        np.cumsum(np.where(alive, counts.ravel(), 0), out=off[1:])
        return replace(self, points=np.ascontiguousarray(self.points[keep]),
                       conf=np.ascontiguousarray(conf[keep]), offsets=off)

    @classmethod
    def keypoints(cls, keypoints, view_names: Sequence[str], marker_names: Sequence[str],
                  body_markers: Sequence[str]) -> Observations:
        """Labelled 2D keypoints.

        Parameters
        ----------
        keypoints : array_like, shape (n_frames, n_views, n_kp, 2 or 3)
            x, y in pixels and optionally a confidence in [0, 1] (default 1); NaN = missing.
        view_names : the views, in the cameras' order
        marker_names : (n_kp,) the body marker each keypoint is; markers of the body without
            a keypoint are missing in every frame
        body_markers : the body's marker names, in order
        """
        kp = np.asarray(keypoints, dtype=float)
        nv, nm = len(view_names), len(body_markers)
        if kp.ndim != 4 or kp.shape[1] != nv or kp.shape[2] != len(marker_names) or \
                kp.shape[3] not in (2, 3):
            raise KinematicsError(f"keypoints need shape (frames, {nv} views, "
                                  f"{len(marker_names)} keypoints, 2 or 3), got {kp.shape}",
                                  field="keypoints")
        index = _marker_index(marker_names, body_markers)
        n = kp.shape[0]
        full = np.full((n, nv, nm, 3), np.nan)
        full[..., 2] = 0.0
        full[:, :, index, :2] = kp[..., :2]
        full[:, :, index, 2] = kp[..., 2] if kp.shape[3] == 3 else 1.0
        conf = full[..., 2]
        if np.any(conf[np.isfinite(conf)] < 0):
            raise KinematicsError("confidences must be >= 0", field="keypoints")
        ok = np.isfinite(full[..., :2]).all(axis=3) & (np.nan_to_num(conf) > 0)
        present = ok.any(axis=2)  # (n, nv): a view with no keypoint holds no rows
        counts = np.where(present, nm, 0).ravel()
        off = np.zeros(counts.size + 1, np.int64)
        np.cumsum(counts, out=off[1:])
        rows = full[present]  # (k, nm, 3)
        conf_rows = np.where(ok[present], np.nan_to_num(rows[..., 2]), 0.0).ravel()
        return cls("keypoints", tuple(view_names), n,
                   np.ascontiguousarray(rows[..., :2].reshape(-1, 2)),
                   np.ascontiguousarray(conf_rows), off, np.zeros((n, 0, 4)),
                   np.zeros(n, np.int64))

    @classmethod
    def points_3d(cls, points, marker_names: Sequence[str], body_markers: Sequence[str]
                  ) -> Observations:
        """Labelled 3D points, shape (n_frames, n_points, 3 or 4): x, y, z in the body's
        length units and optionally a weight (default 1); NaN = missing."""
        p = np.asarray(points, dtype=float)
        if p.ndim != 3 or p.shape[1] != len(marker_names) or p.shape[2] not in (3, 4):
            raise KinematicsError(f"3D points need shape (frames, {len(marker_names)} points, "
                                  f"3 or 4), got {p.shape}", field="points3d")
        index = _marker_index(marker_names, body_markers)
        n = p.shape[0]
        full = np.full((n, len(body_markers), 4), np.nan)
        full[:, index, :3] = p[..., :3]
        full[:, index, 3] = p[..., 3] if p.shape[2] == 4 else 1.0
        w = full[..., 3]
        if np.any(w[np.isfinite(w)] < 0):
            raise KinematicsError("weights must be >= 0", field="points3d")
        missing = ~np.isfinite(full[..., :3]).all(axis=2) | ~np.isfinite(w)
        full[missing, 3] = 0.0
        return cls("points3d", (), n, np.empty((0, 2)), np.empty(0),
                   np.zeros(1, np.int64), np.ascontiguousarray(full),
                   np.zeros(n, np.int64))

    # -- access -------------------------------------------------------------------------
    def select(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                  np.ndarray]:
        """``points, conf, offsets, points3d`` of the given frames only, in that order."""
        frames = np.asarray(frames, dtype=np.int64)
        nv = self.n_views
        p3 = np.ascontiguousarray(self.points3d[frames])
        marks = self.marks(frames)
        if marks is not None:  # the kernels' hidden marks (n, n_markers, n_views)
            p3 = np.ascontiguousarray(marks.transpose(0, 2, 1), dtype=float)
        if nv == 0:
            return self.points, self.conf, np.zeros(1, np.int64), p3
        starts = self.offsets[frames * nv]
        stops = self.offsets[frames * nv + nv]
        rows = (np.concatenate([np.arange(a, b) for a, b in zip(starts, stops, strict=True)])
                if len(frames) else np.empty(0, np.int64)).astype(np.int64)
        counts = np.diff(self.offsets)[(frames[:, None] * nv + np.arange(nv)).ravel()]
        off = np.zeros(counts.size + 1, np.int64)
        np.cumsum(counts, out=off[1:])
        return (np.ascontiguousarray(self.points[rows].reshape(-1, 2)),
                np.ascontiguousarray(self.conf[rows]), off, p3)

    def take(self, frames) -> Observations:
        """The observations of these frames only, in this order."""
        frames = np.asarray(frames, dtype=np.int64)
        points, conf, offsets, _ = self.select(frames)
        hidden = None if self.hidden is None else self.hidden[frames]
        return Observations(self.kind, self.view_names, len(frames), points, conf, offsets,
                            np.ascontiguousarray(self.points3d[frames]), self.dropped[frames],
                            hidden, self.unseen)

    def arrays(self, frames: np.ndarray) -> ObservationArrays:
        """:meth:`select` as the kernels' namedtuple."""
        return ObservationArrays(int(self.objective), *self.select(frames))

    def view_counts(self, frames: np.ndarray) -> np.ndarray:
        """(len(frames), n_views) rows per view."""
        nv = self.n_views
        if nv == 0:
            return np.zeros((len(frames), 0), np.int64)
        return np.diff(self.offsets).reshape(self.n_frames, nv)[np.asarray(frames)]

    def frame_views(self, frame: int) -> list[np.ndarray]:
        """The 2D rows of each view of one frame (for keypoints, NaN rows included)."""
        nv = self.n_views
        return [self.points[self.offsets[frame * nv + v]: self.offsets[frame * nv + v + 1]]
                for v in range(nv)]


def sorted_by_x(pts: np.ndarray, off: np.ndarray) -> np.ndarray:
    """The points of each (frame, view) cell sorted by x (stable): the kernels search a view
    with many detections by a sweep along x (``_kernels.error2d.nearest_sorted``). Which
    detection is which does not matter to an unlabelled fit."""
    cell = np.repeat(np.arange(len(off) - 1), np.diff(off))
    return np.ascontiguousarray(pts[np.lexsort((pts[:, 0], cell))])


def _marker_index(names: Sequence[str], body_markers: Sequence[str]) -> np.ndarray:
    where = {m: k for k, m in enumerate(body_markers)}
    unknown = [n for n in names if n not in where]
    if unknown:
        raise KinematicsError(f"'{unknown[0]}' is not a marker of the body "
                              f"(markers: {', '.join(body_markers)})", field="marker_names")
    if len(set(names)) != len(names):
        raise KinematicsError("a marker is named twice", field="marker_names")
    return np.array([where[n] for n in names], np.int64)
