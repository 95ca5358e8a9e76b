"""Root placement for a fit: root markers tracked, free roots placed from the detections
or from labelled 3D points (the maths is :mod:`kinematics.fit.placement`).
"""

from __future__ import annotations

import numpy as np

from kinematics._kernels import root_track as _root_track
from kinematics.fit import placement
from kinematics.model.fk import forward_kinematics_reference
from kinematics.observe.observations import Observations


class RootsMixin:
    """The :class:`~kinematics.fit.Fitter`'s root placement."""

    def track_roots(self, detections, frames=None) -> np.ndarray:
        """Root position of every chain for each frame, shape (n_frames, n_chains, 3).

        Chains with ``root.mode == "marker"`` follow their root marker (Sects. 2.1, 3.3.1):
        frame by frame, in the order of ``frames``, the marker's previous position is
        projected into every view, the nearest detection there is taken as its image (within
        ``params.root_gate_px`` if set, a gate that doubles for every frame the marker is
        lost), and the new 3D position is the least-squares point over the observing views
        (orthographic or pinhole), keeping unobserved directions. The first frame starts
        from the configured root position (the manual offset of the paper) with the root
        marker where the start posture puts it; the root then moves by the tracked marker's
        displacement. Free roots get their per-frame seed position
        (:mod:`kinematics.fit.placement`); fixed chains keep their position.
        """
        obs = self.observations(detections)
        idx = self._frame_indices(frames, obs.n_frames)
        return self._place(obs, idx)[0]

    def _place(self, obs: Observations, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Seed root positions (n, n_chains, 3) and rotations (n, n_chains, 3, 3)."""
        out = np.broadcast_to(self._roots, (len(idx), *self._roots.shape)).copy()
        rot = self.problem.identity_rotations(len(idx))
        if len(idx) == 0 or not (self._tracked or self.problem.free_chains):
            return out, rot
        pts, _, off, _ = obs.select(idx)
        labelled = self._labelled_3d(obs, idx) if obs.labelled else None
        gate = np.inf if self.params.root_gate_px is None else float(self.params.root_gate_px)
        if self._tracked:
            markers0 = forward_kinematics_reference(self.body, self._mean_deg).markers
        for k in self._tracked:
            x0 = np.ascontiguousarray(markers0[self._root_marker[k]], dtype=float)
            if labelled is None:
                track = np.empty((len(idx), 3))
                p_k, off_k = pts, off
                marks = self._marks(obs, idx)
                if marks is not None:  # a view where the root marker is hidden: none
                    p_k, off_k = _emptied(pts, off, marks[:, :, self._root_marker[k]])
                _root_track.track_root(p_k, off_k, x0, gate, 1e-9, self.problem.cams, track)
            else:  # a labelled root marker needs no tracking; gaps keep the last position
                track = _carry_forward(labelled[:, self._root_marker[k]], x0)
            out[:, k] = self._roots[k] + (track - x0)
        if self.problem.free_chains:
            if labelled is None:
                nv = self.n_views
                frames = ([pts[off[f * nv + v]: off[f * nv + v + 1]] for v in range(nv)]
                          for f in range(len(idx)))
                tri_gate = placement.DEFAULT_GATE_PX if self.params.root_gate_px is None\
                    else gate
                pos, seed_rot, _ = placement.place_roots(
                    self.body, self.cameras, frames, self.problem.windows, tri_gate,
                    resolve=lambda f, q, poses: self._resolve(obs, idx[f], q, poses))
            else:
                pos, seed_rot, _ = placement.place_roots_from_points(
                    self.body, labelled, self.problem.windows)
            for q, c in enumerate(self.problem.free_chains):
                out[:, c] = pos[:, q]
                rot[:, c] = seed_rot[:, q]
        return out, rot

    def _resolve(self, obs: Observations, frame: int, q: int, poses: list) -> int:
        """Which of several equally good seed poses of free root ``q`` to take in ``frame``:
        the whole body is fitted from each, the lowest E wins (a mirror-symmetric root
        constellation cannot tell left from right; the limbs can)."""
        c = self.problem.free_chains[q]
        one = np.array([frame], np.int64)
        errors = []
        for r, t, *_ in poses:
            roots = self._roots[None].copy()
            rots = self.problem.identity_rotations(1)
            roots[0, c], rots[0, c] = t, r
            res = self._fit_block(obs, one, one, roots, rots, self.problem.start,
                                  np.array([0, 1], np.int64))[0]
            errors.append(res.error)
        return int(np.argmin(errors))

    def _labelled_3d(self, obs: Observations, idx: np.ndarray) -> np.ndarray:
        """3D positions of the labelled markers, (n, n_markers, 3), NaN where unknown:
        the 3D points themselves, or keypoints triangulated over their views."""
        if obs.kind == "points3d":
            p = obs.points3d[idx, :, :3].copy()
            p[obs.points3d[idx, :, 3] <= 0] = np.nan
            return p
        nm = len(self.body.marker_names)
        out = np.empty((len(idx), nm, 3))
        nv = obs.n_views
        for k, f in enumerate(idx):
            rows = [slice(obs.offsets[f * nv + v], obs.offsets[f * nv + v + 1])
                    for v in range(nv)]
            out[k] = placement.triangulate_labelled(
                self.cameras, [obs.points[r] for r in rows], [obs.conf[r] for r in rows], nm)
        return out

def _emptied(points: np.ndarray, offsets: np.ndarray, cells: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Ragged points (frame-major offsets) with the (frame, view) ``cells`` flagged True
    emptied."""
    counts = np.diff(offsets)
    keep = np.repeat(~np.asarray(cells, bool).ravel(), counts)
    new_off = np.zeros_like(offsets)
    np.cumsum(np.where(cells.ravel(), 0, counts), out=new_off[1:])
    return np.ascontiguousarray(points[keep]), new_off

def _carry_forward(points: np.ndarray, first: np.ndarray) -> np.ndarray:
    """(n, 3) points with each NaN row replaced by the last finite one (``first`` before
    any)."""
    out = np.array(points, dtype=float, copy=True)
    last = np.asarray(first, dtype=float)
    for k in range(len(out)):
        if np.isfinite(out[k]).all():
            last = out[k]
        else:
            out[k] = last
    return out
