"""The lane backend against the scalar kernel, measured in one run: ns per chain-iteration on
the paper's protocol, fitted frames/s with the defaults, and how the cost grows.

Run from the repository root::

    python bench/bench_lanes.py [--frames 128] [--video-frames 512] [--repeats 3] [--threads 1]
                                [--sweep-frames 1024] [--sweep-threshold 3]

Problems (detections: every marker projected with 0.2 px noise, plus ``--ghosts`` random
points per view):

* the paper's protocol: the locust leg in its two orthographic views, Table 1 schedule run
  to the end (ε = 0), one run per frame, Eq. 5 — ns per chain-iteration of each backend on
  ``--threads`` numba threads (time × threads / iterations); again with the lanes' general
  loops instead of the kernel generated for the body (``VIDEOTRACK_NO_CODEGEN``), and with
  that kernel in float32 (``precision = "float32"``);
* the defaults (refinement, the bounded error, two candidates, the threshold measured on the
  video), the paper's Table 1 schedule with re-analysis, and the short schedule that keeps
  Table 2's accuracy (refinement, N_end 5000, 1-px threshold) on a longer video: fitted
  frames/s of each backend on 2 threads, and whether the results agree;
* the growth table: ns per chain-iteration against detections per view (locust), for
  labelled keypoints (1 px noise, weights 0.5-1, 5 % missing) and against markers and
  views (the stick insect's leg and body with 2 or 4 pinhole views);
* throughput against accuracy (``--sweep-frames``): the Table 1 schedule and shorter ones
  with refinement, one or two runs per frame, each with its angle RMSE against the truth;
  the Table 1 schedule and N_end 2000 again with ``precision = "float32"``.

Both backends give the same results to the last bit (tests/kinematics/test_lanes.py); the
table says so again for the frames timed here. The float32 row (the lanes' generated kernel
in float32) gives the largest angle difference from the scalar kernel instead.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numba
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO))

from _report import machine, print_table  # noqa: E402

from kinematics.cameras import PinholeCamera  # noqa: E402
from kinematics.fit import AnnealParams, Fitter  # noqa: E402
from kinematics.model.chain_xml import load_body  # noqa: E402
from kinematics.model.fk import forward_kinematics  # noqa: E402
from kinematics.model.rotations import euler_yxz  # noqa: E402
from kinematics.observe.observations import Observations  # noqa: E402
from videotrack.synth.motion import smooth_random_motion  # noqa: E402
from videotrack.synth.paper_setup import bundled_chain, locust_cameras  # noqa: E402


def detections(body, cams, angles, ghosts: int, seed: int = 0) -> list:
    rng = np.random.default_rng(seed)
    lo, hi = 20.0, 280.0
    out = []
    for a in angles:
        mk = forward_kinematics(body, a).markers
        views = []
        for cam in cams.values():
            p = cam.project(mk)
            if np.isfinite(p).any():
                lo, hi = np.nanmin(p) - 20, np.nanmax(p) + 20
            views.append(np.concatenate([p + rng.normal(0, 0.2, p.shape),
                                         rng.uniform(lo, hi, (ghosts, 2))]))
        out.append(views)
    return out


def keypoints(body, cams, angles, seed: int = 4) -> Observations:
    """Labelled 2D keypoints of ``angles``: every marker projected with 1 px noise and a
    confidence in [0.5, 1], 5 % of them missing."""
    rng = np.random.default_rng(seed)
    kp = []
    for a in angles:
        mk = forward_kinematics(body, a).markers
        kp.append([np.c_[cam.project(mk) + rng.normal(0, 1.0, (len(mk), 2)),
                         rng.uniform(0.5, 1.0, len(mk))] for cam in cams.values()])
    kp = np.array(kp)
    kp[rng.random(kp.shape[:3]) < 0.05, :2] = np.nan
    names = list(body.marker_names)
    return Observations.keypoints(kp, list(cams), names, names)


def timed_fit(body, cams, dets, params, repeats: int):
    """(best seconds, results) of fitting every frame; the first call compiles."""
    fitter = Fitter(body, cams, params)
    fitter.fit(dets, frames=[0, 1])
    best, res = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = fitter.fit(dets)
        best = min(best, time.perf_counter() - t0)
    return best, res


def same(a, b) -> bool:
    return len(a) == len(b) and all(np.array_equal(x.angles_deg, y.angles_deg) and (
        x.error == y.error or (np.isnan(x.error) and np.isnan(y.error)))
        for x, y in zip(a, b, strict=True))


def per_iteration(body, cams, dets, params, repeats, threads, precision="float64"):
    """ns per chain-iteration of each backend, and whether they agree (the lanes in
    ``precision``; float32: the largest angle difference in degrees)."""
    out = {}
    for backend in ("scalar", "lanes"):
        dt, res = timed_fit(body, cams, dets, replace(params, backend=backend,
                                                      precision=precision), repeats)
        out[backend] = (dt * threads / sum(r.iterations for r in res) * 1e9, res)
    a, b = out["scalar"][1], out["lanes"][1]
    agree = same(a, b) if precision == "float64" else float(np.max(np.abs(
        np.array([r.angles_deg for r in a]) - np.array([r.angles_deg for r in b]))))
    return out["scalar"][0], out["lanes"][0], agree


def agreement(agree) -> str:
    """The results column: same / DIFFERENT (float64), or float32's largest difference."""
    if isinstance(agree, bool):
        return "same" if agree else "DIFFERENT"
    return "same angles" if agree == 0 else f"within {agree:.2g}°"


