"""Fixtures of the detection tests: small videos with markers planted at known positions."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from videotrack.synth.render import render_markers

#: Frame size of the planted-marker videos: two 80 x 60 views side by side.
WIDTH, HEIGHT = 160, 60
N_FRAMES = 12


def write_video(path: Path, frames, fourcc: str = "FFV1", fps: float = 25.0) -> Path:
    """Write uint8 frames (grey or BGR) with OpenCV; FFV1 is lossless."""
    frames = list(frames)
    h, w = frames[0].shape[:2]
    colour = frames[0].ndim == 3
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h),
                             isColor=colour)
    assert writer.isOpened(), f"cannot write {fourcc} video"
    for f in frames:
        writer.write(f)
    writer.release()
    return path


def write_sequence(folder: Path, frames, ext: str = ".png", name: str = "img{}") -> Path:
    """Write frames as numbered images (unpadded numbers: natural sort is needed)."""
    folder.mkdir(parents=True, exist_ok=True)
    for i, f in enumerate(frames):
        assert cv2.imwrite(str(folder / (name.format(i) + ext)), f)
    return folder


def planted_scene(n_frames: int = N_FRAMES, seed: int = 3):
    """Marker positions of a two-view scene, in frame coordinates.

    Returns ``(left, right)``, each of shape (n_frames, 3, 2): three well-separated markers per
    view moving by sub-pixel steps, the left view in x 0..79, the right in x 80..159.
    """
    rng = np.random.default_rng(seed)
    base = np.array([[15.3, 14.6], [40.2, 40.7], [62.8, 20.1]])
    step = rng.uniform(-0.6, 0.6, (3, 2))
    t = np.arange(n_frames)[:, None, None]
    left = base[None] + t * step[None]
    right = left[:, ::-1] * [1, 1] + [80.0, 0.0]
    right[:, :, 1] = HEIGHT - 1 - right[:, :, 1]  # a different layout in the right view
    return left, right


def render_scene(left, right, noise: float = 1.0, seed: int = 7):
    """Grey frames, shape (n, HEIGHT, WIDTH), of :func:`planted_scene` markers."""
    rng = np.random.default_rng(seed)
    return [render_markers((HEIGHT, WIDTH), np.concatenate([a, b]), 4.0, 200.0, 20.0, noise,
                           rng) for a, b in zip(left, right, strict=True)]


@pytest.fixture
def scene():
    return planted_scene()


@pytest.fixture
def scene_video(tmp_path, scene):
    """An FFV1 video of :func:`planted_scene`; returns (path, left, right)."""
    left, right = scene
    return write_video(tmp_path / "scene.avi", render_scene(left, right)), left, right


PROJECT = """\
[video]
path = "scene.avi"

[[views]]
name = "left"
roi = [0, 0, 80, 60]

[[views]]
name = "right"
roi = [80, 0, 80, 60]
flip_x = true

[[filters.steps]]
type = "threshold"
value = 90

[markers]
min_area = 3
"""


@pytest.fixture
def project(tmp_path, scene_video):
    """A project file for :func:`scene_video`; returns (config path, left, right)."""
    _, left, right = scene_video
    config = tmp_path / "project.toml"
    config.write_text(PROJECT)
    return config, left, right


@pytest.fixture
def video_writer():
    """:func:`write_video` (helpers are handed to tests as fixtures)."""
    return write_video


@pytest.fixture
def sequence_writer():
    """:func:`write_sequence`."""
    return write_sequence


@pytest.fixture
def scene_renderer():
    """:func:`render_scene`."""
    return render_scene
