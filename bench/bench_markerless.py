"""Markerless route, synthetic truth: the chain fitted to 2D keypoints against
triangulate-then-fit with each triangulation backend.

A free-root rat hind leg (videotrack.synth.keypoints: pelvis with both hips and the tail
base, femur, tibia) moves through smooth random postures, seen by 4 calibrated pinhole
cameras; every camera's DeepLabCut CSV has 2 px of noise and 10 % of its keypoints missing
or swapped with another keypoint. Each project runs through ``videotrack.workflow.run.run_project``
as ``videotrack fit project.toml`` does:

- route "2d": the chain fitted to the 2D keypoints directly (labelled reprojection error);
- route "3d" with triangulation linear / ransac / optim: the keypoints triangulated, then the
  chain fitted to the 3D points;

and the triangulated points themselves are scored too. Figures: joint-angle RMSE over the
free axes (goal <= 1.5 deg for the 2D fit), mean 3D error of the joints and of the markers
(mm; for the triangulations the markers are the triangulated points).

    python bench/bench_markerless.py [--frames 100] [--seed 0] [--distance 350] [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import in_out_folder, machine, print_table

ANNEAL_2D = "[anneal]\nseed = 0\n"  # the 2D route's default cap (30 px)
ANNEAL_3D = "[anneal]\nseed = 0\ntau0 = 5.0\nreanalysis_threshold = 3.0\ncap_px = 30.0\n"
ROUTES = {
    "chain fitted to 2D keypoints": 'route = "2d"\n' + ANNEAL_2D,
    "linear, then chain fitted": 'route = "3d"\ntriangulation = "linear"\n' + ANNEAL_3D,
    "ransac, then chain fitted": 'route = "3d"\ntriangulation = "ransac"\n' + ANNEAL_3D,
    "optim, then chain fitted": 'route = "3d"\ntriangulation = "optim"\n' + ANNEAL_3D,
}


def _mean_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.nanmean(np.linalg.norm(a - b, axis=-1)))


def run(folder: Path, frames: int, seed: int, distance: float) -> list[tuple]:
    from videotrack.markerless.route import load_keypoints
    from videotrack.project.config import load_config
    from videotrack.synth.keypoints import write_session
    from videotrack.workflow import load_model, run_project

    rows = []
    for k, (name, text) in enumerate(ROUTES.items()):
        s = write_session(folder / f"route{k}", frames, noise_px=2.0, bad_share=0.1, seed=seed,
                          project_text=text, distance=distance)
        config = load_config(s.project)
        t0 = time.perf_counter()
        result = run_project(config, detect=False).results
        seconds = time.perf_counter() - t0
        free = ~s.body.locked_mask()
        err = (result.angles_deg - s.angles_deg + 180) % 360 - 180
        rmse = float(np.sqrt(np.nanmean(err[:, free] ** 2)))
        ok = int(result.ok_mask().sum())
        rows.append((name, f"{rmse:.2f}", f"{_mean_error(result.joints, s.joints):.2f}",
                     f"{_mean_error(result.markers, s.markers):.2f}", f"{ok}/{frames}",
                     f"{seconds:.1f}", "<= 1.5 deg" if k == 0 else ""))
        if k:  # the triangulated points themselves
            points = load_keypoints(config, load_model(config)).observations.points3d
            placed = np.isfinite(points[..., :3]).all(axis=2).mean()
            rows.append((f"{name.split(',')[0]} points alone", "", "",
                         f"{_mean_error(points[..., :3], s.markers):.2f}",
                         f"{100 * placed:.0f} % placed", "", ""))
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--distance", type=float, default=350.0,
                        help="cameras' distance from the leg, mm (350: femur about 80 px)")
    parser.add_argument("--out", type=Path, help="keep the sessions in this folder")
    args = parser.parse_args()

    def bench(folder: Path, keep: bool) -> int:
        rows = run(folder, args.frames, args.seed, args.distance)
        print(f"machine: {machine()}\n")
        print(f"{args.frames} frames, 4 pinhole cameras at {args.distance:g} mm, 2 px noise, "
              f"10 % of keypoints missing or swapped, seed {args.seed}\n")
        print_table(rows, results=("joint-angle RMSE (deg)", "joint error (mm)",
                                   "marker error (mm)", "frames ok", "fit (s)"))
        return 0

    return in_out_folder(args.out, "bench_markerless_", bench)


if __name__ == "__main__":
    sys.exit(main())
