"""What the noise model and the set-up checks cost: fitting time with the locust defaults, with
and without them, alternated in one run.

Run from the repository root::

    python bench/bench_confidence_cost.py [--frames 200] [--repeats 3]

Protocol: ``videotrack synth``'s locust project (``--frames`` frames), detected once; then
``Fitter.fit`` of every frame with the defaults (the noise model measured on the threshold's
sample, every frame judged, the set-up checked) and with ``noise_floor_px = None`` (no noise
test, no check of the sample; the detections' check stays), alternated ``--repeats`` times;
the fastest of each. Goal: at most 10 % more time.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import machine, print_table


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)

    from videotrack.detect.detections import load_detections
    from videotrack.project.config import load_config
    from videotrack.workflow import load_model, run_project

    with tempfile.TemporaryDirectory(prefix="bench-cost-") as tmp:
        folder = Path(tmp) / "p"
        subprocess.run(["videotrack", "synth", str(folder), "--frames", str(args.frames)],
                       check=True, capture_output=True)
        config = load_config(folder / "project.toml")
        run_project(config, fit=False)
        det = load_detections(folder / "detections.npz")
        model = load_model(config)
        rows = {"with": model.params,
                "without": replace(model.params, noise_floor_px=None)}
        model.fitter().fit(det, range(8))  # kernels compiled or loaded
        times = {k: [] for k in rows}
        for _ in range(args.repeats):
            for name, params in rows.items():
                fitter = model.fitter(params=params)
                t0 = time.perf_counter()
                fitter.fit(det)
                times[name].append(time.perf_counter() - t0)
    best = {k: min(v) for k, v in times.items()}
    ratio = best["with"] / best["without"]
    print(f"machine: {machine()}; {args.frames} frames, best of {args.repeats}\n")
    print_table([
        ("fit with the noise model and set-up checks (s)", f"{best['with']:.2f}", ""),
        ("fit without them, noise_floor_px = None (s)", f"{best['without']:.2f}", ""),
        ("ratio", f"{ratio:.3f}", "≤ 1.10"),
    ])
    return 0


if __name__ == "__main__":
    sys.exit(main())
