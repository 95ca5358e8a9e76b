"""How the cost of an annealing iteration grows with detections, cameras and limbs.

Run from the repository root::

    python bench/bench_scaling.py [--iterations 20000]

One thread, one frame, one run of ``--iterations`` (ε = 0, so every run does them all);
ns per iteration, best of 3; the paper's Eq. 5, and for the locust also the defaults' bounded
error (whose term for unexplained detections visits every marker for every detection).
Views with more than ``SWEEP_MIN`` (16) detections are searched by a sweep along x. Bodies:
the paper's locust leg (1 chain, 4 markers) and the shipped six-legged fly (6 chains, 30
markers), with ghost detections added to reach the detection counts; cameras: orthographic
pairs (locust) or 2-6 pinhole cameras (fly). The fly is annealed with partitions (each leg in
turn, its own markers scored) and, for comparison, every axis at once.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import machine, print_table

from kinematics.cameras import PinholeCamera
from kinematics.fit import AnnealParams, ErrorOptions, Fitter
from kinematics.model.chain_xml import load_body
from kinematics.model.fk import forward_kinematics
from kinematics.model.rotations import euler_yxz
from videotrack.synth.paper_setup import bundled_chain, locust_cameras


def ring(n: int, distance: float) -> dict:
    k = [[1500.0, 0, 640], [0, 1500.0, 512], [0, 0, 1]]
    cams = {}
    for i in range(n):
        r = euler_yxz(2 * np.pi * i / n, 0.4, 0.0).T
        centre = euler_yxz(2 * np.pi * i / n, 0.4, 0.0) @ np.array([0.0, 0.0, -distance])
        cams[f"c{i}"] = PinholeCamera(f"c{i}", k, R=r, t=-r @ centre)
    return cams


def frame(body, cams, n_det: int, rng) -> list:
    markers = forward_kinematics(body, body.mean_posture_deg()).markers
    out = []
    for c in cams.values():
        p = c.project(markers)
        extra = max(0, n_det - len(p))
        lo, hi = p.min(axis=0) - 40, p.max(axis=0) + 40
        out.append(np.vstack([p, rng.uniform(lo, hi, (extra, 2))]))
    return out


def ns_per_iteration(body, cams, det, iterations: int, partitions: str,
                     error: str = "paper") -> float:
    params = AnnealParams.paper(epsilon=0.0, max_runs=1, partitions=partitions, partition_rounds=1,
                                error=ErrorOptions(error, cap_px=None if error == "paper"
                                                   else 10.0)).with_schedule(iterations)
    fitter = Fitter(body, cams, params)
    fitter.fit_frame(det)
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        r = fitter.fit_frame(det)
        best = min(best, (time.perf_counter() - t0) / r.iterations)
    return best * 1e9


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--iterations", type=int, default=20000)
    args = ap.parse_args()
    numba.set_num_threads(1)
    rng = np.random.default_rng(0)
    rows = []
    with bundled_chain("locust_hindleg.xml") as p:
        locust = load_body(p)
    cams = locust_cameras()
    for error in ("paper", "bounded"):
        for n_det in (4, 10, 30, 100, 300, 1000):
            det = frame(locust, cams, n_det, rng)
            ns = ns_per_iteration(locust, cams, det, args.iterations, "none", error)
            rows.append((f"locust, 2 ortho views, {n_det} detections/view", f"{ns:.0f}",
                         f"error {error}"))
    with bundled_chain("fly_six_legs.xml") as p:
        fly = load_body(p)
    for n_cam in (2, 6):
        cams = ring(n_cam, 40.0)
        for n_det in (30, 100):
            det = frame(fly, cams, n_det, rng)
            for mode in ("auto", "none"):
                label = "by leg" if mode == "auto" else "all axes"
                rows.append((f"fly, {n_cam} pinhole views, {n_det} detections/view, {label}",
                             f"{ns_per_iteration(fly, cams, det, args.iterations, mode):.0f}",
                             ""))
    print(f"ns per SA iteration, 1 thread; {machine()}\n")
    print_table(rows, "note", results=("ns/iteration",))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
