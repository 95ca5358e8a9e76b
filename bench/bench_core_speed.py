"""Speed of one annealing iteration before and after a change of the fitting core, measured in
the same run: the baseline revision is checked out into a temporary git worktree and both
trees time the same problem in alternating subprocesses (one numba thread each).

Run from the repository root::

    python bench/bench_core_speed.py [--baseline 8c15132] [--rounds 3] [--frames 6]

Problems: the paper's locust leg in its two orthographic views (Table 1 schedule run to the end,
ε = 0, one run, 10 detections per frame), and the stick-insect leg (marker root) in two pinhole
views. Printed: ns per iteration of each tree (best over rounds) and the ratio old/new (≥ 1:
the new core is not slower).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))

from _report import machine, print_table  # noqa: E402

# Runs inside each tree with only the public API both versions share (under either layout).
SNIPPET = r"""
import json, sys, time
import numba, numpy as np
from kinematics.cameras import PinholeCamera
try:  # the tree's layout since the fitting layer moved into packages
    from kinematics.fit import AnnealParams, Fitter
    from kinematics.model.chain_xml import load_body
    from kinematics.model.fk import forward_kinematics
    from videotrack.synth.motion import smooth_random_motion
    from videotrack.synth.paper_setup import bundled_chain, locust_cameras
except ImportError:  # ... and before
    from kinematics.anneal import AnnealParams, Fitter
    from kinematics.chain_xml import load_body
    from kinematics.fk import forward_kinematics
    from videotrack.motion import smooth_random_motion
    from videotrack.paper_setup import bundled_chain, locust_cameras

numba.set_num_threads(1)
n_frames = int(sys.argv[1])

def dets(body, cams, angles, roots=None):
    rng = np.random.default_rng(0)
    out = []
    for a in angles:
        mk = forward_kinematics(body, a, roots).markers
        out.append([np.concatenate([c.project(mk) + rng.normal(0, 0.05, mk[:, :2].shape),
                                    rng.uniform(20, 280, (1, 2))]) for c in cams.values()])
    return out

def time_it(body, cams):
    truth = smooth_random_motion(body, n_frames, 1, seed=0)
    d = dets(body, cams, truth)
    # the paper's settings (the old tree's defaults; newer trees name them paper())
    paper = getattr(AnnealParams, "paper", AnnealParams)
    f = Fitter(body, cams, paper(epsilon=0.0, max_runs=1))
    f.fit_frame(d[0])
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        its = sum(f.fit_frame(x, frame=k).iterations for k, x in enumerate(d))
        best = min(best, (time.perf_counter() - t0) / its)
    return best * 1e9

out = {}
with bundled_chain("locust_hindleg.xml") as p:
    out["locust, 2 orthographic views"] = time_it(load_body(p), locust_cameras())
k = [[900.0, 0.0, 400.0], [0.0, 900.0, 300.0], [0.0, 0.0, 1.0]]
pin = {"top": PinholeCamera("top", k, rvec=[np.pi / 2, 0.0, 0.0], t=[0.0, 0.0, 200.0]),
       "side": PinholeCamera("side", k, rvec=[0.0, np.pi, 0.0], t=[0.0, 0.0, 200.0])}
with bundled_chain("stick_insect_frontleg.xml") as p:
    out["stick insect, 2 pinhole views"] = time_it(load_body(p), pin)
print(json.dumps(out))
"""


def run_tree(tree: Path, frames: int) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    res = subprocess.run([sys.executable, "-c", SNIPPET, str(frames)], cwd=tree, env=env,
                         capture_output=True, text=True, check=False)
    if res.returncode:
        raise SystemExit(f"timing in {tree} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", default="8c15132", help="git revision to compare against")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=6)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="vt-baseline-") as tmp:
        old = Path(tmp) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", str(old), args.baseline],
                       cwd=REPO, check=True, capture_output=True)
        try:
            best: dict[str, dict[str, float]] = {"old": {}, "new": {}}
            for _ in range(args.rounds):  # alternate, so load changes hit both alike
                for name, tree in (("old", old), ("new", REPO)):
                    for k, v in run_tree(tree, args.frames).items():
                        best[name][k] = min(best[name].get(k, float("inf")), v)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old)], cwd=REPO,
                           check=False, capture_output=True)
    rows = [(k, f"{best['old'][k]:.0f}", f"{best['new'][k]:.0f}",
             f"{best['old'][k] / best['new'][k]:.3f}", ">= 0.95") for k in best["new"]]
    print(f"SA iteration, old ({args.baseline}) vs new (working tree); {machine()}")
    print_table(rows, target="goal (old/new)", results=("old ns/it", "new ns/it", "old/new"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
