"""Marker detection benchmark: centroid accuracy and throughput on one core.

Run from the repository root::

    python bench/bench_detection.py [--frames 400] [--repeats 3]

Scene: 720 x 576 grey PAL frames holding two 360 x 576 views side by side (the right one
mirrored), five 4-px-diameter markers per view (10 per frame) at random sub-pixel positions,
background 20, marker intensity 200, Gaussian noise sigma = 2 grey levels, rendered
anti-aliased by ``videotrack.synth.render.render_markers``. Filter chain: a global threshold at 100.

(a) accuracy: RMS distance between detected centroids and the planted positions, for the
intensity-weighted centroid (default) and the binary centroid (the mean of the region's pixel
centres, close to the paper's 'center pixel' approach).
(b) throughput with OpenCV, FFmpeg and numba on one thread (cv2.setNumThreads(1), FFmpeg
threads = 1): filtering + regions + centroids on frames already in memory, and the whole
``detect_video`` run including decoding of an FFV1 and an MJPG AVI (and of an FFV1 AVI of
the same scene without noise); decoding alone for scale.
Each throughput is the best of ``--repeats`` runs.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _report import machine, print_table

from videotrack.detect.detections import DetectSettings
from videotrack.detect.filters import FilterChain
from videotrack.detect.markers import MarkerSettings
from videotrack.detect.run import FrameDetector, detect_video
from videotrack.detect.video import VideoSource
from videotrack.detect.views import View
from videotrack.synth.render import render_markers

WIDTH, HEIGHT, PER_VIEW = 720, 576, 5
VIEWS = (View("left", (0, 0, 360, 576)), View("right", (360, 0, 360, 576), flip_x=True))
CHAIN = FilterChain([{"type": "threshold", "value": 100}])


def make_scene(n_frames: int, seed: int = 0, noise: float = 2.0):
    """Frames and planted marker positions (frame coordinates), shape (n, 10, 2)."""
    rng = np.random.default_rng(seed)
    truth = np.empty((n_frames, 2 * PER_VIEW, 2))
    frames = []
    for t in range(n_frames):
        for v, x0 in enumerate((0, 360)):
            # Markers on a jittered grid: at least 40 px apart, never touching.
            cells = rng.choice(8 * 12, PER_VIEW, replace=False)
            cx, cy = cells % 8, cells // 8
            xy = np.c_[x0 + 20 + 40 * cx, 20 + 45 * cy] + rng.uniform(-8, 8, (PER_VIEW, 2))
            truth[t, v * PER_VIEW : (v + 1) * PER_VIEW] = xy
        frames.append(render_markers((HEIGHT, WIDTH), truth[t], 4.0, 200.0, 20.0, noise, rng))
    return frames, truth


def write(path: Path, frames, fourcc: str) -> Path:
    """An AVI of grey frames: FFV1 stores grey; MJPG stores colour (as MJPG cameras do),
    through OpenCV's own encoder at quality 95, which keeps the noise (FFmpeg's MJPEG default
    quantises it away, which would flatter decoding speed; FFmpeg cannot decode OpenCV's grey
    MJPEG)."""
    mjpg = fourcc == "MJPG"
    api = cv2.CAP_OPENCV_MJPEG if mjpg else cv2.CAP_FFMPEG
    params = [cv2.VIDEOWRITER_PROP_QUALITY, 95] if mjpg else [cv2.VIDEOWRITER_PROP_IS_COLOR, 0]
    writer = cv2.VideoWriter(str(path), api, cv2.VideoWriter_fourcc(*fourcc), 25.0,
                             (WIDTH, HEIGHT), params)
    for f in frames:
        writer.write(cv2.cvtColor(f, cv2.COLOR_GRAY2BGR) if mjpg else f)
    writer.release()
    return path


def errors(detections, truth) -> tuple[np.ndarray, int]:
    """Distance of each planted marker to its nearest detection, and the detection count."""
    dist, n_found = [], 0
    for r in range(detections.n_records):
        found = []
        for v, view in enumerate(VIEWS):
            found.append(view.to_frame(detections.points_of(r, v)))
        found = np.concatenate(found)
        n_found += len(found)
        d = np.linalg.norm(found[:, None] - truth[r][None], axis=2)
        dist.append(d.min(axis=0))
    return np.concatenate(dist), n_found


def best_fps(run, n: int, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - t0)
    return n / best


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=400, help="frames in the test videos")
    parser.add_argument("--repeats", type=int, default=3, help="runs per timing (best counts)")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    warnings.simplefilter("error")  # a benchmark run must be clean

    frames, truth = make_scene(args.frames)
    n = len(frames)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        ffv1 = write(Path(tmp) / "bench_ffv1.avi", frames, "FFV1")
        mjpg = write(Path(tmp) / "bench_mjpg.avi", frames, "MJPG")
        # FFV1 decoding cost grows with entropy: noise-free frames (as 'videotrack synth'
        # writes by default) decode about 20x faster than frames with sigma = 2 noise.
        clean = write(Path(tmp) / "bench_ffv1_clean.avi", make_scene(n, noise=0.0)[0], "FFV1")
        settings = DetectSettings(VIEWS, CHAIN, MarkerSettings(min_area=2))
        binary = DetectSettings(VIEWS, CHAIN, MarkerSettings(min_area=2, weighting="binary"))

        # (a) accuracy, from the lossless video (and the lossy MJPG one)
        runs = (("intensity-weighted centroid", ffv1, settings, "<= 0.15 px"),
                ("binary centroid (paper-like)", ffv1, binary, "(paper: 0.43 px)"),
                ("intensity-weighted, from MJPG q95", mjpg, settings, ""))
        for label, path, s, goal in runs:
            det = detect_video(VideoSource(path, threads=1), s)
            err, n_found = errors(det, truth)
            rows.append((f"RMS error, {label}", f"{np.sqrt(np.mean(err**2)):.3f} px", goal))
            if label.startswith("intensity-weighted centroid"):
                rows.append(("max error / markers found",
                             f"{err.max():.3f} px / {n_found} of {truth[:, :, 0].size}", ""))

        # (b) throughput, one core
        detector = FrameDetector(VideoSource(ffv1, threads=1), settings)
        single = [(f,) for f in frames]
        rows.append(("filtering + centroids, decode excluded",
                     f"{best_fps(lambda: [detector(f) for f in single], n, args.repeats):.0f} "
                     "frames/s", ">= 1000 frames/s"))
        videos = (("FFV1", ffv1), ("MJPG", mjpg), ("FFV1, noise-free frames", clean))
        for name, path in videos:
            fps = best_fps(lambda p=path: detect_video(VideoSource(p, threads=1), settings), n,
                           args.repeats)
            rows.append((f"detect_video incl. decoding {name}", f"{fps:.0f} frames/s",
                         ">= 300 frames/s"))
        for name, path in videos:
            fps = best_fps(lambda p=path: sum(1 for _ in VideoSource(p, threads=1).frames(
                reuse=True)), n, args.repeats)
            rows.append((f"decoding alone, {name}", f"{fps:.0f} frames/s", ""))
        sizes = ", ".join(f"{name} {os.path.getsize(p) / n / 1024:.0f} KiB"
                          for name, p in videos)

    print(f"marker detection: {n} frames {WIDTH}x{HEIGHT}, 2 views, {2 * PER_VIEW} markers per "
          f"frame, 4 px, noise sigma 2; one thread ({machine()} seen); "
          f"per frame: {sizes}")
    print_table(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