def pinholes(n: int) -> dict:
    k = [[900.0, 0.0, 400.0], [0.0, 900.0, 300.0], [0.0, 0.0, 1.0]]
    cams = {}
    for i in range(n):
        r = euler_yxz(2 * np.pi * i / n, 0.3, 0.0).T
        centre = euler_yxz(2 * np.pi * i / n, 0.3, 0.0) @ np.array([0.0, 0.0, -200.0])
        cams[f"cam{i}"] = PinholeCamera(f"cam{i}", k, R=r, t=-r @ centre)
    return cams


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=128)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1, help="numba threads of the ns rows")
    ap.add_argument("--ghosts", type=int, default=1)
    ap.add_argument("--video-frames", type=int, default=512,
                    help="frames of the defaults row (the threshold's 64-frame sample is "
                         "fitted first, so short videos understate the lanes)")
    ap.add_argument("--sweep-frames", type=int, default=1024,
                    help="frames of the short-schedule table (0 to skip)")
    ap.add_argument("--sweep-threshold", type=float, default=3.0,
                    help="re-analysis threshold of the short schedules (px): above a right "
                         "fit's E with this noise (8 marker images x ~0.25 px)")
    args = ap.parse_args(argv)
    if args.sweep_frames < 0 or args.sweep_threshold <= 0:
        ap.error("--sweep-frames must be >= 0 and --sweep-threshold > 0")
    with bundled_chain("locust_hindleg.xml") as p:
        locust = load_body(p)
    cams = locust_cameras()
    truth = smooth_random_motion(locust, args.frames, 1, seed=0)
    dets = detections(locust, cams, truth, args.ghosts)
    rows = []
    numba.set_num_threads(args.threads)
    paper = AnnealParams.paper(epsilon=0.0, max_runs=1)
    s, lane, ok = per_iteration(locust, cams, dets, paper, args.repeats, args.threads)
    rows.append((f"paper protocol, locust 2 views: ns per chain-iteration ({args.threads} "
                 "thread)", f"{s:.0f}", f"{lane:.1f}", f"{s / lane:.2f}x",
                 agreement(ok), "lanes <= 25"))
    s, lane, ok = per_iteration(locust, cams, dets, paper, args.repeats, args.threads,
                                "float32")
    rows.append(("the same, lanes in float32 (precision = \"float32\")", f"{s:.0f}",
                 f"{lane:.1f}", f"{s / lane:.2f}x", agreement(ok), "lanes <= 15"))
    os.environ["VIDEOTRACK_NO_CODEGEN"] = "1"  # the lanes' general loops, for comparison
    try:
        s, lane, ok = per_iteration(locust, cams, dets, paper, args.repeats, args.threads)
    finally:
        del os.environ["VIDEOTRACK_NO_CODEGEN"]
    rows.append(("the same, lanes without the generated kernel (general loops)", f"{s:.0f}",
                 f"{lane:.1f}", f"{s / lane:.2f}x", "same" if ok else "DIFFERENT", ""))
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    fps = {}
    results = {}
    video = detections(locust, cams, smooth_random_motion(locust, args.video_frames, 1, seed=5),
                       args.ghosts, seed=5)
    for backend in ("scalar", "lanes"):
        dt, res = timed_fit(locust, cams, video, AnnealParams(backend=backend), args.repeats)
        fps[backend], results[backend] = len(video) / dt, res
    rows.append((f"defaults, locust 2 views, {args.video_frames} frames: fitted frames/s "
                 "(2 threads)",
                 f"{fps['scalar']:.0f}", f"{fps['lanes']:.0f}",
                 f"{fps['lanes'] / fps['scalar']:.2f}x",
                 "same" if same(results["scalar"], results["lanes"]) else "DIFFERENT", ""))
    # the throughput figures: the Table 1 schedule with re-analysis (the paper's
    # settings), and the short schedule of the Table 2 sweep that keeps its accuracy
    fast = AnnealParams.paper(refine=True, reanalysis_threshold=1.0).with_schedule(5000)
    for name, params in (("Table 1 schedule incl. re-analysis (paper profile)",
                          AnnealParams.paper()),
                         ("refine + N_end 5000, threshold 1 px (Table 2 sweep)", fast)):
        rate = {}
        for backend in ("scalar", "lanes"):
            dt, res = timed_fit(locust, cams, video, replace(params, backend=backend),
                                args.repeats)
            rate[backend] = (len(video) / dt, res)
        goal = ">= 1000 (lanes)" if "Table 1" in name else ">= 10000 (lanes)"
        rows.append((f"{name}: fitted frames/s (2 threads)", f"{rate['scalar'][0]:.0f}",
                     f"{rate['lanes'][0]:.0f}", f"{rate['lanes'][0] / rate['scalar'][0]:.2f}x",
                     "same" if same(rate["scalar"][1], rate["lanes"][1]) else "DIFFERENT",
                     goal))
    numba.set_num_threads(args.threads)
    short = paper.with_schedule(5000)
    for ghosts in (10, 20, 30, 100):  # enough frames to fill every lane
        d = detections(locust, cams, truth, ghosts - 4, seed=1)
        s, lane, ok = per_iteration(locust, cams, d, short, 1, args.threads)
        rows.append((f"locust, 2 views, {ghosts} detections per view: ns per iteration",
                     f"{s:.0f}", f"{lane:.1f}", f"{s / lane:.2f}x",
                     "same" if ok else "DIFFERENT", ""))
    kp = keypoints(locust, cams, truth)
    s, lane, ok = per_iteration(locust, cams, kp, short, 1, args.threads)
    rows.append(("locust, 2 views, labelled keypoints (DeepLabCut-like): ns per iteration",
                 f"{s:.0f}", f"{lane:.1f}", f"{s / lane:.2f}x", "same" if ok else "DIFFERENT",
                 ""))
    with bundled_chain("stick_insect_frontleg.xml") as p:
        stick = load_body(p)
    st = smooth_random_motion(stick, args.frames, 1, seed=2)
    for n_views in (2, 4):
        c = pinholes(n_views)
        d = detections(stick, c, st, 1, seed=3)
        s, lane, ok = per_iteration(stick, c, d, short, 1, args.threads)
        rows.append((f"stick insect ({len(stick.marker_names)} markers), {n_views} pinhole "
                     "views: ns per iteration", f"{s:.0f}", f"{lane:.1f}", f"{s / lane:.2f}x",
                     "same" if ok else "DIFFERENT", ""))
    print(f"machine: {machine()}; numba threads for ns rows: {args.threads}")
    print_table(rows, results=("scalar", "lanes", "speed-up", "results"))
    if args.sweep_frames:
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        print(f"\nShort schedules: the default backend, 2 threads, {args.sweep_frames} frames "
              "(0.2 px noise, 1 ghost per view), refinement, re-analysis threshold "
              f"{args.sweep_threshold} px; angle RMSE against the truth (deg)")
        labels, table = sweep(locust, cams, args.sweep_frames, args.sweep_threshold)
        print_table(table, target="frames > 10 deg off",
                    results=("frames/s", "runs per frame", *labels))
    return 0


