"""Other tools' camera files: Anipose ``calibration.toml``, OpenCV YAML, DLT-11 coefficients
(DLTdv, easyWand, Argus) and Qualisys ``.qca`` (as Pose2Sim ships it).

Readers return ``{name: PinholeCamera}`` (world to camera, OpenCV pixel convention: origin
at the centre of the top-left pixel, v down); writers are atomic. Reading Anipose TOML and
OpenCV YAML is :mod:`kinematics.cameras.files`'s; this module adds the writers and the other
formats. Every problem is a one-line :class:`~kinematics.errors.KinematicsError` naming the
file (and line or field).
"""

from __future__ import annotations

import csv
import io
import os
import warnings
from collections.abc import Mapping
from pathlib import Path

import cv2
import numpy as np

from kinematics.cameras import PinholeCamera
from kinematics.cameras.calibration_math import rotation_to_rvec
from kinematics.cameras.files import import_anipose_toml, import_opencv_yaml
from kinematics.errors import KinematicsError
from kinematics.fileio import atomic_write, atomic_write_text
from videotrack.errors import VideoTrackWarning

__all__ = [
    "import_anipose_toml",
    "import_opencv_yaml",
    "load_dlt_csv",
    "load_qca",
    "save_anipose_toml",
    "save_dlt_csv",
    "save_opencv_yaml",
]

#: DLT coordinate conventions: DLTdv/easyWand/Argus digitise with the origin at the bottom
#: left and 1-based pixels (MATLAB); "top-left" is OpenCV's 0-based, v-down convention.
ORIGINS = ("bottom-left", "top-left")


def _pinholes(cameras) -> list[PinholeCamera]:
    cams = list(cameras.values()) if isinstance(cameras, Mapping) else list(cameras)
    for cam in cams:
        if not isinstance(cam, PinholeCamera):
            raise KinematicsError(f"{cam.name} is not a pinhole camera; this format holds "
                                  "pinhole cameras only", field=f"cameras.{cam.name}")
    if not cams:
        raise KinematicsError("no cameras to save", field="cameras")
    return cams


def _num(x: float) -> str:
    return repr(float(x))


def _vec(v) -> str:
    return "[" + ", ".join(_num(x) for x in np.ravel(v)) + "]"


# --- Anipose ------------------------------------------------------------------------------


def save_anipose_toml(path: str | os.PathLike, cameras, *, error: float | None = None) -> None:
    """Write an Anipose ``calibration.toml`` (``cam_0``, ``cam_1`` ... tables); world units
    are the cameras' (mm for a calibration made by VideoTrack)."""
    lines = []
    for i, cam in enumerate(_pinholes(cameras)):
        if cam.image_size is None:
            raise KinematicsError("Anipose needs the image size of every camera",
                                  field=f"cameras.{cam.name}.size", file=path)
        if np.any(cam.dist[5:]):
            raise KinematicsError("Anipose holds 5 distortion coefficients; this camera has "
                                  "k4-k6", field=f"cameras.{cam.name}.dist", file=path)
        rvec = cam.rvec if cam.rvec is not None else rotation_to_rvec(cam.R)
        lines += [f"[cam_{i}]", f"name = \"{cam.name}\"", f"size = {_vec(cam.image_size)}",
                  "matrix = [" + ", ".join(_vec(row) for row in cam.K) + "]",
                  f"distortions = {_vec(cam.dist[:5])}", f"rotation = {_vec(rvec)}",
                  f"translation = {_vec(cam.t)}", "", ""]
    lines += ["[metadata]", "adjusted = true"]
    if error is not None:
        lines.append(f"error = {_num(error)}")
    atomic_write_text(path, "\n".join(lines) + "\n")


# --- OpenCV YAML --------------------------------------------------------------------------


def save_opencv_yaml(path: str | os.PathLike, camera: PinholeCamera) -> None:
    """Write one camera as OpenCV FileStorage YAML (``camera_matrix``,
    ``distortion_coefficients``, ``R``, ``T``, ``image_width``, ``image_height``), which
    ``cv2.FileStorage`` and :func:`import_opencv_yaml` read."""
    (camera,) = _pinholes([camera])
    path = Path(path)
    n = 8 if np.any(camera.dist[5:]) else 5
    tmp = path.with_name(f".{path.name}.cv.yml")  # FileStorage writes by name only
    try:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        if camera.image_size is not None:
            fs.write("image_width", int(camera.image_size[0]))
            fs.write("image_height", int(camera.image_size[1]))
        fs.write("camera_matrix", np.asarray(camera.K))
        fs.write("distortion_coefficients", np.asarray(camera.dist[:n]).reshape(1, -1))
        fs.write("R", np.asarray(camera.R))
        fs.write("T", np.asarray(camera.t).reshape(3, 1))
        fs.release()
        data = tmp.read_bytes()
    except (cv2.error, OSError) as err:
        raise KinematicsError(f"cannot write file: {err}", file=path) from None
    finally:
        tmp.unlink(missing_ok=True)
    with atomic_write(path, "wb") as fh:
        fh.write(data)


