"""numba kernels of forward kinematics (twin of
:func:`kinematics.model.fk.forward_kinematics_reference`).

Arrays follow :class:`kinematics.model.packing.BodyArrays`; angles are radians. No allocation in
:func:`joint_frames` and :func:`marker_positions`, so the annealing loop can call them.
"""

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def euler_yxz_into(ay, ax, az, out):
    """out = Ry(ay) · Rx(ax) · Rz(az) (Eq. 1)."""
    ca, sa = np.cos(ay), np.sin(ay)
    cb, sb = np.cos(ax), np.sin(ax)
    cc, sc = np.cos(az), np.sin(az)
    out[0, 0] = ca * cc + sa * sb * sc
    out[0, 1] = -ca * sc + sa * sb * cc
    out[0, 2] = sa * cb
    out[1, 0] = cb * sc
    out[1, 1] = cb * cc
    out[1, 2] = -sb
    out[2, 0] = -sa * cc + ca * sb * sc
    out[2, 1] = sa * sc + ca * sb * cc
    out[2, 2] = ca * cb


@njit(cache=True, nogil=True, inline="always")
def matmul3_into(a, b, out):
    for i in range(3):
        for k in range(3):
            out[i, k] = a[i, 0] * b[0, k] + a[i, 1] * b[1, k] + a[i, 2] * b[2, k]


@njit(cache=True, nogil=True)
def joint_frames(angles, root_pos, parent, chain, pre_rot, pre_trans, post_rot, post_trans,
                 axis_index, rot_out, pos_out, tmp_a, tmp_b):
    """Fill rot_out (nj, 3, 3) and pos_out (nj, 3) with every joint frame (Eq. 1).

    tmp_a, tmp_b are (3, 3) scratch matrices supplied by the caller.
    """
    for j in range(parent.shape[0]):
        euler_yxz_into(angles[axis_index[j, 0]], angles[axis_index[j, 1]],
                       angles[axis_index[j, 2]], tmp_a)
        p = parent[j]
        if p < 0:
            matmul3_into(tmp_a, post_rot[j], rot_out[j])
            for i in range(3):
                pos_out[j, i] = root_pos[chain[j], i]
        else:
            matmul3_into(rot_out[p], pre_rot[j], tmp_b)
            for i in range(3):
                pos_out[j, i] = pos_out[p, i] + (rot_out[p, i, 0] * pre_trans[j, 0]
                                                 + rot_out[p, i, 1] * pre_trans[j, 1]
                                                 + rot_out[p, i, 2] * pre_trans[j, 2])
            _mul3(tmp_b, tmp_a, post_rot[j], rot_out[j])
        t0, t1, t2 = post_trans[j, 0], post_trans[j, 1], post_trans[j, 2]
        for i in range(3):
            pos_out[j, i] += rot_out[j, i, 0] * t0 + rot_out[j, i, 1] * t1 + rot_out[j, i, 2] * t2


@njit(cache=True, nogil=True, inline="always")
def _mul3(a, b, c, out):
    """out = a · b · c for 3×3 matrices, without scratch storage."""
    for i in range(3):
        r0 = a[i, 0] * b[0, 0] + a[i, 1] * b[1, 0] + a[i, 2] * b[2, 0]
        r1 = a[i, 0] * b[0, 1] + a[i, 1] * b[1, 1] + a[i, 2] * b[2, 1]
        r2 = a[i, 0] * b[0, 2] + a[i, 1] * b[1, 2] + a[i, 2] * b[2, 2]
        for k in range(3):
            out[i, k] = r0 * c[0, k] + r1 * c[1, k] + r2 * c[2, k]


@njit(cache=True, nogil=True)
def local_points(rot, pos, owner, local, out):
    """out[k] = pos[owner[k]] + rot[owner[k]] · local[k] (markers, segment ends)."""
    for k in range(owner.shape[0]):
        j = owner[k]
        for i in range(3):
            out[k, i] = pos[j, i] + (rot[j, i, 0] * local[k, 0] + rot[j, i, 1] * local[k, 1]
                                     + rot[j, i, 2] * local[k, 2])


@njit(cache=True, nogil=True)
def fk_batch(angles, root_pos, parent, chain, pre_rot, pre_trans, post_rot, post_trans,
             axis_index, segment_joint, segment_end, marker_joint, marker_local,
             joints_out, segments_out, markers_out):
    """Forward kinematics for many postures: angles (n, n_axes), root_pos (n, nc, 3)."""
    nj = parent.shape[0]
    rot = np.empty((nj, 3, 3))
    tmp_a = np.empty((3, 3))
    tmp_b = np.empty((3, 3))
    for n in range(angles.shape[0]):
        joint_frames(angles[n], root_pos[n], parent, chain, pre_rot, pre_trans, post_rot,
                     post_trans, axis_index, rot, joints_out[n], tmp_a, tmp_b)
        local_points(rot, joints_out[n], segment_joint, segment_end, segments_out[n])
        local_points(rot, joints_out[n], marker_joint, marker_local, markers_out[n])
