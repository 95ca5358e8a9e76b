"""Triangulation backends side by side with aniposelib 0.8, and against planted truth.

On two real multi-camera sessions (``../shared/data`` items 6 and 8: the pose2sim demo's
OpenPose JSON of 4 cameras, the sleap-anipose mouse's SLEAP tracks of 4 cameras) the same 2D
input and calibration go to VideoTrack's backends and to aniposelib's: the linear results must
agree within 1e-6, RANSAC and the optimisation must reproject at least as well, and VideoTrack
must be >= 10x faster for linear and RANSAC and >= 3x for the optimisation, timed in this one
run with the two libraries called in turn (best of N rounds each, and every round's speed-up,
so that the shared machine's changing load hits both alike). A synthetic chain (4 cameras,
2 px noise, 10 % of keypoints swapped or missing) gives the 3D error of every backend against
the truth.

Needs aniposelib 0.8 and jax (``pip install --no-deps aniposelib==0.8.0 toml`` and
``pip install jax``; aniposelib's own requirement of opencv-contrib-python is not needed).

    python bench/bench_triangulation.py [--data ../shared/data] [--repeat 5]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import machine, print_table

from kinematics.cameras import PinholeCamera
from kinematics.cameras.files import import_anipose_toml
from kinematics.model.rotations import euler_yxz
from kinematics.observe.triangulation import (
    triangulate_linear,
    triangulate_optim,
    triangulate_ransac,
)
from videotrack.io.keypoints import align_cameras, read_keypoints

BODY_25B_LIMBS = [("LHip", "LKnee"), ("LKnee", "LAnkle"), ("RHip", "RKnee"),
                  ("RKnee", "RAnkle"), ("LShoulder", "LElbow"), ("LElbow", "LWrist"),
                  ("RShoulder", "RElbow"), ("RElbow", "RWrist")]
#: aniposelib's optim_points settings, used by both sides (the Anipose paper's β and α).
OPTIM = dict(smooth=2.0, limb_weight=2.0, loss_px=15.0, n_deriv=1)


def best_time(fn, repeat: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def alternate(ours, theirs, rounds: int) -> tuple[float, float, list[float], object, object]:
    """Both sides timed in turn, ``rounds`` times, so that a change of load on the shared
    machine hits both alike: best time of each, the speed-up of every round, and each
    side's first output."""
    t_our, t_their, ratios, outs = np.inf, np.inf, [], {}
    for _ in range(rounds):
        times = []
        for side, fn in (("ours", ours), ("theirs", theirs)):
            t = time.perf_counter()
            out = fn()
            times.append(time.perf_counter() - t)
            outs.setdefault(side, out)
        t_our, t_their = min(t_our, times[0]), min(t_their, times[1])
        ratios.append(times[1] / times[0])
    return t_our, t_their, ratios, outs["ours"], outs["theirs"]


def spread(ratios: list[float]) -> str:
    """Speed-ups of the rounds: lowest / median / highest."""
    return " / ".join(f"{q:.0f}x" for q in np.percentile(ratios, [0, 50, 100]))


def mean_reprojection(cams, xy, xyz) -> float:
    """Mean over points of the mean pixel error over the cameras that see them (the pose-3d
    error column), the same NumPy code for every result."""
    proj = np.stack([c.project(xyz) for c in cams])
    err = np.linalg.norm(proj - xy, axis=-1)
    return float(np.nanmean(np.nanmean(np.where(np.isfinite(err), err, np.nan), axis=0)))


def mouse(data: Path):
    root = data / "sleap_anipose_mouse4cam"
    views = ("back", "mid", "side", "top")
    tracks = {v: read_keypoints(root / v / f"minimal_{v}_proofread.analysis.h5")
              for v in views}
    names, _, xy, score = align_cameras(tracks)
    import h5py

    with h5py.File(root / "top" / "minimal_top_proofread.analysis.h5", "r") as f:
        limbs = [tuple(int(i) for i in e) for e in f["edge_inds"][:]]
    return "sleap_anipose_mouse4cam (SLEAP, 4 cameras)", root / "calibration.toml", views, \
        names, xy, score, 0.0, limbs


def pose2sim(data: Path):
    root = data / "pose2sim_demo"
    views = ("cam01", "cam02", "cam03", "cam04")
    tracks = {v: read_keypoints(root / "balancing_trial" / "pose_openpose_json" / f"{v}_json",
                                model="BODY_25B") for v in views}
    names, _, xy, score = align_cameras(tracks)
    limbs = [(names.index(a), names.index(b)) for a, b in BODY_25B_LIMBS]
    calib = root / "calibration" / "Calib_qualisys_converted_by_pose2sim.toml"
    return "pose2sim_demo (OpenPose, 4 cameras)", calib, views, names, xy, score, 0.3, limbs


