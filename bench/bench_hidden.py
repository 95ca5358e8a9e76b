"""A marker marked hidden in a view: the fit's accuracy with and without the mark.

Run from the repository root::

    python bench/bench_hidden.py [--frames 60] [--seeds 0 1 2]

Protocol: the paper's locust set-up (``chains/locust_hindleg.xml``, the two orthographic views
of ``locust_cameras``), planted detections (exact projections + 0.2 px noise) of a smooth
random movement. The tibia tip (M3) is occluded in the side view in every frame; what the
side view shows in its place is nothing, or a ghost ``d`` px from where the tip would be
(a neighbour's leg, dirt). Each video is fitted as it is and with the tip marked hidden in
the side view (``Observations.with_hidden``, the GUI's H key), with the paper profile and
with the defaults. Reported: the RMSE of γ (the joint the tip measures) and of the other
free axes (φ, ψ, α, β), over the seeds.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import machine, print_table

from kinematics.fit import AnnealParams, Fitter
from kinematics.model.chain_xml import load_body
from kinematics.model.fk import forward_kinematics
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import bundled_chain, locust_cameras

NOISE_PX = 0.2
GHOSTS = (None, 6.0, 15.0, 25.0)  # px from the hidden tip; None: nothing there
PROFILES = {"paper": AnnealParams.paper, "defaults": AnnealParams}
GAMMA = 8  # state index of γ; the other free axes are φ ψ α β
OTHERS = [0, 1, 2, 5]


def video(body, cams, truth, ghost, seed):
    """Detections per frame and view, the tip taken out of the side view (and a ghost)."""
    rng = np.random.default_rng(seed)
    tip = body.marker_names.index("M3")
    frames = []
    for m in forward_kinematics(body, truth).markers:
        side, top = (c.project(m) + rng.normal(0, NOISE_PX, (len(m), 2))
                     for c in cams.values())
        shown = np.delete(side, tip, axis=0)
        if ghost is not None:
            shown = np.concatenate([shown, side[tip:tip + 1] + ghost / np.sqrt(2)])
        frames.append([shown, top])
    hidden = np.zeros((len(truth), 2, len(body.marker_names)), bool)
    hidden[:, 0, tip] = True
    return frames, hidden


def rmse(results, truth, cols) -> float:
    ang = np.array([r.angles_deg for r in results])[:, cols]
    return float(np.sqrt(np.mean((ang - truth[:, cols]) ** 2)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args(argv)
    with bundled_chain("locust_hindleg.xml") as path:
        body = load_body(path)
    cams = locust_cameras()
    rows = []
    for profile, make in PROFILES.items():
        for ghost in GHOSTS:
            errs = {"as is": ([], []), "hidden": ([], [])}
            for seed in args.seeds:
                truth = smooth_random_motion(body, args.frames, max(2, args.frames // 30),
                                             seed=seed)
                frames, hidden = video(body, cams, truth, ghost, seed)
                fitter = Fitter(body, cams, make(seed=seed))
                obs = fitter.observations(frames)
                for name, data in (("as is", obs), ("hidden", obs.with_hidden(hidden))):
                    res = fitter.fit(data)
                    errs[name][0].append(rmse(res, truth, [GAMMA]) ** 2)
                    errs[name][1].append(rmse(res, truth, OTHERS) ** 2)
            what = "nothing" if ghost is None else f"ghost {ghost:g} px"
            cells = [f"{np.sqrt(np.mean(errs[k][0])):.2f} / {np.sqrt(np.mean(errs[k][1])):.2f}"
                     for k in ("as is", "hidden")]
            rows.append((f"{profile}, {what}", *cells, ""))
    print(f"machine: {machine()}; {args.frames} frames x seeds {args.seeds}; "
          f"RMSE (deg) γ / φ ψ α β")
    print_table(rows, target="", results=("as is", "tip hidden in side"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
