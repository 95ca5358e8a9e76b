"""The project dialog's filter preview and paths (no Qt)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


# -- project dialog -------------------------------------------------------------------------
@dataclass(frozen=True)
class ViewPreview:
    """One view of the filter preview: the view image, the filter chain's mask (both in view
    orientation and size) and the detected centroids."""

    image: np.ndarray  # (h, w) or (h, w, 3) uint8
    mask: np.ndarray  # (h, w) uint8, non-zero for marker pixels
    points: np.ndarray  # (n, 2)

    def overlay(self, colour=(255, 40, 220)) -> np.ndarray:
        """RGB picture: the image dimmed to grey with the mask's pixels in ``colour``."""
        grey = self.image if self.image.ndim == 2 else self.image.mean(axis=2)
        rgb = np.repeat((0.6 * grey)[..., None], 3, axis=2).astype(np.uint8)
        rgb[self.mask > 0] = colour
        return rgb


def detection_preview(detector, frame_set) -> list[ViewPreview]:
    """What the filter chain makes of one frame, per view (the project dialog's preview).

    Parameters
    ----------
    detector : videotrack.detect.run.FrameDetector
    frame_set : tuple of ndarray
        One frame per video (:meth:`videotrack.detect.video.VideoSet.read`).

    Returns
    -------
    list of ViewPreview
        Per view: the view image, the mask (fields of de-interlaced video are stretched back
        to full height) and the centroids of the first field.
    """
    _, points, _ = detector(frame_set)[0]
    out = []
    for plane, chain, pts in zip(detector.planes[0], detector.filters[0], points, strict=True):
        frame = frame_set[plane.view.video]
        mask, _ = chain.run(plane.extract(frame))
        h = plane.view.size[1]
        if mask.shape[0] != h:  # one field: repeat its rows
            mask = np.repeat(mask, -(-h // mask.shape[0]), axis=0)[:h]
        out.append(ViewPreview(np.ascontiguousarray(plane.view.cut(frame)),
                               np.ascontiguousarray(plane.view.flip_image(mask)), pts))
    return out


def relative_path(path, base) -> str:
    """``path`` relative to the folder ``base`` when below it, else absolute (POSIX form)."""
    from pathlib import Path

    p, b = Path(path).absolute(), Path(base).absolute()
    try:
        return p.relative_to(b).as_posix()
    except ValueError:
        return p.as_posix()