# --- DLT-11 ---------------------------------------------------------------------------------


def _flip(height: float) -> np.ndarray:
    """Pixels OpenCV -> DLTdv: u + 1, height - v (1-based, v up)."""
    return np.array([[1.0, 0.0, 1.0], [0.0, -1.0, float(height)], [0.0, 0.0, 1.0]])


def dlt_coefficients(camera: PinholeCamera, origin: str = "bottom-left") -> np.ndarray:
    """The 11 DLT coefficients of a camera (distortion is not representable: dropped)."""
    P = camera.K @ np.hstack([camera.R, camera.t[:, None]])
    if origin == "bottom-left":
        if camera.image_size is None:
            raise KinematicsError("the bottom-left DLT convention needs the image size",
                                  field=f"cameras.{camera.name}.size")
        P = _flip(camera.image_size[1]) @ P
    if abs(P[2, 3]) < 1e-9 * np.abs(P).max():
        raise KinematicsError("DLT-11 cannot describe a camera whose focal plane contains the "
                              "world origin (e.g. the camera that defines the world frame); "
                              "move the origin (videotrack calibrate --world-view)",
                              field=f"cameras.{camera.name}")
    return (P / P[2, 3]).ravel()[:11]


def camera_from_dlt(name: str, coefficients, size=None, origin: str = "bottom-left",
                    *, field: str = "dlt") -> PinholeCamera:
    """A pinhole camera (no distortion) from 11 DLT coefficients.

    The camera matrix is decomposed (RQ); a DLT camera may have skew and a non-square
    pixel grid, which a PinholeCamera (OpenCV's model) cannot: skew is dropped, with a
    warning when it is larger than 0.1 % of the focal length.
    """
    L = np.asarray(coefficients, dtype=np.float64)
    if L.shape != (11,):
        raise KinematicsError(f"expected 11 DLT coefficients, got {L.size}", field=field)
    if not np.all(np.isfinite(L)):
        bad = int(np.flatnonzero(~np.isfinite(L))[0])
        raise KinematicsError(f"DLT coefficient {bad + 1} of 11 is {L[bad]} (must be finite)",
                              field=field)
    P = np.append(L, 1.0).reshape(3, 4)
    if origin == "bottom-left":
        if size is None:
            raise KinematicsError("the bottom-left DLT convention needs the image height",
                                  field=field)
        P = np.linalg.inv(_flip(size[1])) @ P
    M = P[:, :3]
    scale = np.abs(M).max()
    if scale == 0 or abs(np.linalg.det(M)) < 1e-12 * scale**3:
        raise KinematicsError("the DLT coefficients are degenerate (singular 3x3 part)",
                              field=field)
    K, R, C, *_ = cv2.decomposeProjectionMatrix(P)
    K = K / K[2, 2]
    # RQ is unique up to signs: make the focal lengths positive
    S = np.diag(np.sign(np.diag(K)))
    K, R = K @ S, S @ R
    if np.linalg.det(R) < 0:  # P was given with the opposite overall sign
        R = -R
    if abs(K[0, 1]) > 1e-3 * K[0, 0]:
        warnings.warn(f"{name}: DLT skew {K[0, 1]:.3g} px dropped (OpenCV's camera model has "
                      "none)", VideoTrackWarning, stacklevel=2)
    K[0, 1] = 0.0
    centre = C[:3, 0] / C[3, 0]
    return PinholeCamera(name, K, (), R=R, t=-R @ centre, size=size)


def save_dlt_csv(path: str | os.PathLike, cameras, *, origin: str = "bottom-left") -> None:
    """Write DLTdv/easyWand ``*_dltCoefs.csv``: 11 rows, one column per camera, no header.

    Distortion cannot be represented in DLT-11 and is dropped, with a warning.
    """
    cams = _pinholes(cameras)
    if origin not in ORIGINS:
        raise KinematicsError(f"expected one of {', '.join(ORIGINS)}, got {origin!r}",
                              field="origin")
    for cam in cams:
        if np.any(cam.dist):
            warnings.warn(f"{cam.name}: DLT coefficients cannot hold lens distortion; it is "
                          f"left out of {Path(path).name}", VideoTrackWarning, stacklevel=2)
    with _located(path):
        cols = np.array([dlt_coefficients(c, origin) for c in cams]).T
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerows([[repr(float(x)) for x in row]
                                                      for row in cols])
    atomic_write_text(path, text.getvalue())


