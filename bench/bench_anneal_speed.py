"""Speed of the posture fit: ns per annealing iteration, frames/s, and the ratios to the paper
and to the NumPy reference, all measured in the same run.

Run from the repository root::

    python bench/bench_anneal_speed.py [--frames 668] [--repeats 3] [--short 5000]

Input: the locust hind-leg chain and the paper's two orthographic views, ``--frames`` postures
of 10 smooth random sequences, detections = true marker images + Gaussian noise (0.05 px) + one
static ghost per view, i.e. 2 views x 4 markers and 10 detected points per frame.

Measured: (a) ns per SA iteration on one thread (one frame, Table 1 schedule run to the end:
ε = 0, one run); (b) frames/s with the Table 1 defaults (re-analysis included) on one thread and
on all of numba's threads; (c) the same with refinement and the shortened schedule
``--short`` (N_l, N_τ scaled; re-analysis threshold 1 px) that keeps the accuracy in
``bench_table2.py``; (d) the NumPy reference loop (:func:`kinematics.fit.anneal_reference`,
4x4 forward kinematics and the NumPy Eq. 5) per iteration; (e) the refinement kernel per frame
against ``scipy.optimize.least_squares`` on the same problem. Timings are the best of
``--repeats`` runs; the first call of each kernel (compilation or cache load) is excluded.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _report import machine, print_table

from kinematics._kernels import refine as rk
from kinematics.fit import AnnealParams, Fitter, anneal_reference
from kinematics.fit.inputs import as_ragged
from kinematics.fit.refine import refine_reference
from kinematics.model.chain_xml import load_body
from kinematics.model.fk import forward_kinematics
from kinematics.observe.observations import ObservationArrays
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import bundled_chain, locust_cameras

PAPER_FPS = 0.4  # Sect. 3.2: Table 1 schedule on a 1.8 GHz Pentium 4


def detections(body, cams, angles, seed=0, noise=0.05):
    rng = np.random.default_rng(seed)
    ghosts = [rng.uniform(20, 280, (1, 2)) for _ in cams]
    out = []
    for a in angles:
        markers = forward_kinematics(body, a).markers
        out.append([np.concatenate([c.project(markers) + rng.normal(0, noise, (4, 2)), g])
                    for c, g in zip(cams.values(), ghosts, strict=True)])
    return out


def best_time(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def fps_on(threads: int, fitter: Fitter, dets, repeats: int) -> tuple[float, list]:
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        out = []
        t = best_time(lambda: out.append(fitter.fit(dets)), repeats)
    finally:
        numba.set_num_threads(before)
    return len(dets) / t, out[-1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=668)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--short", type=int, default=5000,
                    help="N_end of the refined schedule (bench_table2's sweep)")
    ap.add_argument("--reference-iterations", type=int, default=300)
    args = ap.parse_args()
    load = os.getloadavg()[0]
    with bundled_chain("locust_hindleg.xml") as path:
        body = load_body(path)
    cams = locust_cameras()
    truth = smooth_random_motion(body, args.frames, 10, seed=0)
    dets = detections(body, cams, truth)
    threads = numba.config.NUMBA_NUM_THREADS
    rows = []

    # (a) ns per iteration, one thread, one frame, the whole schedule.
    one = Fitter(body, cams, AnnealParams.paper(epsilon=0.0, max_runs=1))
    one.fit_frame(dets[0])  # compile or load the cache
    numba.set_num_threads(1)
    t_frame = min(best_time(lambda k=k: one.fit_frame(dets[k], frame=k), args.repeats)
                  for k in range(5))
    numba.set_num_threads(threads)
    ns_it = t_frame / 35000 * 1e9
    rows.append(("SA iteration, 1 thread (locust, 2 views, 10 points)", f"{ns_it:.0f} ns",
                 "<= 200 ns"))

    # (d) the NumPy reference, same loop, same stream.
    ref_params = AnnealParams.paper(epsilon=0.0, max_runs=1).with_schedule(
        args.reference_iterations)
    t_ref = best_time(lambda: anneal_reference(body, cams, dets[0], ref_params), 1)
    ns_ref = t_ref / args.reference_iterations * 1e9
    rows.append(("NumPy reference iteration (anneal_reference)", f"{ns_ref / 1000:.0f} µs",
                 ""))
    rows.append(("kernel speed-up over the NumPy reference", f"{ns_ref / ns_it:.0f}x", ""))

    # (b) Table 1 defaults, re-analysis included; (c) refinement + the short schedule.
    def schedule_rows(label: str, fitter: Fitter, target_on_2: str = "") -> Fitter:
        fitter.fit(dets[:4])  # compile and warm up
        for n_threads in sorted({1, threads}):
            fps, res = fps_on(n_threads, fitter, dets, args.repeats)
            rerun = sum(r.runs > 1 for r in res)
            rows.append((f"{label}, {n_threads} thread{'s' * (n_threads > 1)} "
                         f"({rerun} frames re-run)", f"{fps:.0f} frames/s",
                         target_on_2 if n_threads == 2 else ""))
            rows.append((f"  ratio to the paper's {PAPER_FPS} frames/s",
                         f"{fps / PAPER_FPS:.0f}x", ""))
        return fitter

    table1 = schedule_rows("Table 1 schedule", Fitter(body, cams, AnnealParams.paper()),
                  ">= 100 frames/s on 2 cores")
    schedule_rows(f"refine + N_end {args.short}", Fitter(body, cams, AnnealParams.paper(
        refine=True, reanalysis_threshold=1.0).with_schedule(args.short)))

    # (e) the refinement kernel against scipy's least_squares, per frame, one thread.
    res = table1.fit(dets)
    starts = np.deg2rad([r.angles_deg for r in res])
    rag = as_ragged(dets, one.view_names)
    roots = np.zeros((len(dets), 1, 3))
    rots = one.problem.identity_rotations(len(dets))
    sse, pairs = np.empty(len(dets)), np.empty(len(dets), np.int64)

    def kernel_all():
        a = starts.copy()
        pr = one.problem
        obs = ObservationArrays(0, rag.points, np.ones(len(rag.points)), rag.offsets,
                                np.zeros((len(a), 4, 4)))
        rk.refine_frames(a, roots, rots, pr.folded, pr.cams, pr.dofs, 10, 5.0, obs, sse,
                         pairs)

    kernel_all()
    numba.set_num_threads(1)
    t_k = best_time(kernel_all, args.repeats) / len(dets)
    numba.set_num_threads(threads)
    t_s = best_time(lambda: [refine_reference(one, r.angles_deg, d) for r, d in
                             zip(res[:20], dets[:20], strict=True)], 1) / 20
    rows.append(("refinement kernel per frame, 1 thread", f"{t_k * 1e6:.1f} µs", ""))
    rows.append(("scipy least_squares, same problem, per frame", f"{t_s * 1e3:.2f} ms", ""))
    rows.append(("  kernel speed-up", f"{t_s / t_k:.0f}x", "~2000x"))

    print(f"Posture-fit speed: {args.frames} frames; {machine()}; numba {numba.__version__}, "
          f"{threads} threads ({numba.threading_layer()}); load average {load:.2f} at the "
          "start (other processes take cores from the timings)")
    print_table(rows, "target")
    return 0


if __name__ == "__main__":
    sys.exit(main())
