"""DeepLabCut keypoint files (also Anipose ``pose-2d`` files, which are DeepLabCut h5).

Both the ``.csv`` and the ``.h5`` (a pandas table under the key ``df_with_missing``) hold one
column per (scorer, [individual,] bodypart, coordinate) with coordinates ``x``, ``y`` and, for
predictions, ``likelihood``; rows are frames (an integer index) or labelled images (a path whose
last number is the frame). Hand labels have no likelihood: their score is 1.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from videotrack.errors import VideoTrackError
from videotrack.io.keypoints import KeypointTracks, make_tracks

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")

#: The last run of digits in a labelled image's name (``img0042.png`` -> 42).
_DIGITS = re.compile(r"(\d+)(?!.*\d)")
_UNIQUE = "single"  # multi-animal DeepLabCut's pseudo-individual of the unique bodyparts


def read(path: Path, individual: str | int | None = None) -> KeypointTracks:
    """Read a DeepLabCut ``.csv`` or ``.h5`` file (see the module doc)."""
    if Path(path).suffix.lower() == ".csv":
        columns, index, values = _read_csv(path)
    else:
        columns, index, values = _read_h5(path)
    return from_columns(columns, index, values, path, individual)


def _frame_numbers(index: list, path) -> np.ndarray:
    """Frame numbers from the row labels: integers, or the last number of an image name."""
    frames = []
    for i, label in enumerate(index):
        if isinstance(label, tuple):
            label = label[-1]
        if isinstance(label, (int, np.integer)):
            frames.append(int(label))
            continue
        text = str(label).strip()
        if text.lstrip("-").isdigit():
            frames.append(int(text))
            continue
        m = _DIGITS.search(Path(text).name)
        frames.append(int(m.group(1)) if m else i)
    frames = np.asarray(frames, dtype=np.int64)
    if len(np.unique(frames)) != len(frames):  # image names without distinct numbers
        frames = np.arange(len(index), dtype=np.int64)
    return frames


def from_columns(columns: list[tuple], index: list, values: np.ndarray, path,
                 individual: str | int | None = None) -> KeypointTracks:
    """Keypoints from DeepLabCut's columns ((scorer, [individual,] bodypart, coord) tuples)."""
    if not columns:
        raise VideoTrackError("no keypoint columns", file=path)
    multi = len(columns[0]) == 4
    if len(columns[0]) not in (3, 4):
        raise VideoTrackError(f"expected 3 or 4 header levels (scorer, [individuals,] "
                              f"bodyparts, coords), got {len(columns[0])}", file=path)
    col = {}  # (individual, bodypart, coord) -> column
    for j, c in enumerate(columns):
        ind, bp, coord = (c[1], c[2], c[3]) if multi else ("", c[1], c[2])
        col[(str(ind), str(bp), str(coord).lower())] = j
    individuals = list(dict.fromkeys(k[0] for k in col))
    animals = [i for i in individuals if i != _UNIQUE] or individuals
    chosen = _choose(animals, individual, path)
    parts = list(dict.fromkeys(k[1] for k in col if k[0] in (chosen, _UNIQUE)))
    owner = {bp: chosen if (chosen, bp, "x") in col else _UNIQUE for bp in parts}

    def block(ind_of):  # (n_frames, n_kp, 3) x, y, score of the given owner per bodypart
        out = np.full((len(index), len(parts), 3), np.nan)
        for k, bp in enumerate(parts):
            ind = ind_of(bp)
            if (ind, bp, "x") not in col or (ind, bp, "y") not in col:
                continue
            out[:, k, 0] = values[:, col[(ind, bp, "x")]]
            out[:, k, 1] = values[:, col[(ind, bp, "y")]]
            lik = col.get((ind, bp, "likelihood"))
            out[:, k, 2] = values[:, lik] if lik is not None else 1.0
        return out

    missing = [bp for bp in parts if (owner[bp], bp, "y") not in col]
    if missing:
        raise VideoTrackError(f"bodypart {missing[0]!r} has no 'y' column", file=path)
    main = block(owner.get)
    others = [block(lambda bp, o=o: o) for o in animals if o != chosen]
    candidates = np.stack(others, axis=1) if others else None
    return make_tracks(parts, main[..., :2], main[..., 2], _frame_numbers(index, path), path,
                       candidates=candidates, individual=chosen or None,
                       images=_labels_images(index))


def _labels_images(index: list) -> bool:
    """Whether the row labels name images (``labeled-data/video/img0042.png``): hand labels
    of picked frames, not a video's consecutive frames."""
    def is_image(label) -> bool:
        if isinstance(label, tuple):
            label = "/".join(str(p) for p in label)
        return Path(str(label)).suffix.lower() in _IMAGE_SUFFIXES

    return bool(index) and all(is_image(label) for label in index)


