"""Does a ± mean what it says: how often each angle's error lies within 2 sd of the truth.

Run from the repository root::

    python bench/bench_uncertainty.py [--frames 200] [--seeds 0 1 2] [--clutter]
    python bench/bench_uncertainty.py --quick        # 60 frames, seed 0

Protocol: ``videotrack synth`` makes the paper's locust project (its chain, two orthographic
views, 4-px markers, a smooth random movement of ``--frames`` frames, seeded by
``--seeds``), rendered and detected as a user's video is; ``videotrack run`` fits it with
the defaults. ``--clutter`` adds projects with 2 static and 1 flickering ghost per view and
2 % occluded marker images. The results' ``<axis>.sd`` columns are compared with the
planted angles (turns wrapped) on the scored axes (φ, ψ, α, β, γ). ``--planted`` adds
detections planted at the model's markers with Gaussian noise of 0.2, 0.7 and 1 px
(``tests/fixtures/planted.py``), fitted with the defaults through the Python API (σ measured
as on a video): renders are far cleaner than real video, planted noise is what σ says.

Columns, per project: σ of the noise model (px, per view, from the sidecar); axis-frames
scored; the share with |error| ≤ 2 sd among frames not flagged (``ok``, ``reanalysed``)
and among all frames; the median sd and the RMSE of the unflagged frames, degrees.

Goal: |error| ≤ 2 sd for 90–98 % of axis-frames (a Gaussian's 95 %). The script prints the
table and exits 0; it does not fail on a missed goal.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
# planted detections (a plain module there; "tests" may be another package's)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "fixtures"))

from _report import machine, print_markdown, synth_locust

AXES = ("J0.phi", "J0.psi", "J0.alpha", "J1.beta", "J2.gamma")
UNFLAGGED = ("ok", "reanalysed")


def _project(folder: Path, frames: int, seed: int, clutter: bool) -> None:
    synth_locust(folder, frames, seed, clutter)
    subprocess.run(["videotrack", "run", str(folder / "project.toml")], check=False,
                   capture_output=True)


def _score(folder: Path) -> dict:
    results = folder / "detections.results.csv"
    rows = list(csv.DictReader(results.open()))
    planted = {int(t["frame"]): t for t in csv.DictReader((folder / "truth.csv").open())}
    sigma = json.loads(results.with_name(results.name + ".json").read_text()).get("noise", {})
    err, sd, unflagged = [], [], []
    for row in rows:
        t = planted[int(row["frame"])]
        fitted = np.array([float(row[a] or "nan") for a in AXES])
        err.append((fitted - np.array([float(t[a]) for a in AXES]) + 180.0) % 360.0 - 180.0)
        sd.append([float(row.get(f"{a}.sd") or "nan") for a in AXES])
        unflagged.append(row["status"] in UNFLAGGED)
    err, sd, unflagged = np.abs(np.array(err)), np.array(sd), np.array(unflagged)
    valid = np.isfinite(err) & np.isfinite(sd) & (sd > 0)
    within = err <= 2 * sd
    good = valid & unflagged[:, None]
    return {"sigma": sigma.get("sigma_px"), "n": int(valid.sum()),
            "unflagged": within[good].mean() if good.any() else np.nan,
            "all": within[valid].mean() if valid.any() else np.nan,
            "sd": np.median(sd[good]) if good.any() else np.nan,
            "rmse": np.sqrt(np.mean(err[good] ** 2)) if good.any() else np.nan}


def _line(label: str, s: dict) -> tuple:
    sig = "-" if s["sigma"] is None else " / ".join(f"{v:.2f}" for v in s["sigma"])
    row = (label, sig, s["n"], f"{100 * s['unflagged']:.1f} %", f"{100 * s['all']:.1f} %",
           f"{s['sd']:.2f}", f"{s['rmse']:.3f}")
    print(row, file=sys.stderr)
    return row


def _planted(noise: float, frames: int, seed: int) -> dict:
    from bodies import locust_body
    from planted import planted_detections

    from kinematics.fit import AnnealParams, Fitter
    from videotrack.synth.motion import smooth_random_motion
    from videotrack.synth.paper_setup import locust_cameras

    body, cams = locust_body(), locust_cameras()
    truth = smooth_random_motion(body, frames, 1, seed=seed)
    fitter = Fitter(body, cams, AnnealParams())
    res = list(fitter.iter_fit(planted_detections(body, cams, truth, seed=seed, noise=noise)))
    axes = [body.axis_labels.index(a) for a in AXES]
    err = np.abs((np.array([r.angles_deg for r in res]) - truth + 180.0) % 360.0 - 180.0)
    sd = np.array([r.sd_deg for r in res])
    err, sd = err[:, axes], sd[:, axes]
    unflagged = np.array([r.status in UNFLAGGED for r in res])
    within = err <= 2 * sd
    return {"sigma": list(fitter.noise.sigma_px), "n": err.size,
            "unflagged": within[unflagged].mean(), "all": within.mean(),
            "sd": np.median(sd[unflagged]), "rmse": np.sqrt(np.mean(err[unflagged] ** 2))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--clutter", action="store_true", help="also projects with clutter")
    ap.add_argument("--planted", action="store_true", help="also planted detections")
    ap.add_argument("--quick", action="store_true", help="60 frames, seed 0")
    args = ap.parse_args(argv)
    frames, seeds = (60, [0]) if args.quick else (args.frames, args.seeds)
    print(f"machine: {machine()}")
    rows = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench-sd-") as tmp:
        for clutter in ((False, True) if args.clutter else (False,)):
            for seed in seeds:
                folder = Path(tmp) / f"p-{seed}-{int(clutter)}"
                _project(folder, frames, seed, clutter)
                rows.append(_line(f"{'clutter' if clutter else 'clean'}, seed {seed}",
                                  _score(folder)))
        for noise in ((0.2, 0.7, 1.0) if args.planted else ()):
            for seed in seeds:
                rows.append(_line(f"planted {noise} px, seed {seed}",
                                  _planted(noise, frames, seed)))
    print(f"\n`python bench/bench_uncertainty.py {' '.join(argv or sys.argv[1:])}` "
          f"({time.perf_counter() - t0:.0f} s)\n")
    header = ("project", "σ (px)", "axis-frames", "≤ 2 sd, unflagged", "≤ 2 sd, all",
              "median sd (°)", "RMSE unflagged (°)")
    print_markdown(header, rows)
    print("\ngoal: |error| ≤ 2 sd for 90–98 % of axis-frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