def sweep(body, cams, n_frames: int, threshold: float) -> tuple[list, list]:
    """Throughput against accuracy: the Table 1 schedule, then shorter schedules with one
    or several runs per frame (``candidates``: the path through time picks among them).
    Returns the free axes' labels and the table's rows."""
    truth = smooth_random_motion(body, n_frames, 1, seed=5)
    video = detections(body, cams, truth, 1, seed=5)
    free = np.flatnonzero(np.ptp(truth, axis=0) > 1e-9)
    short = AnnealParams.paper(refine=True, reanalysis_threshold=threshold)
    settings = [("paper (Table 1)", AnnealParams.paper())]
    settings += [(f"N_end {n}, {c} run{'s' if c > 1 else ''} per frame",
                  replace(short.with_schedule(n), candidates=c))
                 for n in (5000, 2000, 1000, 500) for c in (1, 2)]
    # precision float32 on the two settings of the figures: its accuracy table
    settings += [(f"{name}, float32", replace(params, precision="float32"))
                 for name, params in settings
                 if name in ("paper (Table 1)", "N_end 2000, 1 run per frame")]
    rows = []
    for name, params in settings:
        dt, res = timed_fit(body, cams, video, params, 2)
        d = np.array([r.angles_deg for r in res])[:, free] - truth[:, free]
        d = (d + 180.0) % 360.0 - 180.0
        rmse = np.sqrt(np.mean(d * d, axis=0))
        rows.append((name, f"{len(video) / dt:.0f}", f"{np.mean([r.runs for r in res]):.2f}",
                     *(f"{x:.2f}" for x in rmse),
                     str(int((np.abs(d) > 10.0).any(axis=1).sum()))))
    return [body.axis_labels[i] for i in free], rows


if __name__ == "__main__":
    raise SystemExit(main())
