"""Checks that name a camera that looks wrong: two cameras that are one (a block of a camera
file copied over another), and a camera whose reprojection errors stand out from the
others'. Each gives one-line warnings for the commands that make or use cameras."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from kinematics.cameras.models import pack_cameras

#: A camera whose median reprojection error exceeds this many times the median of the other
#: cameras' medians (and OUTLIER_MIN_PX) is named.
OUTLIER_FACTOR = 3.0
OUTLIER_MIN_PX = 2.0


def _named(cameras) -> list[tuple[str, object]]:
    if isinstance(cameras, Mapping):
        return list(cameras.items())
    return [(c.name, c) for c in cameras]


def identical_cameras(cameras: Mapping[str, object] | Sequence) -> list[tuple[str, str]]:
    """Pairs of cameras with the same model, lens and pose (to 1e-9): one of each is wrong,
    as two cameras cannot stand in one place looking one way."""
    named = _named(cameras)
    packed = [pack_cameras([c]) for _, c in named]
    pairs = []
    for i in range(len(named)):
        for j in range(i + 1, len(named)):
            if all(np.allclose(a, b, rtol=1e-9, atol=1e-12)
                   for a, b in zip(packed[i], packed[j], strict=True)):
                pairs.append((named[i][0], named[j][0]))
    return pairs


def outlying_cameras(median_px: Mapping[str, float]) -> list[str]:
    """Cameras whose median reprojection error (px) stands out from the others'
    (:data:`OUTLIER_FACTOR`, :data:`OUTLIER_MIN_PX`)."""
    out = []
    for name, e in median_px.items():
        others = [v for k, v in median_px.items() if k != name and np.isfinite(v)]
        if others and np.isfinite(e) and e > OUTLIER_MIN_PX and \
                e > OUTLIER_FACTOR * float(np.median(others)):
            out.append(name)
    return out


def camera_warnings(cameras, median_px: Mapping[str, float] | None = None) -> list[str]:
    """One-line warnings: identical cameras, and (given each camera's median reprojection
    error) the cameras whose errors stand out."""
    found = [f"cameras {a} and {b} are identical (the same lens and pose): one of them is "
             "wrong, e.g. a block of the camera file copied over another"
             for a, b in identical_cameras(cameras)]
    if median_px:
        others = {n: e for n, e in median_px.items()}
        for name in outlying_cameras(median_px):
            rest = float(np.median([e for n, e in others.items() if n != name]))
            times = f"{median_px[name] / rest:.0f} x" if rest > 0 else "above"
            found.append(f"camera {name} reprojects with a median error of "
                         f"{median_px[name]:.1f} px, {times} the other cameras' "
                         f"({rest:.1f} px): its calibration (or its keypoints' camera) may "
                         "be wrong")
    return found
