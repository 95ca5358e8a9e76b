"""The records kernels build and pass among themselves: one frame's observations
(:class:`FrameObs`) and one run's scratch (:class:`Scratch`). The records Python builds
once per block are defined beside their builders (``FoldedBody``, ``DofArrays``,
``Schedule``, ``ErrorArgs``, ``FitOutputs`` in :mod:`kinematics.fit.problem`,
``CameraArrays`` in :mod:`kinematics.cameras.models`, ``Partitions``,
``ObservationArrays``). A kernel reads a record's fields by name; the loops it calls once
per iteration take plain arrays (unpacked once, before the loop)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


class FrameObs(NamedTuple):
    """One frame's observations: the block's ``points`` and ``conf``, the frame's
    ``view_off`` (n_views + 1,) into them, and its ``obs3``: labelled 3D points
    (n_markers, 4), a cloud (k, 4), or hidden marks of unlabelled points (empty for none)."""

    objective: int
    points: np.ndarray
    conf: np.ndarray
    view_off: np.ndarray
    obs3: np.ndarray


class Scratch(NamedTuple):
    """One run's scratch: the state's current, candidate and best values and their cosines
    and sines (n_state,); the joint frames ``rot`` (nj, 3, 3), ``pos`` (nj, 3), the 3D
    markers ``mk`` (nm, 3), their projections ``proj`` (n_views, nm, 2), ``per_view``
    (n_views,) and ``nearest`` (nm,) int64."""

    cur: np.ndarray
    cand: np.ndarray
    best: np.ndarray
    cs: np.ndarray
    sn: np.ndarray
    rot: np.ndarray
    pos: np.ndarray
    mk: np.ndarray
    proj: np.ndarray
    per_view: np.ndarray
    nearest: np.ndarray


@njit(cache=True, nogil=True)
def new_scratch(na, nj, nm, nv):
    """A :class:`Scratch` for ``na`` state entries, ``nj`` joints, ``nm`` markers and ``nv``
    views (uninitialised)."""
    return Scratch(np.empty(na), np.empty(na), np.empty(na), np.empty(na), np.empty(na),
                   np.empty((nj, 3, 3)), np.empty((nj, 3)), np.empty((nm, 3)),
                   np.empty((nv, nm, 2)), np.empty(nv), np.empty(nm, np.int64))


@njit(cache=True, nogil=True, inline="always")
def frame_obs(obs, f, nv):
    """Frame ``f``'s :class:`FrameObs` of a block's ``ObservationArrays`` ``obs`` over
    ``nv`` views (views of its arrays, no copy)."""
    return FrameObs(obs.objective, obs.points, obs.conf, obs.offsets[f * nv: f * nv + nv + 1],
                    obs.points3d[f])