class _located:
    def __init__(self, path):
        self.path = path

    def __enter__(self):
        return self

    def __exit__(self, kind, err, tb):
        if isinstance(err, KinematicsError):
            raise err.located(file=self.path) from None
        return False


def load_dlt_csv(path: str | os.PathLike, names=None, sizes=None, *,
                 origin: str = "bottom-left") -> dict[str, PinholeCamera]:
    """Read a DLT coefficient CSV (11 rows, one column per camera; comma or whitespace).

    Parameters
    ----------
    names : list of str, optional
        Camera names; default ``cam1``, ``cam2`` ...
    sizes : list of (width, height), optional
        Image sizes, needed for the bottom-left (DLTdv) convention.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise KinematicsError(f"cannot read file: {err}", file=path) from None
    rows = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            rows.append([float(x) for x in line.replace(",", " ").split()])
        except ValueError:
            raise KinematicsError(f"expected numbers, got {line.strip()[:40]!r}", file=path,
                                  line=number) from None
    if len(rows) != 11 or len({len(r) for r in rows}) != 1:
        raise KinematicsError(f"expected 11 rows of DLT coefficients with one column per "
                              f"camera, got {len(rows)} rows", file=path)
    L = np.array(rows)  # (11, n_cams)
    n = L.shape[1]
    names = list(names) if names is not None else [f"cam{i + 1}" for i in range(n)]
    sizes = list(sizes) if sizes is not None else [None] * n
    if len(names) != n or len(sizes) != n:
        raise KinematicsError(f"the file has {n} camera column(s); {len(names)} name(s) and "
                              f"{len(sizes)} size(s) given", file=path)
    with _located(path):
        return {name: camera_from_dlt(name, L[:, i], sizes[i], origin, field=f"column {i + 1}")
                for i, name in enumerate(names)}


# --- Qualisys .qca --------------------------------------------------------------------------


def _attr(elem, key: str, path, where: str) -> float:
    value = elem.get(key)
    try:
        return float(value)
    except (TypeError, ValueError):
        raise KinematicsError(f"expected a number in attribute {key!r}, got {value!r}",
                              file=path, line=elem.sourceline, field=where) from None


def load_qca(path: str | os.PathLike) -> dict[str, PinholeCamera]:
    """Import a Qualisys QTM calibration (``.qca``, XML), world units mm.

    Qualisys gives intrinsics in 1/64 pixel (sub-pixel units of the sensor), the camera's
    orientation and position in the world, and a camera frame with y up and z backwards;
    OpenCV's frame is y down, z forward: ``R = diag(1, -1, -1) R_qca``, ``t = -R x_qca``
    (checked against Pose2Sim's conversion of the same file). Distortion: radial k1-k3 and
    tangential p1, p2 (OpenCV's model).
    """
    from kinematics.model.safe_xml import read_foreign

    root = read_foreign(path)
    cams = root.findall("./cameras/camera")
    if root.tag != "calibration" or not cams:
        raise KinematicsError("not a Qualisys calibration: expected <calibration> with "
                              "<cameras><camera> elements", file=path)
    out: dict[str, PinholeCamera] = {}
    for i, cam in enumerate(cams):
        name = cam.get("serial") or f"cam{i + 1}"
        where = f"camera {name}"
        tr, intr, fov = cam.find("transform"), cam.find("intrinsic"), cam.find("fov_video")
        if tr is None or intr is None:
            raise KinematicsError("missing <transform> or <intrinsic>", file=path,
                                  line=cam.sourceline, field=where)
        rot = np.array([[_attr(tr, f"r{a}{b}", path, where) for b in "123"] for a in "123"])
        pos = np.array([_attr(tr, k, path, where) for k in "xyz"])
        left = top = 0.0
        size = None
        if fov is not None:
            left, top = _attr(fov, "left", path, where), _attr(fov, "top", path, where)
            size = (int(_attr(fov, "right", path, where) - left + 1),
                    int(_attr(fov, "bottom", path, where) - top + 1))
        f = [_attr(intr, k, path, where) / 64.0 for k in ("focalLengthU", "focalLengthV")]
        c = [_attr(intr, "centerPointU", path, where) / 64.0 - left,
             _attr(intr, "centerPointV", path, where) / 64.0 - top]
        dist = [_attr(intr, k, path, where) for k in
                ("radialDistortion1", "radialDistortion2", "tangentalDistortion1",
                 "tangentalDistortion2", "radialDistortion3")]
        R = np.diag([1.0, -1.0, -1.0]) @ rot
        try:
            out[name] = PinholeCamera(name, [[f[0], 0, c[0]], [0, f[1], c[1]], [0, 0, 1]],
                                      dist, R=R, t=-R @ pos, size=size)
        except KinematicsError as err:
            raise err.located(file=path, line=cam.sourceline) from None
    return out
