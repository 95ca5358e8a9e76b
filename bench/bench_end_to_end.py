"""End to end: decoding, detection and fitting of a two-view video, each stage and the whole.

Run from the repository root::

    python bench/bench_end_to_end.py [--frames 1000] [--repeats 3] [--out DIR]

Video: ``videotrack synth`` renders the paper's locust hind leg (smooth random motion, 10
sequences) in two orthographic views of 360 x 576 px side by side, 720 x 576 frames, pixel
noise sigma = 2 grey levels. synth writes FFV1 (or PNG); the frames are re-encoded to MJPG at
quality 95 by OpenCV's encoder as ``bench/bench_detection.py`` does (colour, as MJPG cameras
record). The project is the one synth writes (threshold 96, min_area 3).

For each fitting setting, in one process after an untimed warm-up run (numba's cache loaded):

- **decode**: every frame decoded to grey as the pipeline opens the video (MJPEG: its
  packets decoded by libjpeg-turbo, ahead in threads; ``videotrack.detect.video``);
- **decode + detect**: ``detect_video`` over the whole video;
- **fit**: ``Fitter.iter_fit`` over the detections, all numba threads;
- **whole**: ``run_project(force=True)`` as ``videotrack run --force`` runs it: detect, save
  the detections, fit, write the results file (no plot); the records are fitted while the
  next are detected (``FitAlongside``) when the setting allows it, else one after the other;
- **whole, one after the other**: ``run_project(fit=False)`` then ``run_project(detect=False)``.

Rates are video frames per second (one record per frame), the best of ``--repeats`` rounds
(each round times every measurement once); a second table gives the CPU time per frame of
the same runs, which other jobs on a shared machine disturb far less than the wall time.
``whole / slowest`` is the whole rate over the slowest stage's (decode + detect, or fit): 1.0
means the slowest stage alone sets the pace. On a machine with few cores the stages also
compete for the same cores, so the whole cannot reach the slowest stage when their CPU time
adds up to more than the cores give. ``bound`` is the better of the two limits: the slowest
stage's rate, and the cores' (every core busy with the stages' own CPU time, measured with
``time.process_time``); ``whole / bound`` is how near the overlapped pipeline comes to it.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _report import in_out_folder, machine, print_table
from bench_detection import write as write_avi

from videotrack.cli import main as cli
from videotrack.detect.run import detect_video, settings_from_config, video_paths
from videotrack.detect.video import open_videos
from videotrack.project.config import load_config
from videotrack.workflow import load_model, not_streamable, run_project

CAMERAS = """\
units = "px"

[cameras.side]
type = "orthographic"
scale = 1.0
axes = ["x", "-y"]
offset = [310.0, 288.0]
size = [360, 576]

