"""Forward kinematics (paper Eq. 1 and 2).

:func:`forward_kinematics_reference` multiplies 4×4 homogeneous matrices literally as the
paper writes them; it is the specification and the test oracle. :func:`forward_kinematics`
runs the numba kernel of :mod:`kinematics._kernels.fk` on a packed body and is vectorised
over postures. Both return positions in root (world) coordinates, in the body's units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinematics._kernels import fk as kern
from kinematics.errors import KinematicsError
from kinematics.model import Body
from kinematics.model.packing import BodyArrays, pack_body
from kinematics.model.rotations import euler_yxz_deg


@dataclass(frozen=True)
class Pose:
    """Positions of one or many postures.

    joints : ndarray, shape (..., n_joints, 3)
        Joint centres (frame origins), in :meth:`Body.joints` order.
    segment_ends : ndarray, shape (..., n_segments, 3)
        Distal ends of the segments (end effectors included), in :meth:`Body.segments` order.
    markers : ndarray, shape (..., n_markers, 3)
        Model markers, in :meth:`Body.markers` order.
    """

    joints: np.ndarray
    segment_ends: np.ndarray
    markers: np.ndarray


def _homogeneous(rot: np.ndarray | None = None, trans=None) -> np.ndarray:
    m = np.eye(4)
    if rot is not None:
        m[:3, :3] = rot
    if trans is not None:
        m[:3, 3] = trans
    return m


def forward_kinematics_reference(
    body: Body, angles_deg, root_positions=None
) -> Pose:
    """Readable Eq. 1/2 for one posture: ``J0 = R0·R0d``, ``Jn+1 = Jn·Sn·Rn+1·Rdn+1·Tn+1``,
    ``S = Ts·Rs``, ``M = J·S·m``; the chain root is then placed at its root position.

    Parameters
    ----------
    angles_deg : array_like, shape (n_axes,)
        Posture vector in :meth:`Body.axis_refs` order, degrees.
    root_positions : array_like, shape (n_chains, 3), optional
        Root positions; defaults to each chain's configured position.
    """
    angles = np.asarray(angles_deg, dtype=float)
    if angles.shape != (body.n_axes,):
        raise KinematicsError(f"posture needs {body.n_axes} angles, got shape {angles.shape}")
    roots = body.root_positions() if root_positions is None else np.asarray(root_positions)
    chain_index = {c.name: k for k, c in enumerate(body.chains)}
    frames: dict[int, np.ndarray] = {}
    joints, ends, markers = [], [], []
    for k, (chain, joint, parent, seg) in enumerate(body.joints()):
        r = _homogeneous(euler_yxz_deg(angles[3 * k: 3 * k + 3]))
        rd = _homogeneous(euler_yxz_deg(joint.orientation_deg))
        t = _homogeneous(trans=joint.translation)
        if parent is None:
            base = _homogeneous(trans=roots[chain_index[chain.name]])
        else:
            base = frames[id(parent)] @ _segment_matrix(seg)
        frame = base @ r @ rd @ t
        frames[id(joint)] = frame
        joints.append(frame[:3, 3])
        for s in joint.segments:
            sm = frame @ _segment_matrix(s)
            ends.append(sm[:3, 3])
            markers.extend((sm @ np.append(m.offset, 1.0))[:3] for m in s.markers)
    return Pose(
        np.array(joints).reshape(-1, 3),
        np.array(ends).reshape(-1, 3),
        np.array(markers).reshape(-1, 3),
    )


def _segment_matrix(seg) -> np.ndarray:
    """S = T^s · R^s: translate by the length along x, then rotate by R^s."""
    return _homogeneous(trans=(seg.length, 0.0, 0.0)) @ _homogeneous(
        euler_yxz_deg(seg.rotation_deg)
    )


def forward_kinematics(
    body: Body | BodyArrays, angles_deg, root_positions=None
) -> Pose:
    """Forward kinematics with the numba kernel, for one posture or many.

    Parameters
    ----------
    body : Body or BodyArrays
        Pack once with :func:`~kinematics.model.packing.pack_body` when calling repeatedly.
    angles_deg : array_like, shape (n_axes,) or (n_postures, n_axes)
    root_positions : array_like, shape (n_chains, 3) or (n_postures, n_chains, 3), optional
        Defaults to the chains' configured positions (required when passing BodyArrays).
    """
    if isinstance(body, Body):
        arrays = pack_body(body)
        if root_positions is None:
            root_positions = body.root_positions()
    else:
        arrays = body
        if root_positions is None:
            raise KinematicsError("root_positions are required with packed arrays")
    angles = np.asarray(angles_deg, dtype=float)
    single = angles.ndim == 1
    angles = np.atleast_2d(angles)
    n, n_axes = angles.shape
    if n_axes != arrays.axis_index.size:
        raise KinematicsError(f"posture needs {arrays.axis_index.size} angles, got {n_axes}")
    roots = np.asarray(root_positions, dtype=float)
    roots = np.ascontiguousarray(np.broadcast_to(roots, (n, arrays.n_chains, 3)))
    nj, ns, nm = arrays.parent.size, arrays.segment_joint.size, arrays.marker_joint.size
    joints = np.empty((n, nj, 3))
    ends = np.empty((n, ns, 3))
    markers = np.empty((n, nm, 3))
    kern.fk_batch(np.ascontiguousarray(np.deg2rad(angles)), roots, arrays.parent, arrays.chain,
                  arrays.pre_rot, arrays.pre_trans, arrays.post_rot, arrays.post_trans,
                  arrays.axis_index, arrays.segment_joint, arrays.segment_end,
                  arrays.marker_joint, arrays.marker_local, joints, ends, markers)
    if single:
        return Pose(joints[0], ends[0], markers[0])
    return Pose(joints, ends, markers)
