"""Camera files (TOML) and import of OpenCV and Anipose calibrations.

The format is documented in ``docs/cameras.md``. Every problem raises
:class:`~kinematics.errors.KinematicsError` with the file, the line where it can be found and
the dotted field (``cameras.top.scale``).
"""

from __future__ import annotations

import json
import os
import re
import tomllib
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np

from kinematics.cameras import (
    DIST_COUNTS,
    Camera,
    OrthographicCamera,
    PinholeCamera,
)
from kinematics.errors import KinematicsError
from kinematics.fileio import atomic_write_text, parse_toml

__all__ = [
    "UNITS",
    "CameraFile",
    "camera_from_table",
    "camera_to_table",
    "import_anipose_toml",
    "import_opencv_yaml",
    "load_camera_file",
    "load_cameras",
    "save_cameras",
]

#: Values of the optional top-level ``units`` key: the length unit of world coordinates.
UNITS = ("px", "mm")

_ORTHOGRAPHIC_KEYS = ("type", "matrix", "scale", "axes", "offset", "size")
_PINHOLE_KEYS = ("type", "K", "dist", "R", "rvec", "t", "size")
_ANIPOSE_KEYS = ("name", "size", "matrix", "distortions", "rotation", "translation", "fisheye")

# OpenCV FileStorage key aliases, in order of preference (calibration samples, common scripts).
_CV_K = ("camera_matrix", "cameraMatrix", "K", "M", "mtx")
_CV_DIST = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "D", "dist")
_CV_ROTATION = ("R", "rvec")
_CV_TRANSLATION = ("T", "t", "tvec")
_CV_SIZE = ("image_size", "imageSize")
_ROS_PINHOLE_MODELS = ("plumb_bob", "rational_polynomial")


class CameraFile(NamedTuple):
    """Contents of a camera file: cameras in file order and the declared length unit."""

    cameras: dict[str, Camera]
    units: str | None


# --- error location -------------------------------------------------------------------------


@contextmanager
def _fields_under(prefix: str, rename: Mapping[str, str] | None = None) -> Iterator[None]:
    """Put ``prefix.`` before the field of errors raised inside, renaming fields first.

    ``rename`` maps constructor parameter names to the key names of the file being read.
    """
    try:
        yield
    except KinematicsError as err:
        field = (rename or {}).get(err.field, err.field)
        err.field = ".".join(part for part in (prefix, field) if part) or None
        raise


_HEADER = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]")
_KEY = re.compile(r"""^\s*("[^"]*"|'[^']*'|[A-Za-z0-9_-]+)\s*=""")


def _line_of(text: str, field: str | None) -> int | None:
    """Best-effort 1-based line of a dotted field (a key, or else its table) in TOML text."""
    if not field:
        return None
    want = field.split(".")
    table: list[str] = []
    best = (0, None)
    for number, line in enumerate(text.splitlines(), 1):
        if m := _HEADER.match(line):
            path = table = [p.strip().strip("\"'") for p in m.group(1).split(".")]
        elif m := _KEY.match(line):
            path = [*table, m.group(1).strip("\"'")]
        else:
            continue
        if path == want:
            return number
        if path == want[: len(path)] and len(path) > best[0]:
            best = (len(path), number)
    return best[1]


@contextmanager
def _located(path, text: str | None = None) -> Iterator[None]:
    """Fill in the file (and, from ``text``, the line) of errors raised inside."""
    try:
        yield
    except KinematicsError as err:
        line = _line_of(text, err.field) if text is not None else None
        raise err.located(file=path, line=line) from None


def _read_text(path) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise KinematicsError(f"cannot read file: {err}", file=path) from None


def _load_toml(path) -> tuple[dict, str]:
    text = _read_text(path)
    try:
        return parse_toml(text), text
    except tomllib.TOMLDecodeError as err:
        msg = str(err)
        m = re.search(r"\s*\(at line (\d+), column \d+\)$", msg)
        line = int(m.group(1)) if m else None
        raise KinematicsError(f"invalid TOML: {msg[: m.start()] if m else msg}", file=path,
                              line=line) from None


def _check_keys(table, allowed: Sequence[str], what: str) -> None:
    if not isinstance(table, dict):
        raise KinematicsError(f"expected a table for {what}, got {table!r}")
    for key in table:
        if key not in allowed:
            raise KinematicsError(f"unknown key {key!r} for {what}; expected one of "
                                  f"{', '.join(allowed)}", field=key)


# --- camera tables --------------------------------------------------------------------------