def _choose(animals: list[str], individual, path) -> str:
    if individual is None:
        return animals[0]
    if isinstance(individual, (int, np.integer)) or str(individual).isdigit():
        i = int(individual)
        if not 0 <= i < len(animals):
            raise VideoTrackError(f"individual {i} out of range (the file has {len(animals)}: "
                                  f"{', '.join(animals) or 'one unnamed'})", file=path,
                                  field="individual")
        return animals[i]
    if str(individual) not in animals:
        raise VideoTrackError(f"no individual {individual!r} (the file has "
                              f"{', '.join(a for a in animals if a) or 'one unnamed'})",
                              file=path, field="individual")
    return str(individual)


def _read_csv(path):
    """(columns, index, values) of a DeepLabCut CSV, with line numbers in errors."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise VideoTrackError(f"cannot read: {e}", file=path) from None
    header = []
    for row in rows:
        header.append(row)
        if not row or row[0].strip().lower() == "coords" or len(header) == 4:
            break
    names = [r[0].strip().lower() if r else "" for r in header]
    if not names or names[0] != "scorer" or names[-1] != "coords":
        raise VideoTrackError("not a DeepLabCut CSV: expected header rows scorer, "
                              "[individuals,] bodyparts, coords", file=path, line=1)
    first = header[0]
    n_index = next((j for j in range(1, len(first)) if first[j].strip()), len(first))
    width = len(first)
    for ln, r in enumerate(header, 1):
        if len(r) != width:
            raise VideoTrackError(f"{len(r)} columns, the first header row has {width}",
                                  file=path, line=ln)
    columns = [tuple(r[j].strip() for r in header) for j in range(n_index, width)]
    index, values = [], []
    for ln, r in enumerate(rows[len(header):], len(header) + 1):
        if not any(c.strip() for c in r):
            continue
        if len(r) != width:
            raise VideoTrackError(f"{len(r)} columns, the header has {width}", file=path,
                                  line=ln)
        label = tuple(r[:n_index]) if n_index > 1 else r[0]
        index.append(label)
        vals = []
        for j in range(n_index, width):
            text = r[j].strip()
            try:
                vals.append(float(text) if text else np.nan)
            except ValueError:
                bp, coord = columns[j - n_index][-2:]
                raise VideoTrackError(f"not a number: {text!r}", file=path, line=ln,
                                      field=f"{bp} {coord}") from None
        values.append(vals)
    if not index:
        raise VideoTrackError("no frames", file=path)
    return columns, index, np.asarray(values, dtype=np.float64)


def _read_h5(path):
    """(columns, index, values) of a DeepLabCut h5 (a pandas table written by DataFrame.to_hdf)."""
    try:
        import pandas as pd
    except ImportError:  # pragma: no cover - pandas is a dependency
        raise VideoTrackError("reading DeepLabCut .h5 needs pandas and tables", file=path) \
            from None
    try:
        with pd.HDFStore(path, mode="r") as store:
            keys = store.keys()
            key = "/df_with_missing" if "/df_with_missing" in keys else (keys or [None])[0]
            if key is None:
                raise VideoTrackError("not a DeepLabCut h5: no pandas table in it", file=path)
            df = store[key]
    except VideoTrackError:
        raise
    except ImportError as e:
        raise VideoTrackError(f"reading DeepLabCut .h5 needs the 'tables' package ({e})",
                              file=path) from None
    except Exception as e:  # pandas/tables raise many types for a foreign or broken file
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise VideoTrackError(f"not a DeepLabCut h5 ({msg})", file=path) from None
    if not isinstance(df, pd.DataFrame) or df.columns.nlevels not in (3, 4):
        raise VideoTrackError("not a DeepLabCut h5: expected a table with 3 or 4 column "
                              "levels (scorer, [individuals,] bodyparts, coords)", file=path)
    try:
        values = df.to_numpy(dtype=np.float64)
    except (TypeError, ValueError):
        raise VideoTrackError("not a DeepLabCut h5: non-numeric columns", file=path) from None
    if not len(df):
        raise VideoTrackError("no frames", file=path)
    return list(df.columns), list(df.index), values


def _frame(tracks: KeypointTracks, scorer: str):
    """DeepLabCut's DataFrame of the keypoints: x, y, likelihood per bodypart, frame index."""
    import pandas as pd

    cols = pd.MultiIndex.from_product([[scorer], list(tracks.names), ["x", "y", "likelihood"]],
                                      names=["scorer", "bodyparts", "coords"])
    values = np.concatenate([tracks.xy, tracks.score[..., None]], axis=2)
    return pd.DataFrame(values.reshape(tracks.n_frames, -1), index=tracks.frames, columns=cols)


def write(path, tracks: KeypointTracks, scorer: str = "videotrack") -> None:
    """Write keypoints as a DeepLabCut file (``.csv`` or ``.h5``, by the suffix), which
    DeepLabCut, Anipose and ``movement.io.load_poses.from_dlc_file`` read; missing points are
    empty (NaN) with an empty likelihood."""
    from kinematics.fileio import atomic_write
    from videotrack.io._files import atomic_path

    df = _frame(tracks, scorer)
    if Path(path).suffix.lower() == ".csv":
        with atomic_write(path) as fh:
            df.to_csv(fh)
    else:
        with atomic_path(path) as tmp:
            df.to_hdf(tmp, key="df_with_missing", format="table", mode="w")
