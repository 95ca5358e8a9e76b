"""The filter chain: view image → mask of marker pixels (+ the grey image for centroids).

The steps and their keys are declared in :data:`videotrack.project.config.FILTER_STEPS` (the single
source of truth, documented in ``docs/detection.md``). Each step takes and gives one *kind* of
image: ``colour`` (BGR), ``grey`` or ``mask`` (0/255); the chain must end with a mask. The grey
image entering the first masking step (threshold, otsu, adaptive, hsv_range) is kept as the
weight image of the intensity-weighted centroids, so background subtraction, channel choice,
masks and inversion before the threshold also shape the centroids.

A chain is compiled once per :class:`~videotrack.detect.views.Plane` (view × field): masks are
rasterised into the plane's orientation and the background median is computed from frames
sampled evenly over the whole video, so the same settings always give the same result whatever
frame range is processed. Every operation is an OpenCV call on uint8 images.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np

from videotrack.errors import VideoTrackError
from videotrack.project.config import FILTER_STEPS

_MASKING = ("threshold", "otsu", "adaptive", "hsv_range")
_CHANNELS = {"blue": 0, "green": 1, "red": 2}
_SHAPES = {"ellipse": cv2.MORPH_ELLIPSE, "rect": cv2.MORPH_RECT, "cross": cv2.MORPH_CROSS}
_MORPH = {"open": cv2.MORPH_OPEN, "close": cv2.MORPH_CLOSE}

#: step type → (kinds it accepts, kind it gives; None: the kind it got)
_KINDS = {
    "channel": (("colour",), "grey"),
    "grey": (("colour", "grey"), "grey"),
    "hsv_range": (("colour",), "mask"),
    "background": (("grey",), "grey"),
    "invert": (("grey", "mask"), None),
    "threshold": (("grey",), "mask"),
    "otsu": (("grey",), "mask"),
    "adaptive": (("grey",), "mask"),
    "erode": (("grey", "mask"), None),
    "dilate": (("grey", "mask"), None),
    "open": (("grey", "mask"), None),
    "close": (("grey", "mask"), None),
    "mask": (("colour", "grey", "mask"), None),
}


class FilterChain:
    """An ordered, validated list of filter steps.

    Parameters
    ----------
    steps : sequence of mapping
        Step tables as in the project file, e.g. ``[{"type": "threshold", "value": 100}]``.
    file : path, optional
        Config file the steps come from (for error messages).
    base : path, optional
        Folder relative mask-image paths resolve against.

    Raises
    ------
    VideoTrackError
        Unknown step or key, absurd value, or steps in an order that cannot work (e.g. a
        threshold after the image is already a mask); the field is ``filters.steps[i]...``.
    """

    def __init__(self, steps: Sequence[Mapping], *, file=None, base=None) -> None:
        self.file = file
        self.steps = tuple(
            FILTER_STEPS.validate(step, where=f"filters.steps[{i}]", file=file, base=base)
            for i, step in enumerate(steps)
        )
        if not self.steps:
            raise VideoTrackError("no filter steps; add [[filters.steps]] ending in a threshold",
                                  file=file, field="filters.steps")
        self.needs_colour = any(s["type"] in ("channel", "grey", "hsv_range") for s in self.steps)
        kind = "colour" if self.needs_colour else "grey"
        self.weights_at = None
        for i, step in enumerate(self.steps):
            accepts, gives = _KINDS[step["type"]]
            if kind not in accepts:
                hint = {"mask": "the image is already a mask",
                        "colour": "the image is still in colour: add a 'grey' or 'channel' step "
                                  "first",
                        "grey": "the image is already grey"}[kind]
                raise VideoTrackError(f"{step['type']!r} cannot take a {kind} image: {hint}",
                                      file=file, field=f"filters.steps[{i}].type")
            if gives == "mask" and self.weights_at is None:
                self.weights_at = i
            kind = gives or kind
        if kind != "mask":
            raise VideoTrackError(
                "the chain must end with a mask: add a threshold, otsu, adaptive or hsv_range "
                "step", file=file, field="filters.steps")

    @classmethod
    def from_config(cls, config) -> FilterChain:
        """The chain of a loaded :class:`~videotrack.project.config.Config`."""
        return cls(config["filters"]["steps"], file=config.path, base=config.folder)

    def __repr__(self) -> str:
        return f"FilterChain({[s['type'] for s in self.steps]})"

    def to_settings(self) -> list[dict]:
        """JSON-able description, as stored in detections and hashed; a mask image is
        represented by its name and the SHA-256 of its bytes."""
        out = []
        for i, step in enumerate(self.steps):
            entry = dict(step)
            if step.get("image"):
                path = Path(step["image"])
                entry["image"] = path.name
                entry["image_sha256"] = hashlib.sha256(
                    _read_bytes(path, self.file, f"filters.steps[{i}].image")).hexdigest()
            out.append(entry)
        return out

    def check_views(self, names: Sequence[str]) -> None:
        """Raise if a mask step names a view that does not exist."""
        for i, step in enumerate(self.steps):
            if step["type"] == "mask" and step["view"] and step["view"] not in names:
                raise VideoTrackError(
                    f"no view named {step['view']!r} (views: {', '.join(names)})",
                    file=self.file, field=f"filters.steps[{i}].view")

    def compile(self, plane, sample_frames: Callable[[int], Sequence[np.ndarray]] | None = None
                ) -> CompiledFilters:
        """Prepare the chain for one plane (view × field).

        Parameters
        ----------
        plane : videotrack.detect.views.Plane
            Where the images come from; masks are mapped into its orientation.
        sample_frames : callable, optional
            ``sample_frames(n)`` returns ``n`` full frames of the plane's video, sampled evenly
            over the whole video; needed by background steps.
        """
        ops = []
        weights_at = None
        for i, step in enumerate(self.steps):
            t = step["type"]
            if t == "background":
                if sample_frames is None:
                    raise ValueError("a background step needs sample_frames")
                done = CompiledFilters(ops, None, self.needs_colour)
                stack = np.stack([done.run_partial(plane.extract(f))
                                  for f in sample_frames(step["frames"])])
                background = np.rint(np.median(stack, axis=0)).astype(np.uint8)
                ops.append(_background_op(background, step["polarity"]))
            elif t == "mask":
                if step["view"] and step["view"] != plane.view.name:
                    continue
                ops.append(_mask_op(self._mask_image(step, i, plane)))
            elif t == "hsv_range" and getattr(plane.view, "hsv", None) is not None:
                lower, upper = plane.view.hsv  # the view keeps its own colour of markers
                ops.append(_simple_op({**step, "lower": list(lower), "upper": list(upper)}))
            else:
                ops.append(_simple_op(step))
            if i == self.weights_at:
                weights_at = len(ops) - 1
        return CompiledFilters(ops, weights_at, self.needs_colour)

    def _mask_image(self, step: Mapping, i: int, plane) -> np.ndarray:
        """Keep-mask (255 = kept) of a mask step in the plane's orientation."""
        w, h = plane.view.size
        masked = np.zeros((h, w), np.uint8)
        for x, y, rw, rh in step["rects"]:
            masked[y : y + rh, x : x + rw] = 255
        shift = 8  # polygons at 1/256-pixel precision
        for poly in step["polygons"]:
            pts = np.rint(np.asarray(poly, dtype=float) * (1 << shift)).astype(np.int32)
            cv2.fillPoly(masked, [pts], 255, lineType=cv2.LINE_8, shift=shift)
        if step["image"]:
            field = f"filters.steps[{i}].image"
            data = np.frombuffer(_read_bytes(Path(step["image"]), self.file, field), np.uint8)
            image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
            if image is None:
                raise VideoTrackError(f"cannot read mask image {step['image']}",
                                      file=self.file, field=field)
            if image.shape != (h, w):
                raise VideoTrackError(
                    f"mask image is {image.shape[1]}x{image.shape[0]}, view "
                    f"{plane.view.name!r} is {w}x{h}", file=self.file, field=field)
            masked[image > 0] = 255
        keep = masked if step["keep"] else cv2.bitwise_not(masked)
        return np.ascontiguousarray(plane.from_view_image(keep))