def camera_from_table(name: str, table: Mapping) -> Camera:
    """Build a camera from one parsed ``[cameras.NAME]`` table of a camera file.

    Errors carry the key inside the table as their field (callers prefix the table path).
    Usable for cameras embedded in other TOML documents (e.g. a run configuration).
    """
    if not isinstance(table, dict):
        raise KinematicsError(f"expected a table, got {table!r}")
    kind = table.get("type")
    if kind == "orthographic":
        _check_keys(table, _ORTHOGRAPHIC_KEYS, "an orthographic camera")
        form_keys = [k for k in ("scale", "axes", "offset") if k in table]
        if "matrix" in table:
            if form_keys:
                raise KinematicsError("give either matrix or scale/axes/offset, not both",
                                      field=form_keys[0])
            with _fields_under("", {"P": "matrix"}):
                return OrthographicCamera(name, table["matrix"], size=table.get("size"))
        for key in ("scale", "axes"):
            if key not in table:
                raise KinematicsError(f"missing key {key!r} (or give matrix)", field=key)
        return OrthographicCamera.from_axes(name, table["scale"], table["axes"],
                                            table.get("offset", (0.0, 0.0)),
                                            size=table.get("size"))
    if kind == "pinhole":
        _check_keys(table, _PINHOLE_KEYS, "a pinhole camera")
        for key in ("K", "t"):
            if key not in table:
                raise KinematicsError(f"missing key {key!r}", field=key)
        if "R" not in table and "rvec" not in table:
            raise KinematicsError("missing key 'R' or 'rvec'", field="R")
        return PinholeCamera(name, table["K"], table.get("dist", ()), table.get("R"), table["t"],
                             table.get("size"), rvec=table.get("rvec"))
    what = "missing key 'type'" if kind is None else f"unknown camera type {kind!r}"
    raise KinematicsError(f"{what}; expected 'orthographic' or 'pinhole'", field="type")


def _dist_count(dist: np.ndarray) -> int:
    """Fewest OpenCV coefficient count that keeps every nonzero coefficient."""
    return next(n for n in DIST_COUNTS if not np.any(dist[n:]))


def camera_to_table(camera: Camera) -> dict:
    """The ``[cameras.NAME]`` table of a camera, in the form the camera was built from."""
    if isinstance(camera, OrthographicCamera):
        table: dict = {"type": "orthographic"}
        form = camera.axes_form
        if form is None:
            table["matrix"] = camera.P.tolist()
        else:
            table.update(scale=form.scale, axes=list(form.axes), offset=list(form.offset))
    elif isinstance(camera, PinholeCamera):
        table = {"type": "pinhole", "K": camera.K.tolist()}
        n_dist = _dist_count(camera.dist)
        if n_dist:
            table["dist"] = camera.dist[:n_dist].tolist()
        if camera.rvec is not None:
            table["rvec"] = camera.rvec.tolist()
        else:
            table["R"] = camera.R.tolist()
        table["t"] = camera.t.tolist()
    else:
        raise KinematicsError(f"not a camera: {camera!r}")
    if camera.image_size is not None:
        table["size"] = list(camera.image_size)
    return table


# --- camera files ---------------------------------------------------------------------------


def load_camera_file(path: str | os.PathLike) -> CameraFile:
    """Read a camera file (TOML, see ``docs/cameras.md``).

    Returns
    -------
    CameraFile
        ``cameras``: name -> camera, in file order; ``units``: "px", "mm" or None.
    """
    doc, text = _load_toml(path)
    with _located(path, text):
        _check_keys(doc, ("units", "cameras"), "a camera file")
        units = doc.get("units")
        if units is not None and units not in UNITS:
            raise KinematicsError(f"expected one of {', '.join(UNITS)}, got {units!r}",
                                  field="units")
        tables = doc.get("cameras")
        if not isinstance(tables, dict) or not tables:
            raise KinematicsError("expected at least one [cameras.NAME] table", field="cameras")
        cameras = {}
        for name, table in tables.items():
            with _fields_under(f"cameras.{name}"):
                cameras[name] = camera_from_table(name, table)
    return CameraFile(cameras, units)


def load_cameras(path: str | os.PathLike) -> dict[str, Camera]:
    """Cameras of a camera file, name -> camera in file order (see :func:`load_camera_file`)."""
    return load_camera_file(path).cameras


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.fullmatch(key) else json.dumps(key, ensure_ascii=False)


def _toml_value(value) -> str:
    """TOML for the values a camera table holds: str, int, float and (nested) lists.

    Floats are written with ``repr`` so they read back bit for bit; matrices get one row
    per line (tomli_w would put every number on its own line).
    """
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a JSON string is a TOML basic string
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if value and isinstance(value[0], list):
        return "[\n" + "".join(f"    {_toml_value(row)},\n" for row in value) + "]"
    return "[" + ", ".join(_toml_value(v) for v in value) + "]"