def real_session(load, data: Path, repeat: int) -> list:
    from aniposelib.cameras import CameraGroup

    title, calib, _views, _names, xy, score, min_score, limbs = load(data)
    cams = list(import_anipose_toml(calib).values())
    group = CameraGroup.load(str(calib))
    xy = np.where((score >= min_score)[..., None], xy, np.nan)  # Anipose's score_threshold
    c, f, j, _ = xy.shape
    flat = xy.reshape(c, -1, 2)
    n_pts = f * j

    def theirs_linear():
        p3 = group.triangulate(flat)
        return p3, group.reprojection_error(p3, flat, mean=True)

    ours = dict(weighted=False)
    theirs_linear()
    triangulate_linear(cams, xy, **ours)  # warm-up: jax and numba compilation
    t_our, t_their, lin_ratios, lin, (p3_their, _) = alternate(
        lambda: triangulate_linear(cams, xy, **ours), theirs_linear, repeat)
    ok = np.isfinite(p3_their).all(axis=1)
    same_nan = np.array_equal(ok, np.isfinite(lin.xyz.reshape(-1, 3)).all(axis=1))
    diff = float(np.abs(lin.xyz.reshape(-1, 3)[ok] - p3_their[ok]).max())

    seen = np.isfinite(flat[..., 0]).any(axis=0)  # aniposelib's RANSAC fails on unseen points
    step = max(1, int(seen.sum()) // 400)
    sample = np.flatnonzero(seen)[::step]
    sub = flat[:, sample][:, None]
    group.triangulate_ransac(flat[:, sample[:2]])
    triangulate_ransac(cams, sub, **ours)
    # aniposelib takes seconds a call here: two rounds
    t_r_our, t_r_their, r_ratios, ran_s, (r_their, _, _, r_err) = alternate(
        lambda: triangulate_ransac(cams, sub, **ours),
        lambda: group.triangulate_ransac(flat[:, sample]), 2)
    r_ok = np.isfinite(r_their).all(axis=1)
    r_diff = float(np.abs(ran_s.xyz[0][r_ok] - r_their[r_ok]).max())
    t_r_full, ran = best_time(lambda: triangulate_ransac(cams, xy, **ours), repeat)

    init = p3_their.reshape(f, j, 3)

    def theirs_optim():
        # BLAS on one thread, as VideoTrack's optimisation runs: aniposelib's faster setting
        # on a shared 2-CPU machine too (1.0-1.2 s against 1.3-3.2 s with two threads)
        with threadpool_limits(1):
            return group.optim_points(xy, init, constraints=limbs,
                                      scale_smooth=OPTIM["smooth"],
                                      scale_length=OPTIM["limb_weight"],
                                      reproj_error_threshold=OPTIM["loss_px"],
                                      n_deriv_smooth=OPTIM["n_deriv"])

    def ours_optim():
        return triangulate_optim(cams, xy, limbs=limbs, **ours, **OPTIM)

    # warm-up: each side's first call compiles (numba, jax) and took 2-5x longer
    theirs_optim()
    ours_optim()
    t_o_our, t_o_their, o_ratios, opt, o_their = alternate(ours_optim, theirs_optim, 2)

    rep = {k: mean_reprojection(cams, xy, v) for k, v in (
        ("lin", lin.xyz), ("ran", ran.xyz), ("opt", opt.xyz), ("opt_their", o_their))}
    ran_sample_err = float(np.nanmean(ran_s.error))
    their_sample_err = float(np.nanmean(np.where(r_ok, r_err, np.nan)))
    print(f"\n### {title}: {f} frames x {j} points, min score {min_score}\n")
    rows = [
        ("linear: max abs difference from aniposelib (world units)", f"{diff:.1e}",
         "same NaN" if same_nan else "NaN differ", "<= 1e-6"),
        (f"linear: time for {n_pts} points (incl. reprojection error)",
         f"{1e3 * t_our:.2f} ms", f"{1e3 * t_their:.1f} ms", ""),
        ("linear: speed-up (best times)", f"{t_their / t_our:.0f}x", "", ">= 10x"),
        (f"linear: speed-up of each of {len(lin_ratios)} rounds (low / median / high)",
         spread(lin_ratios), "", ""),
        (f"RANSAC: max abs difference from aniposelib ({len(sample)} points)",
         f"{r_diff:.1e}", "", "(same semantics)"),
        ("RANSAC: mean reprojection error of the sample (px)", f"{ran_sample_err:.3f}",
         f"{their_sample_err:.3f}", "<= aniposelib"),
        (f"RANSAC: time per point ({len(sample)} points)",
         f"{1e6 * t_r_our / len(sample):.2f} us", f"{1e6 * t_r_their / len(sample):.0f} us",
         ""),
        ("RANSAC: speed-up (best times; rounds: low / high)",
         f"{t_r_their / t_r_our:.0f}x ({min(r_ratios):.0f}x / {max(r_ratios):.0f}x)", "",
         ">= 10x"),
        (f"RANSAC: time for all {n_pts} points", f"{1e3 * t_r_full:.2f} ms", "", ""),
        ("optimisation: mean reprojection error (px)", f"{rep['opt']:.3f}",
         f"{rep['opt_their']:.3f}", "<= aniposelib"),
        ("optimisation: time (whole trial)", f"{t_o_our:.2f} s", f"{t_o_their:.2f} s", ""),
        ("optimisation: speed-up (best times; rounds: low / high)",
         f"{t_o_their / t_o_our:.1f}x ({min(o_ratios):.1f}x / {max(o_ratios):.1f}x)", "",
         ">= 3x"),
        ("mean reprojection error: linear / RANSAC (all points, px)",
         f"{rep['lin']:.3f} / {rep['ran']:.3f}", "", ""),
    ]
    print_table(rows, results=("VideoTrack", "aniposelib"))
    return rows


def ring_cameras(n=4):
    k = [[1000.0, 0, 639.5], [0, 1000.0, 511.5], [0, 0, 1]]
    cams = []
    for i in range(n):
        r = euler_yxz(2 * np.pi * i / n + 0.3, 0.35, 0.05 * i).T
        centre = r.T @ np.array([0.0, 0.0, -500.0])
        cams.append(PinholeCamera(f"cam{i}", k, [-0.2, 0.06, 0.001, -0.001, 0.0], R=r,
                                  t=-r @ centre, size=(1280, 1024)))
    return cams


def synthetic(n_frames=600, n_points=8, seed=0):
    """A chain of 20 mm segments moving through known postures, 4 cameras, 2 px noise, 10 %
    of keypoints swapped with a neighbour's or missing."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames)[:, None]
    ang = (0.5 * np.sin(0.07 * t + rng.uniform(0, 6, n_points))
           + np.linspace(0, 2.0, n_points))
    seg = np.stack([np.cos(ang), np.sin(ang), 0.4 * np.sin(0.8 * ang + 0.03 * t)], -1)
    seg *= 20.0 / np.linalg.norm(seg, axis=-1, keepdims=True)
    truth = np.cumsum(seg, axis=1) + np.stack(
        [30 * np.sin(0.02 * t[:, 0]), 10 * np.cos(0.03 * t[:, 0]), np.zeros(n_frames)],
        -1)[:, None] - np.array([60.0, 20.0, 0.0])
    cams = ring_cameras()
    xy = np.stack([c.project(truth) for c in cams])
    xy += rng.normal(0, 2.0, xy.shape)
    bad = rng.random(xy.shape[:3]) < 0.10
    swap = bad & (rng.random(xy.shape[:3]) < 0.5)
    c, f, j = np.nonzero(swap)
    xy[c, f, j] = xy[c, f, (j + 1) % n_points]
    xy[bad & ~swap] = np.nan
    return cams, truth, xy, [(i, i + 1) for i in range(n_points - 1)]


def synthetic_case() -> list:
    cams, truth, xy, limbs = synthetic()
    f, j = truth.shape[:2]
    seg = np.full(len(limbs), 20.0)
    runs = {
        "linear (DLT)": lambda: triangulate_linear(cams, xy),
        "RANSAC (aniposelib semantics)": lambda: triangulate_ransac(cams, xy),
        "RANSAC, min 3 cameras, inliers within 10 px": lambda: triangulate_ransac(
            cams, xy, min_cams=3, good_px=0.0, inlier_px=10.0),
        "optimisation from linear, unknown lengths": lambda: triangulate_optim(
            cams, xy, limbs=limbs, **OPTIM),
        "optimisation from RANSAC (3 cams, 10 px), unknown lengths": lambda: triangulate_optim(
            cams, xy, limbs=limbs, init="ransac", min_cams=3, good_px=0.0, inlier_px=10.0,
            **OPTIM),
        "optimisation from RANSAC (3 cams, 10 px), given lengths": lambda: triangulate_optim(
            cams, xy, limbs=limbs, limb_lengths=seg, init="ransac", min_cams=3, good_px=0.0,
            inlier_px=10.0, **OPTIM),
    }
    print(f"\n### Synthetic truth: {f} frames x {j} points on a chain, 4 cameras at 500 mm, "
          "2 px noise, 10 % of keypoints swapped or missing\n")
    rows = []
    for name, fn in runs.items():
        dt, res = best_time(fn, 2)
        e = np.linalg.norm(res.xyz - truth, axis=-1)
        ok = np.isfinite(e)
        lengths = np.linalg.norm(np.diff(res.xyz, axis=1), axis=-1)
        rows.append((name, f"{np.mean(e[ok]):.2f}", f"{np.median(e[ok]):.2f}",
                     f"{np.percentile(e[ok], 95):.2f}", f"{100 * ok.mean():.1f} %",
                     f"{np.nanstd(lengths):.2f}", f"{dt:.2f} s"))
    print_table(rows, target="time",
                results=("mean 3D error (mm)", "median (mm)", "95th pct (mm)", "points placed",
                         "SD of segment lengths (mm, true 20)"))
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path,
                        default=Path(__file__).resolve().parents[2] / "shared" / "data")
    parser.add_argument("--repeat", type=int, default=5,
                        help="rounds of the linear timings (best of N)")
    args = parser.parse_args()
    print(f"machine: {machine()}")
    try:
        import aniposelib  # noqa: F401
        import jax  # noqa: F401
    except ImportError as err:
        print(f"aniposelib comparison skipped: {err}")
    else:
        for load in (mouse, pose2sim):
            try:
                real_session(load, args.data, args.repeat)
            except FileNotFoundError as err:
                print(f"\n(skipped: {err})")
    synthetic_case()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
