"""Camera models: orthographic views (paper Eq. 3, generalised) and OpenCV pinhole cameras.

Both models map world points (x, y, z), in the chain's units, to pixel coordinates (u, v)
with the origin at the centre of the top-left pixel, u to the right and v down (OpenCV's
convention). The NumPy ``project`` methods here are the readable specification; the fitter
packs cameras once with :func:`pack_cameras` and projects with the numba kernels in
:mod:`kinematics._kernels.camera`, which the tests compare against these methods.

Cameras are immutable: their arrays are read-only and attributes cannot be reassigned.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple, TypeAlias

import cv2
import numpy as np

from kinematics._kernels.camera import ORTHOGRAPHIC, PINHOLE, project_points_kernel
from kinematics.errors import KinematicsError

__all__ = [
    "AxesForm",
    "Camera",
    "CameraArrays",
    "OrthographicCamera",
    "PinholeCamera",
    "describe_camera",
    "pack_cameras",
    "project_packed",
]

#: Distortion coefficient counts OpenCV's pinhole model accepts and we support:
#: none, (k1, k2, p1, p2), + k3, + (k4, k5, k6) (rational model). Stored padded to 8.
DIST_COUNTS = (0, 4, 5, 8)

#: Largest entry of |R Rᵀ - I| accepted as orthonormal (files carry rounded matrices).
ORTHONORMAL_TOL = 1e-6

_WORLD_AXES = {"x": 0, "y": 1, "z": 2}


# --- validation helpers (shared with camera_io) ---------------------------------------------


def _is_number_tree(value) -> bool:
    """True for a number or nested lists of numbers; bools and strings are not numbers."""
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "iuf"
    if isinstance(value, list | tuple):
        return all(_is_number_tree(v) for v in value)
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    )


#: The largest number a camera may hold (focal lengths in pixels, positions in µm: 1e7).
MAX_NUMBER = 1e12


def _as_float_array(value, shape: tuple[int, ...] | None, field: str, *, ravel=False):
    """Validate ``value`` as a finite float64 array of ``shape``; return it read-only.

    ``ravel`` flattens first (OpenCV hands out vectors as (1, n) or (n, 1)); ``shape``
    None accepts any shape.
    """
    if not _is_number_tree(value):
        raise KinematicsError(f"expected numbers, got {value!r}", field=field)
    try:
        arr = np.array(value, dtype=np.float64)
    except ValueError:  # ragged nested lists
        raise KinematicsError(f"expected a regular array of numbers, got {value!r}",
                              field=field) from None
    if ravel:
        arr = arr.ravel()
    if shape is not None and arr.shape != shape:
        want = "a number" if shape == () else f"shape {shape}"
        raise KinematicsError(f"expected {want}, got shape {arr.shape}", field=field)
    if not np.all(np.isfinite(arr)):
        raise KinematicsError("must be finite (no NaN or inf)", field=field)
    if arr.size and np.abs(arr).max() > MAX_NUMBER:  # a typo: a projection would overflow
        raise KinematicsError(f"{np.abs(arr).max():g} is out of range (at most "
                              f"{MAX_NUMBER:g} in size)", field=field)
    arr.setflags(write=False)
    return arr


def _as_name(name) -> str:
    if not isinstance(name, str) or not name.strip() or not name.isprintable():
        raise KinematicsError(f"camera name must be a non-empty printable string, got {name!r}",
                              field="name")
    return name


def _as_size(size, field: str = "size") -> tuple[int, int] | None:
    """Image size (width, height) in pixels, or None; integral floats are accepted."""
    if size is None:
        return None
    arr = _as_float_array(size, (2,), field, ravel=True)
    if np.any(arr != np.round(arr)) or np.any(arr < 1):
        raise KinematicsError(f"expected two positive integers (width, height), got {size!r}",
                              field=field)
    return int(arr[0]), int(arr[1])


def _as_points(points) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 0 or pts.shape[-1] != 3:
        raise KinematicsError(f"points must have shape (..., 3), got {pts.shape}", field="points")
    return pts


def _view_direction(rows: np.ndarray) -> np.ndarray:
    """Unit vector u × v for the world directions of image u and v: where the camera looks."""
    w = np.cross(rows[0], rows[1])
    return w / np.linalg.norm(w)


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is not None and b is not None and np.array_equal(a, b)
    return a == b


class _Camera:
    """Shared behaviour: validated projection, immutability, exact equality."""

    kind: int
    name: str
    image_size: tuple[int, int] | None

    def project(self, points) -> np.ndarray:
        """Project world points to pixels.

        Parameters
        ----------
        points : array_like, shape (..., 3)
            World points in the chain's units.

        Returns
        -------
        ndarray, shape (..., 2)
            Pixel coordinates (u, v); NaN where a point is NaN or (pinhole) not in front
            of the camera.
        """
        return self._project(_as_points(points))

    def _project(self, pts: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _state(self) -> tuple:
        raise NotImplementedError

    def _set(self, **attrs) -> None:
        for key, value in attrs.items():
            object.__setattr__(self, key, value)

    def __setattr__(self, key, value):
        raise AttributeError(f"{type(self).__name__} is immutable; build a new camera")

    def __eq__(self, other):
        if type(self) is not type(other):
            return NotImplemented
        return all(_same(a, b) for a, b in zip(self._state(), other._state(), strict=True))

    __hash__ = None

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {describe_camera(self)}>"


# --- orthographic ---------------------------------------------------------------------------


class AxesForm(NamedTuple):
    """The scale/axes/offset description of an orthographic view (Eq. 3 generalised)."""

    scale: float
    axes: tuple[str, str]
    offset: tuple[float, float]


def _parse_axis(axis, field: str) -> tuple[int, float]:
    """'x', '+y', '-z' -> (world axis index, sign)."""
    if isinstance(axis, str) and axis.lstrip("+-") in _WORLD_AXES and len(axis) <= 2:
        return _WORLD_AXES[axis[-1]], -1.0 if axis[0] == "-" else 1.0
    raise KinematicsError(f"expected a signed world axis like 'x' or '-y', got {axis!r}",
                          field=field)


class OrthographicCamera(_Camera):
    """Orthographic view: ``(u, v) = P @ (x, y, z, 1)``; the paper's Eq. 3 generalised.

    Parameters
    ----------
    name : str
        Camera name, unique within a camera file.
    P : array_like, shape (2, 4)
        Projection matrix from homogeneous world coordinates to pixels.
    size : (int, int), optional
        Image size (width, height) in pixels.

    Attributes
    ----------
    P : ndarray, shape (2, 4)
    image_size : (int, int) or None
    axes_form : AxesForm or None
        The scale/axes/offset the camera was built from with :meth:`from_axes`, kept so a
        camera file saves it in that form; None when built from a matrix.
    """

    kind = ORTHOGRAPHIC

    def __init__(self, name: str, P, *, size=None) -> None:
        P = _as_float_array(P, (2, 4), "P")
        if np.linalg.norm(np.cross(P[0, :3], P[1, :3])) == 0.0:
            raise KinematicsError("the rows of P[:, :3] are parallel or zero; the view is "
                                  "degenerate", field="P")
        self._set(name=_as_name(name), P=P, image_size=_as_size(size), axes_form=None)

    @classmethod
    def from_axes(cls, name: str, scale: float, axes, offset=(0.0, 0.0), *, size=None):
        """Build a view from a scale, a pair of signed world axes and a pixel offset.

        ``u = scale * sign_u * world[axis_u] + offset[0]`` and likewise for v. With the
        world convention (x anterior, y up, z right) a side view seen from the animal's
        right is ``axes=("x", "-y")`` (image v grows downward, world up is -v) and a top
        view is ``axes=("x", "z")``; Eq. 3 of the paper is ``axes=("x", "y")``, zero offset.

        Parameters
        ----------
        name : str
        scale : float
            Pixels per world unit, > 0; mirror views use a negated axis, not a negative scale.
        axes : (str, str)
            Signed world axis names for image u and image v, on different world axes.
        offset : (float, float)
            Pixel coordinates of the world origin.
        size : (int, int), optional
            Image size (width, height) in pixels.
        """
        s = float(_as_float_array(scale, (), "scale"))
        if s <= 0.0:
            raise KinematicsError(f"scale must be > 0, got {s!r}", field="scale")
        if not isinstance(axes, list | tuple) or len(axes) != 2:
            raise KinematicsError(f"expected two axis names, got {axes!r}", field="axes")
        (iu, su), (iv, sv) = (_parse_axis(a, "axes") for a in axes)
        if iu == iv:
            raise KinematicsError(f"image u and v need different world axes, got {axes!r}",
                                  field="axes")
        off = _as_float_array(offset, (2,), "offset")
        P = np.zeros((2, 4))
        P[0, iu], P[1, iv] = s * su, s * sv
        P[:, 3] = off
        cam = cls(name, P, size=size)
        form = AxesForm(s, (str(axes[0]), str(axes[1])), (float(off[0]), float(off[1])))
        cam._set(axes_form=form)
        return cam

    @property
    def view_direction(self) -> np.ndarray:
        """World direction the camera looks along, shape (3,), unit length."""
        return _view_direction(self.P[:, :3])

    def _project(self, pts):
        return pts @ self.P[:, :3].T + self.P[:, 3]

    def _state(self):
        return (self.name, self.P, self.image_size, self.axes_form)


# --- pinhole --------------------------------------------------------------------------------


def _as_K(K) -> np.ndarray:
    K = _as_float_array(K, (3, 3), "K")
    if not np.array_equal(K[2], [0.0, 0.0, 1.0]):
        raise KinematicsError(f"last row of K must be [0, 0, 1], got {K[2].tolist()}", field="K")
    if K[0, 1] != 0.0 or K[1, 0] != 0.0:
        # cv2.projectPoints ignores skew, so a camera with skew would not be OpenCV's model.
        raise KinematicsError("K must have zero skew (K[0][1] = K[1][0] = 0)", field="K")
    if K[0, 0] <= 0.0 or K[1, 1] <= 0.0:
        raise KinematicsError("focal lengths K[0][0] and K[1][1] must be > 0", field="K")
    return K


def _as_dist(dist) -> np.ndarray:
    d = _as_float_array(dist, None, "dist", ravel=True)
    if d.size not in DIST_COUNTS:
        raise KinematicsError(
            f"expected 0, 4, 5 or 8 distortion coefficients (k1, k2, p1, p2[, k3[, k4, k5, "
            f"k6]]), got {d.size}; thin-prism and tilted models are not supported",
            field="dist")
    padded = np.zeros(8)
    padded[: d.size] = d
    padded.setflags(write=False)
    return padded


def _as_rotation(R, rvec) -> tuple[np.ndarray, np.ndarray | None]:
    """Rotation matrix from R (3, 3) or a Rodrigues vector rvec (3,); identity if neither."""
    if R is not None and rvec is not None:
        raise KinematicsError("give R (3x3 matrix) or rvec (Rodrigues vector), not both",
                              field="rvec")
    if R is None and rvec is None:
        R = np.eye(3)
    if rvec is not None:
        rvec = _as_float_array(rvec, (3,), "rvec", ravel=True)
        R = cv2.Rodrigues(np.array(rvec))[0]  # the same conversion cv2.projectPoints uses
        R.setflags(write=False)
        return R, rvec
    R = _as_float_array(R, (3, 3), "R")
    err = np.max(np.abs(R @ R.T - np.eye(3)))
    if err > ORTHONORMAL_TOL:
        raise KinematicsError(f"R is not orthonormal (max |R Rᵀ - I| = {err:.3g})", field="R")
    if np.linalg.det(R) < 0.0:
        raise KinematicsError("R is a reflection (det < 0), not a rotation", field="R")
    return R, None


class PinholeCamera(_Camera):
    """OpenCV's pinhole camera with the rational distortion model.

    ``x_cam = R @ X + t``; ``(x, y) = x_cam[:2] / x_cam[2]``; distortion with
    ``(k1, k2, p1, p2, k3, k4, k5, k6)``; ``u = fx * x' + cx``, ``v = fy * y' + cy`` -
    exactly ``cv2.projectPoints``. Points with camera-frame ``z <= 0`` project to NaN.

    Parameters
    ----------
    name : str
    K : array_like, shape (3, 3)
        Intrinsic matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels.
    dist : array_like, shape (0,), (4,), (5,) or (8,)
        Distortion coefficients in OpenCV's order; stored padded with zeros to 8.
    R : array_like, shape (3, 3), optional
        World-to-camera rotation. Give R or ``rvec``, not both; default identity.
    t : array_like, shape (3,)
        World-to-camera translation, in the chain's units.
    size : (int, int), optional
        Image size (width, height) in pixels.
    rvec : array_like, shape (3,), optional
        World-to-camera rotation as an OpenCV Rodrigues vector (axis * angle in radians).

    Attributes
    ----------
    K, dist (8,), R, t, image_size
    rvec : ndarray, shape (3,), or None
        The Rodrigues vector the camera was built from, kept so a file saves it in that
        form; None when built from R.
    """

    kind = PINHOLE

    def __init__(self, name: str, K, dist=(), R=None, t=(0.0, 0.0, 0.0), size=None, *,
                 rvec=None) -> None:
        R, rvec = _as_rotation(R, rvec)
        self._set(name=_as_name(name), K=_as_K(K), dist=_as_dist(dist), R=R, rvec=rvec,
                  t=_as_float_array(t, (3,), "t", ravel=True), image_size=_as_size(size))

    @property
    def centre(self) -> np.ndarray:
        """Camera centre in world coordinates, ``-Rᵀ t``, shape (3,)."""
        return -self.R.T @ self.t

    @property
    def view_direction(self) -> np.ndarray:
        """World direction of the optical axis, shape (3,), unit length."""
        return _view_direction(self.R[:2])

    def _project(self, pts):
        xc = pts @ self.R.T + self.t
        z = np.where(xc[..., 2] > 0.0, xc[..., 2], np.nan)  # behind the camera: NaN
        xn, yn = xc[..., 0] / z, xc[..., 1] / z
        k1, k2, p1, p2, k3, k4, k5, k6 = self.dist
        r2 = xn * xn + yn * yn
        radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = xn * radial + 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn)
        yd = yn * radial + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn
        return np.stack([self.K[0, 0] * xd + self.K[0, 2], self.K[1, 1] * yd + self.K[1, 2]], -1)

    def _state(self):
        return (self.name, self.K, self.dist, self.R, self.rvec, self.t, self.image_size)


Camera: TypeAlias = OrthographicCamera | PinholeCamera


# --- packed arrays for the numba kernels ----------------------------------------------------


class CameraArrays(NamedTuple):
    """Cameras packed into contiguous arrays for :mod:`kinematics._kernels.camera`.

    Unused slots hold identity/zero values (P for pinhole; K, dist, R, t for orthographic).
    """

    kind: np.ndarray  # (n,) int64: 0 orthographic, 1 pinhole
    P: np.ndarray  # (n, 2, 4)
    K: np.ndarray  # (n, 3, 3)
    dist: np.ndarray  # (n, 8)
    R: np.ndarray  # (n, 3, 3)
    t: np.ndarray  # (n, 3)


def pack_cameras(cameras: Sequence[Camera] | Mapping[str, Camera]) -> CameraArrays:
    """Pack cameras once, in order, into :class:`CameraArrays` (a mapping packs its values).

    Parameters
    ----------
    cameras : sequence of Camera, or mapping name -> Camera
        Camera ``c`` of the kernels is the ``c``-th item.

    Returns
    -------
    CameraArrays
    """
    cams = list(cameras.values()) if isinstance(cameras, Mapping) else list(cameras)
    n = len(cams)
    kind = np.zeros(n, dtype=np.int64)
    P, dist, t = np.zeros((n, 2, 4)), np.zeros((n, 8)), np.zeros((n, 3))
    K, R = np.tile(np.eye(3), (n, 1, 1)), np.tile(np.eye(3), (n, 1, 1))
    for c, cam in enumerate(cams):
        if isinstance(cam, OrthographicCamera):
            P[c] = cam.P
        elif isinstance(cam, PinholeCamera):
            kind[c] = PINHOLE
            K[c], dist[c], R[c], t[c] = cam.K, cam.dist, cam.R, cam.t
        else:
            raise KinematicsError(f"not a camera: {cam!r}", field=f"cameras[{c}]")
    return CameraArrays(kind, P, K, dist, R, t)


def project_packed(arrays: CameraArrays, camera_index: int, points) -> np.ndarray:
    """Project points through packed camera ``camera_index`` with the numba kernel.

    Parameters
    ----------
    arrays : CameraArrays
        From :func:`pack_cameras`.
    camera_index : int
    points : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 2)
        Same values as ``camera.project(points)``.
    """
    n = arrays.kind.shape[0]
    if isinstance(camera_index, bool) or not isinstance(camera_index, int | np.integer) or not (
        0 <= camera_index < n
    ):
        raise KinematicsError(f"expected an index in [0, {n}), got {camera_index!r}",
                              field="camera_index")
    pts = _as_points(points)
    flat = np.ascontiguousarray(pts.reshape(-1, 3))
    out = np.empty((flat.shape[0], 2))
    project_points_kernel(*arrays, int(camera_index), flat, out)
    return out.reshape((*pts.shape[:-1], 2))


# --- description ----------------------------------------------------------------------------


def _fmt(values) -> str:
    return "(" + ", ".join(f"{v + 0.0:.6g}" for v in np.ravel(values)) + ")"  # no "-0"


def describe_camera(cam: Camera) -> str:
    """One-line human summary of a camera (name, model, parameters, view direction, size)."""
    size = "" if cam.image_size is None else f", {cam.image_size[0]}x{cam.image_size[1]} px"
    look = f"looks along {_fmt(cam.view_direction)}"
    if isinstance(cam, OrthographicCamera):
        form = cam.axes_form
        if form is not None:
            what = (f"scale {form.scale:.6g}, axes ({form.axes[0]}, {form.axes[1]}), "
                    f"offset {_fmt(form.offset)}")
        else:
            what = f"P [{_fmt(cam.P[0])}, {_fmt(cam.P[1])}]"
        return f"{cam.name}: orthographic, {what}, {look}{size}"
    k = cam.K
    n_dist = int(np.count_nonzero(cam.dist))
    return (f"{cam.name}: pinhole, f {_fmt((k[0, 0], k[1, 1]))} px, c {_fmt((k[0, 2], k[1, 2]))},"
            f" {n_dist} nonzero distortion coefficient{'s' * (n_dist != 1)}, centre "
            f"{_fmt(cam.centre)}, {look}{size}")
