"""The one place that defines the rotation convention (paper Eq. 1).

A joint's rotation is ``R = Ry(ay) · Rx(ax) · Rz(az)``: active, right-handed rotations
about the axes of the frame the joint hangs from. Angles here are radians; files and
user-facing APIs use degrees and convert at their edge.

World convention used by the shipped chains and cameras: x points anterior, y dorsal (up),
z to the animal's right. Segments extend along their joint's local +x axis.
"""

from __future__ import annotations

import numpy as np

#: Order in which a joint's three axes are stored and multiplied (Eq. 1).
AXIS_ORDER = ("y", "x", "z")


def rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def euler_yxz(ay: float, ax: float, az: float) -> np.ndarray:
    """Rotation matrix ``Ry(ay) @ Rx(ax) @ Rz(az)`` (Eq. 1), angles in radians."""
    return rot_y(ay) @ rot_x(ax) @ rot_z(az)


def euler_yxz_deg(angles_deg) -> np.ndarray:
    """:func:`euler_yxz` for a (y, x, z) triple in degrees."""
    ay, ax, az = np.deg2rad(np.asarray(angles_deg, dtype=float))
    return euler_yxz(ay, ax, az)
