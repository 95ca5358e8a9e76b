"""The never-overwrite rule: an output may not replace an input, nor a file of another kind.

Every command that writes (``detect``, ``fit``, ``run``, ``batch``, ``synth``) checks its
output paths with :func:`guard_outputs` before doing any work:

- an output that is one of the run's inputs (the chain, the cameras, a video, a config file,
  the detections a fit reads, an image of an image folder, ...) is refused, always;
- an output path holding an existing file of another kind (results over an XML chain, a
  detections file over a video, ...) is refused unless ``force`` (``--force``);
- an existing file of the same kind (the results of an earlier fit) is replaced, atomically,
  as before; an empty file may be replaced by anything.
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Iterable, Mapping
from pathlib import Path

from kinematics.fileio import parse_toml
from videotrack.errors import VideoTrackError

#: Kinds of files the commands write, and how each is described in messages.
KINDS = {
    "results": "results CSV",
    "sidecar": "results sidecar (JSON)",
    "detections": "detections file (.npz)",
    "png": "PNG image",
    "summary": "batch summary CSV",
    "video": "video",
    "folder": "folder",
    "csv": "CSV table",
    "toml": "TOML file",
    "xml": "XML file",
    "corners": "calibration corner cache (.npz)",
    "npz": "NumPy archive (.npz)",
    "h5": "HDF5 file (.h5, .nwb)",
    "trc": "OpenSim marker file (.trc)",
    "mot": "OpenSim motion file (.mot)",
    "c3d": "C3D file",
    "pose3d": "pose-3d CSV (Anipose)",
}


def _head(path: Path, n: int = 512) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(n)
    except OSError:
        return b""


def _first_line(path: Path) -> str:
    return _head(path, 4096).split(b"\n", 1)[0].decode("utf-8", "replace").lstrip("\ufeff")


def is_kind(path: str | os.PathLike, kind: str) -> bool:
    """Whether the existing file ``path`` is a file of ``kind`` (see :data:`KINDS`)."""
    path = Path(path)
    if kind == "folder":
        return path.is_dir()
    if path.is_dir():
        return False
    head = _head(path)
    if kind == "results":
        return _first_line(path).startswith("frame,video_frame,field,time")
    if kind == "pose3d":
        from videotrack.io.pose3d import is_pose3d
        return is_pose3d(path)
    if kind == "summary":
        return _first_line(path).startswith("trial,state,")
    if kind == "csv":
        line = _first_line(path)
        return bool(line) and "," in line and "\0" not in line
    if kind == "png":
        return head.startswith(b"\x89PNG\r\n\x1a\n")
    if kind == "detections":
        try:
            with zipfile.ZipFile(path) as z:
                return "metadata.npy" in z.namelist()
        except (OSError, zipfile.BadZipFile):
            return False
    if kind == "corners":  # videotrack.calibration.detect.CACHE_MARK
        try:
            with zipfile.ZipFile(path) as z:
                return "calibration_corners.npy" in z.namelist()
        except (OSError, zipfile.BadZipFile):
            return False
    if kind == "video":
        return ((head[:4] == b"RIFF" and head[8:12] == b"AVI ") or head[4:8] == b"ftyp"
                or head[:4] == b"\x1aE\xdf\xa3")
    if kind == "npz":
        return head.startswith(b"PK")
    if kind == "h5":
        return head.startswith(b"\x89HDF\r\n\x1a\n")
    if kind == "trc":
        return head.startswith(b"PathFileType")
    if kind == "mot":
        return b"endheader" in _head(path, 4096)
    if kind == "c3d":
        return len(head) > 1 and head[1] == 0x50  # the C3D header's key byte
    if kind == "xml":
        return head.lstrip(b"\xef\xbb\xbf \t\r\n").startswith(b"<")
    if kind in ("sidecar", "toml"):
        try:
            text = path.read_text(encoding="utf-8")
            data = json.loads(text) if kind == "sidecar" else parse_toml(text)
        except (OSError, UnicodeDecodeError, ValueError):
            return False
        return isinstance(data, dict) and (kind == "toml" or "rows" in data)
    raise ValueError(f"unknown kind {kind!r}")


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(os.path.abspath(a)) == Path(os.path.abspath(b))


def guard_outputs(outputs: Mapping[str | os.PathLike, str],
                  inputs: Mapping[str | os.PathLike, str] | Iterable = (), *,
                  force: bool = False, field: str | None = None) -> None:
    """Refuse outputs that would overwrite an input or an existing file of another kind.

    Parameters
    ----------
    outputs : mapping
        Output path -> its kind (a key of :data:`KINDS`).
    inputs : mapping or iterable
        Input paths (-> what they are, e.g. ``"the chain"``, for the message). An input that
        is an image folder also protects the images in it.
    force : bool
        Allow replacing an existing file of another kind (never an input).
    field : str, optional
        The option or key that named the outputs, for the message.

    Raises
    ------
    VideoTrackError
        Naming the output file and why it is not written.
    """
    from videotrack.detect.video import IMAGE_EXTENSIONS

    roles = dict(inputs) if isinstance(inputs, Mapping) else {p: "an input" for p in inputs}
    roles = {Path(p): role for p, role in roles.items() if p}
    for out, kind in outputs.items():
        out = Path(out)
        for src, role in roles.items():
            inside = (out.suffix.lower() in IMAGE_EXTENSIONS and src.is_dir()
                      and _same(out.parent, src))
            if _same(out, src) or inside:
                what = role if not inside else f"an image in {role}"
                raise VideoTrackError(f"is {what} of this run: an output never replaces an "
                                      "input; choose another path", file=out, field=field)
        if force or not (out.exists() or out.is_symlink()):
            continue
        if out.is_file() and out.stat().st_size == 0:
            continue
        if not is_kind(out, kind):
            raise VideoTrackError(f"exists and is not a {KINDS[kind]}: not overwritten "
                                  "(--force does)", file=out, field=field)