[cameras.top]
type = "orthographic"
scale = 1.0
axes = ["x", "z"]
offset = [310.0, 288.0]
size = [360, 576]
"""

#: The fitting settings timed ([anneal] overrides): the defaults, the paper's Table 1, and a
#: short schedule with one answer per frame and a fixed re-analysis threshold (both of which
#: let the pipeline fit while it detects).
SETTINGS = {
    "defaults": {},
    "paper (Table 1)": {"profile": "paper"},
    "N_end 5000, 1 candidate, absolute threshold": {"n_end": 5000, "candidates": 1,
                                                    "threshold_mode": "absolute"},
}


def make_project(folder: Path, frames: int) -> Path:
    """The synthetic project, its video re-encoded to MJPG; returns the project file."""
    (folder / "cameras_576.toml").write_text(CAMERAS)
    project = folder / "project"
    with contextlib.redirect_stdout(io.StringIO()):  # synth lists what it wrote
        code = cli(["synth", str(project), "--cameras", str(folder / "cameras_576.toml"),
                    "--frames", str(frames), "--noise", "2", "--force"])
    if code != 0:
        raise SystemExit("videotrack synth failed")
    video = project / "video.avi"
    with open_videos(video) as videos:
        grey = [f.copy() for _, (f,) in videos.frames()]
    write_avi(project / "mjpg.avi", grey, "MJPG")
    shutil.move(project / "mjpg.avi", video)
    return project / "project.toml"


def timed(run) -> tuple[float, float]:
    """Wall time and process CPU time (every thread, FFmpeg's and numba's too) of ``run()``."""
    w0, c0 = time.perf_counter(), time.process_time()
    run()
    return time.perf_counter() - w0, time.process_time() - c0


def measure(config, anneal: dict, repeats: int) -> dict:
    settings = settings_from_config(config)
    paths = video_paths(config)

    def decode():
        with open_videos(paths, colour=settings.filters.needs_colour) as videos:
            for _ in videos.frames(reuse=True):
                pass

    def detect():
        with open_videos(paths, colour=settings.filters.needs_colour) as videos:
            found["detections"] = detect_video(videos, settings)

    found = {}
    model = load_model(config, **anneal)

    def fit():
        model.fitter().fit(found["detections"])

    def whole():
        found["run"] = run_project(config, anneal=anneal, force=True, plot=False)

    def one_after_other():
        run_project(config, fit=False, force=True)
        run_project(config, anneal=anneal, detect=False, force=True, plot=False)

    whole()  # warm-up: numba's cache, the video's pages
    n = found["run"].detections.n_records
    # rounds over all measurements, so that a spell of load from other jobs on a shared
    # machine spoils one round rather than one measurement; the best wall time counts
    times = {}
    for _ in range(repeats):
        for name, f in (("decode", decode), ("detect", detect), ("fit", fit),
                        ("whole", whole), ("sequential", one_after_other)):
            got = timed(f)
            times[name] = min(times.get(name, got), got)
    return {"n": n, "times": times, "overlapped": found["run"].overlapped,
            "why": not_streamable(model)}


def run(folder: Path, frames: int, repeats: int) -> int:
    import numba

    project = make_project(folder, frames)
    config = load_config(project)
    cores = os.cpu_count() or 1
    rows, cpu_rows, notes = [], [], []
    for name, anneal in SETTINGS.items():
        m = measure(config, anneal, repeats)
        n, t = m["n"], m["times"]
        rate = {k: n / wall for k, (wall, _) in t.items()}
        slowest = min(rate["detect"], rate["fit"])
        bound = min(slowest, n * cores / (t["detect"][1] + t["fit"][1]))
        rows.append((name, *(f"{rate[k]:.0f}" for k in
                             ("decode", "detect", "fit", "whole", "sequential")),
                     f"{rate['whole'] / slowest:.2f}", f"{bound:.0f}",
                     f"{rate['whole'] / bound:.2f}", "yes" if m["overlapped"] else "no",
                     "1000"))
        cpu_rows.append((name, *(f"{1e3 * t[k][1] / n:.2f}" for k in
                                 ("decode", "detect", "fit", "whole", "sequential")), ""))
        if m["why"]:
            notes.append(f"- {name}: not overlapped: {m['why']}")
    print(f"Machine: {machine()}; numba {numba.__version__}, {numba.get_num_threads()} "
          f"threads, {numba.threading_layer()} layer")
    print(f"Video: {frames} frames 720x576 MJPG q95, two views; frames/s, best of "
          f"{repeats}\n")
    print_table(rows, target="goal (whole)",
                results=("decode", "decode + detect", "fit", "whole",
                         "whole, one after the other", "whole / slowest", "bound",
                         "whole / bound", "overlapped"))
    print("\nCPU time per frame (ms, all threads; the same runs):\n")
    print_table(cpu_rows, target="", results=("decode", "decode + detect", "fit", "whole",
                                             "whole, one after the other"))
    print()
    for line in notes:
        print(line)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=1000, help="frames of the video")
    parser.add_argument("--repeats", type=int, default=3, help="rounds of timings (best counts)")
    parser.add_argument("--out", type=Path, help="keep the project here (default: temporary)")
    args = parser.parse_args()
    return in_out_folder(args.out, "bench_e2e_", lambda folder, _keep: run(
        folder, args.frames, args.repeats))


if __name__ == "__main__":
    raise SystemExit(main())
