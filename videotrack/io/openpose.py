"""OpenPose JSON keypoints: a folder with one JSON file per frame (``--write_json``).

Each file lists ``people``, each with ``pose_keypoints_2d`` = [x0, y0, c0, x1, ...]; a point
with confidence 0 was not detected. The frame number is the last number in the file name
(``cam01.0042.json``, ``video_000000000042_keypoints.json``). One person is followed: by index
in each frame's list, the one with the largest bounding box (default), or the most confident;
the others become candidates for the Viterbi filter.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from videotrack.errors import VideoTrackError
from videotrack.io.keypoints import KeypointTracks, make_tracks

_DIGITS = re.compile(r"(\d+)(?!.*\d)")

#: Keypoint names of OpenPose's body models, in the order of ``pose_keypoints_2d``.
MODELS = {
    "BODY_25": ("Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow",
                "LWrist", "MidHip", "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle",
                "REye", "LEye", "REar", "LEar", "LBigToe", "LSmallToe", "LHeel", "RBigToe",
                "RSmallToe", "RHeel"),
    # the experimental model Pose2Sim uses; "Neck" and "Head" are its UpperNeck and HeadTop
    "BODY_25B": ("Nose", "LEye", "REye", "LEar", "REar", "LShoulder", "RShoulder", "LElbow",
                 "RElbow", "LWrist", "RWrist", "LHip", "RHip", "LKnee", "RKnee", "LAnkle",
                 "RAnkle", "Neck", "Head", "LBigToe", "LSmallToe", "LHeel", "RBigToe",
                 "RSmallToe", "RHeel"),
    "COCO": ("Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
             "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar",
             "LEar"),
}
_BY_COUNT = {25: "BODY_25", 18: "COCO"}
CHOICES = ("largest", "confident")


def _frame_files(path: Path) -> list[tuple[int, Path]]:
    files = sorted(path.glob("*.json")) if path.is_dir() else [path]
    if not files:
        raise VideoTrackError("no OpenPose JSON files in this folder", file=path)
    numbers = []
    for i, f in enumerate(files):
        m = _DIGITS.search(f.stem)
        numbers.append(int(m.group(1)) if m else i)
    if len(set(numbers)) != len(numbers):  # names without distinct numbers: file order
        numbers = list(range(len(files)))
    return sorted(zip(numbers, files, strict=True))


def _people(file: Path) -> list[np.ndarray]:
    """The (n_kp, 3) keypoints of every person in one frame's file."""
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise VideoTrackError(f"not JSON: {e.msg}", file=file, line=e.lineno) from None
    except (OSError, UnicodeDecodeError) as e:
        raise VideoTrackError(f"cannot read: {e}", file=file) from None
    if not isinstance(data, dict) or not isinstance(data.get("people"), list):
        raise VideoTrackError("not an OpenPose file: no 'people' list", file=file)
    out = []
    for i, person in enumerate(data["people"]):
        values = person.get("pose_keypoints_2d") if isinstance(person, dict) else None
        try:
            arr = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            arr = np.empty(0)
        if arr.ndim != 1 or arr.size == 0 or arr.size % 3:
            raise VideoTrackError("pose_keypoints_2d must be a list of x, y, confidence "
                                  "triples", file=file, field=f"people[{i}]")
        out.append(arr.reshape(-1, 3))
    return out


def _rank(person: np.ndarray, how: str) -> float:
    seen = person[person[:, 2] > 0]
    if not len(seen):
        return -1.0
    if how == "confident":
        return float(seen[:, 2].mean())
    return float(np.prod(seen[:, :2].max(axis=0) - seen[:, :2].min(axis=0)))


def read(path: Path, individual: str | int | None = None, model: str | None = None
         ) -> KeypointTracks:
    """Read an OpenPose JSON folder (or one file); ``individual`` is a person index,
    ``"largest"`` (default) or ``"confident"``; ``model`` names the keypoints."""
    path = Path(path)
    how = "largest" if individual is None else individual
    if not (isinstance(how, (int, np.integer)) or str(how).isdigit() or how in CHOICES):
        raise VideoTrackError(f"person must be an index, 'largest' or 'confident', not "
                              f"{individual!r}", file=path, field="individual")
    frames_files = _frame_files(path)
    per_frame = [_people(f) for _, f in frames_files]
    n_kp = {p.shape[0] for people in per_frame for p in people}
    if len(n_kp) > 1:
        raise VideoTrackError(f"people have different keypoint counts {sorted(n_kp)}",
                              file=path)
    if not n_kp:
        raise VideoTrackError("no person in any frame", file=path)
    k = n_kp.pop()
    names = _names(model, k, path)
    n_people = max(len(p) for p in per_frame)
    data = np.full((len(per_frame), n_people + 1, k, 3), np.nan)  # + 1: an absent person
    for f, people in enumerate(per_frame):
        if not people:
            continue
        if isinstance(how, str) and not how.isdigit():
            order = sorted(range(len(people)), key=lambda j: -_rank(people[j], how))
        else:
            i = int(how)  # that person first; when absent, slot 0 stays empty
            first = [i] if i < len(people) else [None]
            order = first + [j for j in range(len(people)) if j != i]
        for slot, j in enumerate(order):
            if j is not None:
                data[f, slot] = people[j]
    unseen = ~(data[..., 2] > 0)  # confidence 0 (or NaN): not detected
    data[unseen] = np.nan
    others = data[:, 1:]
    others = others[:, np.isfinite(others[..., 0]).any(axis=(0, 2))]
    candidates = others if others.shape[1] else None
    return make_tracks(names, data[:, 0, :, :2], data[:, 0, :, 2],
                       [n for n, _ in frames_files], path, candidates=candidates,
                       individual=str(how))


def _names(model: str | None, k: int, path) -> tuple[str, ...]:
    if model is None:
        model = _BY_COUNT.get(k)
        if model is None:
            return tuple(f"kp{i}" for i in range(k))
    key = str(model).upper()
    if key not in MODELS:
        raise VideoTrackError(f"unknown OpenPose model {model!r} (one of "
                              f"{', '.join(MODELS)})", file=path, field="model")
    if len(MODELS[key]) != k:
        raise VideoTrackError(f"model {key} has {len(MODELS[key])} keypoints, the files have "
                              f"{k}", file=path, field="model")
    return MODELS[key]