def _dumps(units: str | None, tables: Mapping[str, dict]) -> str:
    lines = [] if units is None else [f"units = {_toml_value(units)}", ""]
    for name, table in tables.items():
        lines.append(f"[cameras.{_toml_key(name)}]")
        lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in table.items()]
        lines.append("")
    return "\n".join(lines)


def save_cameras(path: str | os.PathLike,
                 cameras: Mapping[str, Camera] | Sequence[Camera], *,
                 units: str | None = None) -> None:
    """Write a camera file atomically; :func:`load_cameras` reads back equal cameras.

    Parameters
    ----------
    path : path-like
    cameras : mapping name -> camera (keys must equal the camera names), or sequence
        Written in order.
    units : {"px", "mm"}, optional
        Length unit of world coordinates, written as the top-level ``units`` key.
    """
    if units is not None and units not in UNITS:
        raise KinematicsError(f"expected one of {', '.join(UNITS)}, got {units!r}",
                              field="units", file=path)
    items = cameras.items() if isinstance(cameras, Mapping) else ((c.name, c) for c in cameras)
    tables: dict[str, dict] = {}
    for key, camera in items:
        with _fields_under(f"cameras.{key}"), _located(path):
            if key in tables:
                raise KinematicsError("two cameras have this name")
            if getattr(camera, "name", key) != key:
                raise KinematicsError(f"key differs from the camera's name {camera.name!r}")
            tables[key] = camera_to_table(camera)
    if not tables:
        raise KinematicsError("no cameras to save", file=path, field="cameras")
    atomic_write_text(path, _dumps(units, tables))


# --- imports --------------------------------------------------------------------------------


def import_anipose_toml(path: str | os.PathLike) -> dict[str, PinholeCamera]:
    """Import an Anipose ``calibration.toml`` (also Pose2Sim's calibration TOML).

    Each table other than ``metadata`` (``cam_0``, ``cam_1`` ...) is one camera with
    ``name``, ``size``, ``matrix``, ``distortions``, ``rotation`` (Rodrigues vector, world
    to camera) and ``translation``; it projects as ``cv2.projectPoints`` with these values.

    Returns
    -------
    dict
        Camera name (the table's ``name``, else the table key) -> PinholeCamera, in file order.
    """
    doc, text = _load_toml(path)
    rename = {"K": "matrix", "dist": "distortions", "rvec": "rotation", "t": "translation"}
    cameras: dict[str, PinholeCamera] = {}
    with _located(path, text):
        for key, table in doc.items():
            if key == "metadata":
                continue
            with _fields_under(key, rename):
                _check_keys(table, _ANIPOSE_KEYS, "an Anipose camera")
                if table.get("fisheye", False) is not False:
                    raise KinematicsError("fisheye cameras are not supported", field="fisheye")
                for required in ("matrix", "rotation", "translation"):
                    if required not in table:
                        raise KinematicsError(f"missing key {required!r}", field=required)
                name = table.get("name", key)
                if name in cameras:
                    raise KinematicsError(f"duplicate camera name {name!r}", field="name")
                cameras[name] = PinholeCamera(name, table["matrix"], table.get("distortions", ()),
                                              t=table["translation"], size=table.get("size"),
                                              rvec=table["rotation"])
        if not cameras:
            raise KinematicsError("no camera tables found")
    return cameras


def _node_value(node):
    """Python value of an OpenCV FileNode: ndarray, list, int, float, str or None."""
    if node.isMap():
        keys = node.keys()
        if "dt" in keys:  # !!opencv-matrix
            try:
                return node.mat()
            except cv2.error:  # its data does not fill rows x cols
                rows, cols = (n.string() if n.isString() else f"{n.real():g}"
                              for n in (node.getNode(k) for k in ("rows", "cols")))
                raise KinematicsError(f"an opencv-matrix of {rows} x {cols} holds "
                                      f"{node.getNode('data').size()} numbers") from None
        if {"rows", "cols", "data"} <= set(keys):  # ROS camera_info YAML
            rows, cols = (int(node.getNode(k).real()) for k in ("rows", "cols"))
            data = _node_value(node.getNode("data"))
            return np.reshape(data, (rows, cols)) if len(data) == rows * cols else data
        return None
    if node.isSeq():
        return [_node_value(node.at(i)) for i in range(node.size())]
    if node.isInt():
        return int(node.real())
    if node.isReal():
        return node.real()
    if node.isString():
        return node.string()
    return None


