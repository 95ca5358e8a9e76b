"""Whether the views agree in 3D: how close each detection lies to an epipolar line of the
other views' detections, against how close it lies by chance (a set-up check before fitting).

Under a right calibration a marker seen in views a and b lies on the epipolar line of its own
image in the other view, to within the detection noise; under a wrong one (a mis-scaled or
swapped camera, swapped views) only by chance. Chance is measured on the same detections: the
distance to the lines of the other view's detections in another frame of the sample, so that
the reference grows with the clutter and the image size alike.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from kinematics.cameras import Camera
from kinematics.observe.cloud import fundamental, ideal_pixels, linear_matrix
from kinematics.observe.observations import Observations


class PairAgreement(NamedTuple):
    """How the detections of view ``a`` agree with view ``b``'s through their cameras."""

    a: int  # view indices
    b: int
    distance_px: float  # median over a's detections of the nearest epipolar line of b's
    chance_px: float  # the same to b's detections of another frame
    excess: float  # share of a's detections nearer b's lines than chance puts them, less chance's
    n: int  # detections measured


def view_agreement(cameras: Sequence[Camera], obs: Observations, frames: np.ndarray,
                   shown: np.ndarray | None = None) -> list[PairAgreement]:
    """:class:`PairAgreement` of every ordered pair of views (a, b) with epipolar geometry
    (cameras that do not share a centre or a direction) on ``frames`` of unlabelled or
    labelled ``obs`` (labelled: each keypoint against its own label's line), where every
    marker a shows b shows too (``shown``: (n_views, n_markers) bool; None: all).

    ``excess`` is robust to clutter, where the median is not: the share of a's detections
    whose nearest line of b in the same frame is less than half as far as in another frame,
    less the same share between two other frames (what chance gives). A right calibration's
    markers all count, ghosts as often as chance: it is about the share of a's detections
    that are real markers, and about 0 for cameras that do not fit. Pairs with fewer than 8
    detections measured are left out."""
    frames = np.asarray(frames, np.int64)
    nv = obs.n_views
    if nv < 2 or len(frames) < 3:
        return []
    views = [[None] * len(frames) for _ in range(nv)]
    for k, f in enumerate(frames):
        for v, pts in enumerate(obs.frame_views(int(f))):
            views[v][k] = ideal_pixels(cameras[v], np.asarray(pts, float)) if len(pts) else pts
    mats = [linear_matrix(c) for c in cameras]
    n = len(frames)
    shifts = (max(1, n // 2), max(1, n // 3))  # two other frames, for chance and its chance
    out = []
    for a in range(nv):
        for b in range(nv):
            if a == b or (shown is not None and (shown[a] & ~shown[b]).any()):
                continue
            fmat = fundamental(mats[a], mats[b])
            if not fmat.any():
                continue
            same, one, two = [], [], []
            for k in range(n):
                pa = views[a][k]
                same.append(_nearest_line(fmat, pa, views[b][k], obs.labelled))
                one.append(_nearest_line(fmat, pa, views[b][(k + shifts[0]) % n], obs.labelled))
                two.append(_nearest_line(fmat, pa, views[b][(k + shifts[1]) % n], obs.labelled))
            same, one, two = np.concatenate(same), np.concatenate(one), np.concatenate(two)
            keep = np.isfinite(same) & np.isfinite(one) & np.isfinite(two)
            if keep.sum() < 8:
                continue
            same, one, two = same[keep], one[keep], two[keep]
            excess = float(np.mean(same < 0.5 * one) - np.mean(two < 0.5 * one))
            out.append(PairAgreement(a, b, float(np.median(same)), float(np.median(one)),
                                     excess, int(keep.sum())))
    return out


def _nearest_line(fmat: np.ndarray, pa: np.ndarray, pb: np.ndarray, labelled: bool
                  ) -> np.ndarray:
    """Per point of ``pa``: the distance (px in b) of the nearest point of ``pb`` to its
    epipolar line in b (labelled: of the point of the same index); NaN where none."""
    if len(pa) == 0:
        return np.zeros(0)
    if len(pb) == 0:
        return np.full(len(pa), np.nan)
    lines = np.c_[pa, np.ones(len(pa))] @ fmat.T  # (n_a, 3) lines in b
    norm = np.hypot(lines[:, 0], lines[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        if labelled:
            n = min(len(pa), len(pb))
            d = np.full(len(pa), np.nan)
            d[:n] = np.abs(np.einsum("ij,ij->i", lines[:n, :2], pb[:n]) + lines[:n, 2]
                           ) / norm[:n]
            return d
        d = np.abs(lines[:, :2] @ pb.T + lines[:, 2:]) / norm[:, None]
        return np.where(np.isfinite(d), d, np.inf).min(axis=1)  # NaN rows: no partner
