"""The CUDA backend against the scalar kernel and the lanes, measured in one run (needs a CUDA
GPU that numba can use; prints why not and exits 0 without one).

Run from the repository root::

    python bench/bench_cuda.py [--frames 32768] [--check-frames 512] [--threads 2]

The locust leg in its two orthographic views, detections as in ``bench/bench_lanes.py``
(0.2 px noise, one ghost per view). Rows:

* the paper's protocol (Table 1 schedule run to the end, ε = 0, one run per frame): ns per
  chain-iteration — the CPU backends' time × numba threads / iterations (per core), the
  GPU's wall time / iterations (the whole GPU);
* fitted frames/s with the paper's profile (Table 1 schedule, re-analysis), with the short
  schedule that keeps Table 2's accuracy (refinement, N_end 5000, 1-px threshold), and with
  the defaults.

Each backend fits the same frames; the CPU backends fit the first ``--check-frames`` of
them (the GPU all ``--frames``: it needs thousands of runs to fill; the frames are
independent, so fitting fewer changes none of them). The last column compares the GPU's
results on those frames with the scalar kernel's: how many are the same to the last bit
(NVVM fuses multiplies and adds, so the roundings differ, and a run whose acceptance
decision flips on one takes another path), and both backends' angle RMSE against the truth.
"""

from __future__ import annotations

import argparse
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
from bench_lanes import detections  # noqa: E402

from kinematics._kernels import cuda as _cuda_kernels  # noqa: E402
from kinematics.fit import AnnealParams, Fitter  # noqa: E402
from kinematics.model.chain_xml import load_body  # noqa: E402
from videotrack.synth.motion import smooth_random_motion  # noqa: E402
from videotrack.synth.paper_setup import bundled_chain, locust_cameras  # noqa: E402


def timed(body, cams, dets, params):
    """(seconds, results) of fitting every frame, after a first call that compiles."""
    fitter = Fitter(body, cams, params)
    fitter.fit(dets[:2])
    t0 = time.perf_counter()
    res = fitter.fit(dets)
    return time.perf_counter() - t0, res


def agreement(scalar, gpu, truth, free) -> str:
    """The GPU's results against the scalar kernel's: the frames whose angles are the same
    to the last bit, and each backend's angle RMSE against the truth (all free axes)."""
    def rmse(res):
        d = np.array([r.angles_deg for r in res])[:, free] - truth[:, free]
        d = (d + 180.0) % 360.0 - 180.0
        return float(np.sqrt(np.mean(d * d)))

    equal = sum(np.array_equal(a.angles_deg, b.angles_deg) for a, b in zip(scalar, gpu,
                                                                           strict=True))
    return (f"{equal}/{len(scalar)} frames bit-equal; RMSE {rmse(scalar):.3f}° / "
            f"{rmse(gpu):.3f}°")


def launch_sweep(body, cams, dets, truth, params) -> int:
    """The paper protocol's fitted frames/s on the GPU against the frames (runs) of one
    launch, and the kernel's compile time (its first call)."""
    fitter = Fitter(body, cams, replace(params, backend="cuda"))
    t0 = time.perf_counter()
    fitter.fit(dets[:2])
    compile_s = time.perf_counter() - t0
    rows = []
    n = 256
    while n <= len(dets):
        t0 = time.perf_counter()
        fitter.fit(dets[:n], chunk_size=n)
        dt = time.perf_counter() - t0
        rows.append((f"{n} frames in one launch: fitted frames/s", f"{n / dt:.0f}", ""))
        n *= 4
    print(f"machine: {machine()}; GPU: {gpu_name()}; the paper protocol (Table 1 schedule "
          f"to the end, 1 run); the kernel compiled in {compile_s:.1f} s")
    print_table(rows, results=("cuda",))
    return 0


def gpu_name() -> str:
    from numba import cuda
    return cuda.get_current_device().name.decode() if isinstance(
        cuda.get_current_device().name, bytes) else str(cuda.get_current_device().name)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=32768, help="frames the GPU fits")
    ap.add_argument("--check-frames", type=int, default=512,
                    help="frames the CPU backends fit (the GPU's first ones)")
    ap.add_argument("--threads", type=int, default=2, help="numba threads of the CPU rows")
    ap.add_argument("--gpu-only", action="store_true",
                    help="only the GPU's frames/s against frames per launch (no CPU rows)")
    args = ap.parse_args(argv)
    if args.frames < 1 or not 1 <= args.check_frames <= args.frames or args.threads < 1:
        ap.error("--frames >= --check-frames >= 1 and --threads >= 1 are needed")
    if not _cuda_kernels.available():
        print("no CUDA GPU that numba can use: nothing to measure")
        return 0
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    threads = numba.get_num_threads()
    with bundled_chain("locust_hindleg.xml") as p:
        locust = load_body(p)
    cams = locust_cameras()
    motion = smooth_random_motion(locust, args.frames, 1, seed=0)
    dets = detections(locust, cams, motion, 1)
    check, truth = dets[:args.check_frames], motion[:args.check_frames]
    free = np.flatnonzero(np.ptp(truth, axis=0) > 1e-9)
    settings = (
        ("paper protocol (Table 1 schedule to the end, 1 run)",
         AnnealParams.paper(epsilon=0.0, max_runs=1)),
        ("paper profile (Table 1 schedule, re-analysis)", AnnealParams.paper()),
        ("refine + N_end 5000, threshold 1 px (Table 2 sweep)",
         AnnealParams.paper(refine=True, reanalysis_threshold=1.0).with_schedule(5000)),
        ("defaults", AnnealParams()),
    )
    if args.gpu_only:
        return launch_sweep(locust, cams, dets, truth, settings[0][1])
    rows = []
    for name, params in settings:
        out = {}
        for backend in ("scalar", "lanes", "cuda"):
            out[backend] = timed(locust, cams, dets if backend == "cuda" else check,
                                 replace(params, backend=backend))
        its = {b: sum(r.iterations for r in res) for b, (_, res) in out.items()}
        agree = agreement(out["scalar"][1], out["cuda"][1][:args.check_frames], truth, free)
        if name.startswith("paper protocol"):
            ns = [out[b][0] * threads / its[b] * 1e9 for b in ("scalar", "lanes")]
            ns.append(out["cuda"][0] / its["cuda"] * 1e9)
            rows.append((f"{name}: ns per chain-iteration", f"{ns[0]:.0f}", f"{ns[1]:.1f}",
                         f"{ns[2]:.3f}", f"{ns[0] / ns[2]:.0f}x", agree))
        fps = [len(out[b][1]) / out[b][0] for b in ("scalar", "lanes", "cuda")]
        rows.append((f"{name}: fitted frames/s", f"{fps[0]:.0f}", f"{fps[1]:.0f}",
                     f"{fps[2]:.0f}", f"{fps[2] / fps[0]:.0f}x", agree))
    print(f"machine: {machine()}; GPU: {gpu_name()}; numba threads of the CPU rows: "
          f"{threads}; the GPU fits {args.frames} frames, the CPU backends "
          f"{args.check_frames}")
    print_table(rows, target="cuda against scalar", results=("scalar", "lanes", "cuda",
                                                       "cuda / scalar"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