def _read_storage(path) -> dict:
    """Top-level keys of an OpenCV FileStorage file (YAML, JSON or XML) as Python values."""
    if not Path(path).is_file():  # FileStorage would only log an error
        raise KinematicsError("file not found", file=path)
    try:
        fs = cv2.FileStorage(os.fspath(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as err:  # parse errors surface as SystemError from cv2.error
        msg = str(err.__cause__ or err)
        m = re.search(r"\((\d+)\): ([^'\n]*)", msg)
        raise KinematicsError(f"cannot parse OpenCV file: {m.group(2) if m else msg.strip()}",
                              file=path, line=int(m.group(1)) if m else None) from None
    try:
        if not fs.isOpened():
            raise KinematicsError("cannot read as an OpenCV FileStorage file", file=path)
        out = {}
        keys = fs.root().keys()  # a FileNode is not iterable
        for key in keys:
            try:
                out[key] = _node_value(fs.getNode(key))
            except KinematicsError as err:
                raise err.located(file=path, field=key) from None
        return out
    finally:
        fs.release()


def import_opencv_yaml(path: str | os.PathLike, name: str | None = None, *,
                       extrinsics: str | os.PathLike | None = None) -> dict[str, PinholeCamera]:
    """Import an OpenCV FileStorage calibration (YAML, also JSON or XML).

    ROS ``camera_info`` YAML files (matrices as ``rows``/``cols``/``data`` maps) are read too.
    A single camera needs a camera matrix (``camera_matrix``, ``cameraMatrix``, ``K``, ``M``
    or ``mtx``) and optionally distortion (``distortion_coefficients``, ``dist_coeffs``,
    ``distCoeffs``, ``D``, ``dist``), a pose (``R`` as 3x3 matrix or Rodrigues vector, or
    ``rvec``; ``T``, ``t`` or ``tvec``; default: at the origin) and the image size
    (``image_width`` and ``image_height``, or ``image_size`` [w, h]). A stereo calibration
    (``M1``, ``D1``, ``M2``, ``D2``, ``R``, ``T`` as written after ``cv2.stereoCalibrate``)
    gives two cameras, the first at the origin and the second at ``x2 = R x1 + T``.
    Other keys (reprojection error, per-view extrinsics ...) are ignored.

    Parameters
    ----------
    path : path-like
    name : str, optional
        Camera name; default the file's stem. Stereo cameras are ``NAME_1`` and ``NAME_2``.
    extrinsics : path-like, optional
        A second file read together with ``path`` (OpenCV's stereo sample writes
        ``intrinsics.yml`` with M1/D1/M2/D2 and ``extrinsics.yml`` with R/T).

    Returns
    -------
    dict
        Name -> PinholeCamera.
    """
    found: dict[str, tuple[object, str | os.PathLike]] = {}  # key -> (value, file)
    for file in (path,) if extrinsics is None else (path, extrinsics):
        found.update({k: (v, file) for k, v in _read_storage(file).items() if v is not None})
    model = found.get("distortion_model", (None,))[0]  # ROS: fisheye is "equidistant"
    if model not in (None, *_ROS_PINHOLE_MODELS):
        raise KinematicsError(f"distortion model {model!r} is not supported; expected one of "
                              f"{', '.join(_ROS_PINHOLE_MODELS)}",
                              file=found["distortion_model"][1], field="distortion_model")
    name = Path(path).stem if name is None else name

    def pick(keys: Sequence[str], required=False) -> str | None:
        key = next((k for k in keys if k in found), None)
        if key is None and required:
            raise KinematicsError(f"none of the keys {', '.join(keys)} found", file=path,
                                  field=keys[0])
        return key

    if "M1" in found:
        r_key, t_key = pick(("R",), True), pick(("T",), True)
        specs = [(f"{name}_1", "M1", "D1", None, None), (f"{name}_2", "M2", "D2", r_key, t_key)]
    else:
        specs = [(name, pick(_CV_K, True), pick(_CV_DIST), pick(_CV_ROTATION),
                  pick(_CV_TRANSLATION))]
    return {cam_name: _cv_camera(found, cam_name, *keys) for cam_name, *keys in specs}


def _cv_camera(found: dict, name: str, k_key: str, d_key, r_key, t_key) -> PinholeCamera:
    """One PinholeCamera from FileStorage values; errors name the file key and its file."""
    if "image_width" in found and "image_height" in found:
        size_key, size = "image_width", [found["image_width"][0], found["image_height"][0]]
    else:
        size_key = next((k for k in _CV_SIZE if k in found), None)
        size = found[size_key][0] if size_key else None

    def get(key, default=None):
        return found[key][0] if key in found else default

    rot = get(r_key)
    is_rvec = rot is not None and np.size(rot) == 3  # R may hold a Rodrigues vector
    rename = {"K": k_key, "dist": d_key, "R": r_key, "rvec": r_key, "t": t_key,
              "size": size_key}
    try:
        return PinholeCamera(name, get(k_key), get(d_key, ()), None if is_rvec else rot,
                             get(t_key, (0.0, 0.0, 0.0)), size, rvec=rot if is_rvec else None)
    except KinematicsError as err:
        err.field = rename.get(err.field) or err.field
        raise err.located(file=found.get(err.field, found[k_key])[1]) from None