class CompiledFilters:
    """The chain prepared for one plane: ``run(image) -> (mask, weights)``."""

    def __init__(self, ops: list, weights_at: int | None, colour: bool) -> None:
        self.ops = ops
        self.weights_at = weights_at
        self.colour = colour

    def run(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Filter a plane image.

        Returns
        -------
        mask : ndarray of uint8, shape (h, w)
            0 background, non-zero marker pixels.
        weights : ndarray of uint8, shape (h, w)
            The grey image the mask was made from (for intensity-weighted centroids).
        """
        img = self._start(image)
        weights = None
        for k, op in enumerate(self.ops):
            if k == self.weights_at:
                weights = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
            img = op(img)
        return img, weights

    def run_partial(self, image: np.ndarray) -> np.ndarray:
        """Apply the ops compiled so far (used while compiling a background step)."""
        img = self._start(image)
        for op in self.ops:
            img = op(img)
        return img

    def _start(self, image: np.ndarray) -> np.ndarray:
        if image.ndim == 3 and not self.colour:
            return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        if image.ndim == 2 and self.colour:
            return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        return image


def _read_bytes(path: Path, file, field: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as err:
        raise VideoTrackError(f"cannot read {path}: {err.strerror}", file=file,
                              field=field) from None


def _background_op(background: np.ndarray, polarity: str):
    if polarity == "brighter":
        return lambda img: cv2.subtract(img, background)
    if polarity == "darker":
        return lambda img: cv2.subtract(background, img)
    return lambda img: cv2.absdiff(img, background)


def _mask_op(keep: np.ndarray):
    return lambda img: cv2.bitwise_and(img, img, mask=keep)


def _simple_op(step: Mapping):
    """The OpenCV call of a step that needs no per-plane data."""
    t = step["type"]
    if t == "channel":
        index = _CHANNELS[step["channel"]]
        return lambda img: cv2.extractChannel(img, index)
    if t == "grey":
        return lambda img: cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
    if t == "hsv_range":
        lower, upper = np.array(step["lower"], np.uint8), np.array(step["upper"], np.uint8)
        if lower[0] <= upper[0]:
            return lambda img: cv2.inRange(cv2.cvtColor(img, cv2.COLOR_BGR2HSV), lower, upper)
        # Hue wraps around (reds): lower..179 or 0..upper.
        lo2, up2 = lower.copy(), upper.copy()
        lo2[0], up2[0] = 0, 179

        def hsv_wrapped(img):
            hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
            return cv2.bitwise_or(cv2.inRange(hsv, lower, up2), cv2.inRange(hsv, lo2, upper))

        return hsv_wrapped
    if t == "invert":
        return cv2.bitwise_not
    if t == "threshold":
        value = step["value"]
        return lambda img: cv2.threshold(img, value, 255, cv2.THRESH_BINARY)[1]
    if t == "otsu":
        return lambda img: cv2.threshold(img, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)[1]
    if t == "adaptive":
        method = (cv2.ADAPTIVE_THRESH_MEAN_C if step["method"] == "mean"
                  else cv2.ADAPTIVE_THRESH_GAUSSIAN_C)
        block, c = step["block_size"], -step["offset"]  # OpenCV keeps src > mean - C
        return lambda img: cv2.adaptiveThreshold(img, 255, method, cv2.THRESH_BINARY, block, c)
    kernel = cv2.getStructuringElement(_SHAPES[step["shape"]], (step["size"], step["size"]))
    n = step["iterations"]
    if t == "erode":
        return lambda img: cv2.erode(img, kernel, iterations=n)
    if t == "dilate":
        return lambda img: cv2.dilate(img, kernel, iterations=n)
    op = _MORPH[t]
    return lambda img: cv2.morphologyEx(img, op, kernel, iterations=n)
