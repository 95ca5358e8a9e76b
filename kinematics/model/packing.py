"""Pack a :class:`~kinematics.model.Body` once into flat arrays for the numba kernels.

Joint ``j``'s frame (rotation ``A_j``, origin ``p_j``) follows Eq. 1 with the constant parts
folded in::

    root:   A_j = R(angles_j) · R^d_j              p_j = root_pos[chain_j] + A_j · T_j
    other:  A_j = A_parent · R^s · R(angles_j) · R^d_j
            p_j = p_parent + A_parent · t^s + A_j · T_j

where ``R^s, t^s`` belong to the parent segment (``t^s = (length, 0, 0)``). A marker on a
segment of joint ``j`` sits at ``p_j + A_j · (t^s + R^s · m)`` (Eq. 2).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from kinematics.model import Body
from kinematics.model.rotations import euler_yxz_deg


class BodyArrays(NamedTuple):
    """Flat, contiguous arrays describing a body (see the module docstring).

    Shapes: ``nj`` joints, ``ns`` segments, ``nm`` markers, ``nc`` chains.
    """

    parent: np.ndarray  # (nj,) int64, -1 for chain roots
    chain: np.ndarray  # (nj,) int64, chain index of each joint
    pre_rot: np.ndarray  # (nj, 3, 3) R^s of the parent segment (identity for roots)
    pre_trans: np.ndarray  # (nj, 3) t^s of the parent segment (zero for roots)
    post_rot: np.ndarray  # (nj, 3, 3) R^d
    post_trans: np.ndarray  # (nj, 3) T
    axis_index: np.ndarray  # (nj, 3) int64, posture-vector index of the y, x, z angles
    segment_joint: np.ndarray  # (ns,) int64, owning joint
    segment_end: np.ndarray  # (ns, 3) t^s in the owning joint's frame
    marker_joint: np.ndarray  # (nm,) int64, owning joint
    marker_local: np.ndarray  # (nm, 3) t^s + R^s m in the owning joint's frame
    n_chains: int


def pack_body(body: Body) -> BodyArrays:
    """Pack ``body`` into :class:`BodyArrays` (done once per fit, not per iteration)."""
    joints = list(body.joints())
    index = {id(j): k for k, (_, j, _, _) in enumerate(joints)}
    chain_index = {c.name: k for k, c in enumerate(body.chains)}
    nj = len(joints)
    parent = np.full(nj, -1, dtype=np.int64)
    chain = np.zeros(nj, dtype=np.int64)
    pre_rot = np.tile(np.eye(3), (nj, 1, 1))
    pre_trans = np.zeros((nj, 3))
    post_rot = np.empty((nj, 3, 3))
    post_trans = np.empty((nj, 3))
    axis_index = np.arange(3 * nj, dtype=np.int64).reshape(nj, 3)
    seg_joint, seg_end, mk_joint, mk_local = [], [], [], []
    for k, (c, joint, par, seg) in enumerate(joints):
        chain[k] = chain_index[c.name]
        if par is not None:
            parent[k] = index[id(par)]
            pre_rot[k] = euler_yxz_deg(seg.rotation_deg)
            pre_trans[k] = (seg.length, 0.0, 0.0)
        post_rot[k] = euler_yxz_deg(joint.orientation_deg)
        post_trans[k] = joint.translation
        for s in joint.segments:
            t = np.array([s.length, 0.0, 0.0])
            rs = euler_yxz_deg(s.rotation_deg)
            seg_joint.append(k)
            seg_end.append(t)
            for m in s.markers:
                mk_joint.append(k)
                mk_local.append(t + rs @ np.asarray(m.offset, dtype=float))
    return BodyArrays(
        parent=parent,
        chain=chain,
        pre_rot=np.ascontiguousarray(pre_rot),
        pre_trans=pre_trans,
        post_rot=np.ascontiguousarray(post_rot),
        post_trans=post_trans,
        axis_index=axis_index,
        segment_joint=np.array(seg_joint, dtype=np.int64),
        segment_end=np.array(seg_end, dtype=float).reshape(-1, 3),
        marker_joint=np.array(mk_joint, dtype=np.int64),
        marker_local=np.array(mk_local, dtype=float).reshape(-1, 3),
        n_chains=len(body.chains),
    )
