"""Read any camera file VideoTrack knows, choosing the reader by name and content."""

from __future__ import annotations

import os
from pathlib import Path

from kinematics.cameras.files import load_cameras
from kinematics.errors import KinematicsError
from videotrack.io.camera_formats import (
    import_anipose_toml,
    import_opencv_yaml,
    load_dlt_csv,
    load_qca,
)

#: Formats of --import, by name.
FORMATS = ("videotrack", "anipose", "opencv", "dlt", "qca")


def guess_format(path: str | os.PathLike) -> str:
    """The format of a camera file from its name and first bytes."""
    path = Path(path)
    name = path.name.lower()
    if name.endswith((".qca", ".qca.txt")):
        return "qca"
    if name.endswith((".yml", ".yaml", ".json")):
        return "opencv"
    if name.endswith((".csv", ".txt")):
        return "dlt"
    if name.endswith(".xml"):
        try:
            head = path.read_bytes()[:2000]
        except OSError as err:
            raise KinematicsError(f"cannot read file: {err.strerror}", file=path) from None
        return "qca" if b"<calibration" in head else "opencv"
    if name.endswith(".toml"):
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError as err:
            raise KinematicsError(f"cannot read file: {err.strerror}", file=path) from None
        return "videotrack" if "[cameras." in text or "[cameras]" in text else "anipose"
    raise KinematicsError("cannot tell the camera file format from the name; give --format "
                          f"({', '.join(FORMATS)})", file=path)


def read_cameras(path, fmt: str | None = None, *, dlt_size=None, dlt_origin="bottom-left"):
    """{name: camera} from a camera file of any known format (``fmt`` None: guess)."""
    fmt = fmt or guess_format(path)
    if fmt == "videotrack":
        return load_cameras(path)
    if fmt == "anipose":
        return import_anipose_toml(path)
    if fmt == "opencv":
        return import_opencv_yaml(path)
    if fmt == "qca":
        return load_qca(path)
    if fmt == "dlt":
        with open(path, encoding="utf-8", errors="replace") as fh:
            n = len(next((ln for ln in fh if ln.strip()), "").replace(",", " ").split())
        sizes = [dlt_size] * n if dlt_size else None
        return load_dlt_csv(path, sizes=sizes, origin=dlt_origin)
    raise KinematicsError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}",
                          field="--format")
