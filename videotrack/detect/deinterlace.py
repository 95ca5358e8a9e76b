"""De-interlacing: splitting each video frame into its two fields (half-frames).

An interlaced camera exposes the even rows (the *top* field, parity 0) and the odd rows (the
*bottom* field, parity 1) at different times, half a frame apart; the paper splits every frame
into these half-frames, which doubles the frame rate (Fig. 1). ``field_order`` says which
field was exposed first: "top" (parity 0 first) or "bottom" (parity 1 first; usual for PAL DV).

Coordinates. A half-frame row ``j`` of parity ``p`` is full-frame row ``2 j + p``, so a
detection at half-frame ``y_half`` lies at full-frame ``y = 2 y_half + p`` (x is unchanged).
With line doubling the half-frame is stretched to full height, either by repeating each row
("repeat": doubled rows 2j and 2j+1 both show half row j, whose centre is doubled y = 2j + 0.5)
or by linear interpolation ("linear": doubled row i samples half row i/2 - 0.25, OpenCV's resize
convention); both give ``y = y_doubled - 0.5 + p``. Detections are always reported in
full-frame coordinates, so one camera calibration serves both fields.

The functions accept an image whose first row is full-frame row ``row0`` (the top of a region
of interest); parity always refers to full-frame rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from videotrack.errors import VideoTrackError
from videotrack.project.config import VIDEO


@dataclass(frozen=True)
class Deinterlace:
    """How frames are split in time.

    Parameters
    ----------
    mode : {"none", "fields"}
        "none" processes whole frames; "fields" splits each frame into two half-frames.
    field_order : {"top", "bottom"}
        Field exposed first (only used with "fields").
    line_doubling : {"none", "repeat", "linear"}
        Stretch half-frames to full height before filtering (only used with "fields").
    """

    mode: str = "none"
    field_order: str = "top"
    line_doubling: str = "none"

    def __post_init__(self) -> None:
        for name in ("mode", "field_order", "line_doubling"):
            key = VIDEO.key("deinterlace" if name == "mode" else name)
            if getattr(self, name) not in key.choices:
                raise VideoTrackError(
                    f"must be one of {', '.join(map(repr, key.choices))}, got "
                    f"{getattr(self, name)!r}",
                    field=f"video.{key.name}",
                )

    @property
    def parities(self) -> tuple[int | None, ...]:
        """Field parities in the order of exposure; ``(None,)`` for whole frames."""
        if self.mode == "none":
            return (None,)
        return (0, 1) if self.field_order == "top" else (1, 0)

    @property
    def fields_per_frame(self) -> int:
        return len(self.parities)

    def frame_rate(self, fps: float) -> float:
        """Rate of the detection records: ``fps`` or, with fields, twice that."""
        return fps * self.fields_per_frame

    def to_dict(self) -> dict:
        return {"mode": self.mode, "field_order": self.field_order,
                "line_doubling": self.line_doubling}

    def first_row(self, parity: int | None, row0: int = 0) -> int:
        """Index, within an image starting at full-frame row ``row0``, of its first row of
        ``parity`` (0 for whole frames)."""
        return 0 if parity is None else (parity - row0) % 2

    def field_image(self, image: np.ndarray, parity: int | None, row0: int = 0) -> np.ndarray:
        """The rows of ``image`` of the given parity (a view, no copy), line-doubled if set.

        Parameters
        ----------
        image : ndarray, shape (h, w) or (h, w, c)
            Image whose first row is full-frame row ``row0``.
        parity : int or None
            0 even (top) field, 1 odd (bottom) field, None the whole image.

        Returns
        -------
        ndarray, shape (ceil((h - r) / 2), w[, c]) for a field (r = its first row), twice the
        rows when line-doubled, or ``image`` itself for parity None.
        """
        if parity is None:
            return image
        half = image[self.first_row(parity, row0)::2]
        if self.line_doubling == "none":
            return half
        interp = cv2.INTER_NEAREST if self.line_doubling == "repeat" else cv2.INTER_LINEAR
        return cv2.resize(half, (half.shape[1], 2 * half.shape[0]), interpolation=interp)

    def to_full_y(self, y, parity: int | None, row0: int = 0):
        """Map y in a :meth:`field_image` back to y in the image it was taken from."""
        if parity is None:
            return y
        r = self.first_row(parity, row0)
        if self.line_doubling == "none":
            return 2.0 * np.asarray(y, dtype=float) + r
        return np.asarray(y, dtype=float) - 0.5 + r

    def from_full_y(self, y, parity: int | None, row0: int = 0):
        """Inverse of :meth:`to_full_y`."""
        if parity is None:
            return y
        r = self.first_row(parity, row0)
        if self.line_doubling == "none":
            return (np.asarray(y, dtype=float) - r) / 2.0
        return np.asarray(y, dtype=float) + 0.5 - r


#: Whole frames, no de-interlacing.
NO_DEINTERLACE = Deinterlace()
