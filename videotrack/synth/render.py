"""Render round markers at known sub-pixel positions: the planted answer for detection tests.

Pixel convention (the project's, as OpenCV): pixel ``frame[i, j]`` is the unit square centred
on the point ``(x, y) = (j, i)``, i.e. it covers ``[j - 0.5, j + 0.5] × [i - 0.5, i + 0.5]``; the
origin is the centre of the top-left pixel. A marker at ``(x, y)`` is a disc (or Gaussian spot)
centred on that point, and each pixel gets the marker's intensity times the fraction of its area
the marker covers (a box-filtered, anti-aliased image), computed by supersampling. The intensity-
weighted centroid of such an image is therefore the planted point up to quantisation and noise.

The synthetic-video generator and the tests both render through :func:`render_markers`.
"""

from __future__ import annotations

import numpy as np

#: Sub-samples per pixel side used to integrate marker coverage over each pixel.
SUPERSAMPLE = 16


def render_markers(
    shape,
    points_xy,
    diameter: float = 4.0,
    intensity=200.0,
    background=20.0,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | int | None = None,
    *,
    profile: str = "disc",
) -> np.ndarray:
    """Render anti-aliased markers into a new uint8 frame.

    Parameters
    ----------
    shape : tuple of int
        ``(height, width)`` for a grey frame or ``(height, width, channels)`` for a colour one
        (channels in OpenCV's BGR order).
    points_xy : array_like, shape (n, 2)
        Marker centres in pixel coordinates (origin at the top-left pixel's centre). Rows with a
        NaN are skipped (an occluded marker); markers partly outside the frame are clipped.
    diameter : float
        Disc diameter in pixels; for ``profile="gaussian"`` the full width at half maximum.
    intensity : float or array_like
        Grey levels added at full coverage. Grey frames: a scalar or one value per marker,
        shape (n,). Colour frames: a scalar, one value per channel, shape (channels,), or one
        row per marker, shape (n, channels). Overlapping markers add.
    background : float or array_like
        Background grey level (a scalar, or one value per channel).
    noise_sigma : float
        Standard deviation of additive Gaussian noise in grey levels, drawn from ``rng``.
    rng : numpy.random.Generator or int, optional
        Random generator or seed; required when ``noise_sigma > 0`` (randomness is explicit).
    profile : {"disc", "gaussian"}
        Marker shape: a uniformly bright disc or a Gaussian spot.

    Returns
    -------
    frame : ndarray of uint8, shape ``shape``
        ``round(background + intensity * coverage + noise)`` clipped to 0..255.
    """
    shape = tuple(int(s) for s in shape)
    if len(shape) not in (2, 3):
        raise ValueError(f"shape must be (h, w) or (h, w, channels), got {shape}")
    if profile not in ("disc", "gaussian"):
        raise ValueError(f"profile must be 'disc' or 'gaussian', got {profile!r}")
    if diameter <= 0:
        raise ValueError(f"diameter must be positive, got {diameter}")
    points = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    channels = shape[2] if len(shape) == 3 else 1
    gains = _per_marker(intensity, len(points), channels)

    canvas = np.zeros((shape[0], shape[1], channels))
    if profile == "disc":
        reach = diameter / 2.0
    else:
        sigma = diameter / (2.0 * np.sqrt(2.0 * np.log(2.0)))
        reach = 4.0 * sigma  # the spot is below 1e-3 of its peak beyond 4 sigma
    # Sub-sample offsets inside a pixel, symmetric about its centre.
    sub = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
    for (px, py), gain in zip(points, gains, strict=True):
        if not (np.isfinite(px) and np.isfinite(py)):
            continue
        x0, x1 = max(int(np.floor(px - reach)) - 1, 0), min(int(np.ceil(px + reach)) + 2, shape[1])
        y0, y1 = max(int(np.floor(py - reach)) - 1, 0), min(int(np.ceil(py + reach)) + 2, shape[0])
        if x0 >= x1 or y0 >= y1:
            continue
        # Sample positions relative to the marker centre, shape (rows, S, cols, S).
        dy = (np.arange(y0, y1)[:, None] + sub[None, :] - py)[:, :, None, None]
        dx = (np.arange(x0, x1)[:, None] + sub[None, :] - px)[None, None, :, :]
        r2 = dx * dx + dy * dy
        if profile == "disc":
            value = (r2 <= reach * reach).astype(float)
        else:
            value = np.exp(-r2 / (2.0 * sigma * sigma))
        coverage = value.mean(axis=(1, 3))
        canvas[y0:y1, x0:x1, :] += coverage[:, :, None] * gain[None, None, :]

    canvas += np.broadcast_to(np.asarray(background, dtype=float), (channels,))
    if noise_sigma > 0:
        if rng is None:
            raise ValueError("noise_sigma > 0 needs an explicit rng (seed or Generator)")
        canvas += np.random.default_rng(rng).normal(0.0, noise_sigma, canvas.shape)
    frame = np.clip(np.rint(canvas), 0, 255).astype(np.uint8)
    return frame if len(shape) == 3 else frame[:, :, 0]


def _per_marker(intensity, n: int, channels: int) -> np.ndarray:
    """Intensity as an (n, channels) array, following :func:`render_markers`' rules."""
    value = np.asarray(intensity, dtype=float)
    if value.ndim == 0:
        return np.full((n, channels), float(value))
    if channels == 1 and value.shape == (n,):
        return value[:, None]
    if channels > 1 and value.shape == (channels,):
        return np.broadcast_to(value, (n, channels))
    if value.shape == (n, channels):
        return value
    raise ValueError(
        f"intensity of shape {value.shape} does not fit {n} markers with {channels} channel(s)"
    )
