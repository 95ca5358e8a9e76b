"""Table 2 of the paper, reproduced: joint-angle accuracy of the fit on an artificial video.

Run from the repository root::

    python bench/bench_table2.py [--frames 668] [--seed 0] [--threshold 1] [--cap 10]

Protocol (paper Sect. 3.2): the locust hind-leg chain shipped in ``chains/locust_hindleg.xml``
(coxa 13, femur 91, tibia 77 px), two orthographic views side and top
(``videotrack.synth.paper_setup.locust_cameras``), 4-px markers at the joint centres and the tibia
tip, ``--frames`` frames made of 10 concatenated smooth random movement sequences
(``videotrack.synth.motion.smooth_random_motion``), rendered anti-aliased by
``videotrack.synth.project`` into
a lossless FFV1 video, markers detected by ``videotrack.detect.run`` (threshold 125, intensity-
weighted centroids), fitted with the Table 1 defaults. Reported: per-axis RMSE of φ, ψ, α, β,
α+β, γ for both views, the side view only and the top view only, with the paper's values; the
view error E; the same with 2 static + 2 flickering ghost markers per view and 2 %
occlusions; the clean video with binary centroids (paper-like detection noise); with
Levenberg-Marquardt refinement, next to the Cramér-Rao bound of the
measured centroid noise (``kinematics.fit.refine.cramer_rao_bound`` at each true posture, marker
images that were occluded left out); and a sweep of shorter annealing schedules with
refinement and a re-analysis threshold suited to refined errors.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.error_function import ErrorOptions
from kinematics.fit.refine import cramer_rao_bound
from kinematics.model.chain_xml import load_body
from videotrack.detect.detections import DetectSettings
from videotrack.detect.filters import FilterChain
from videotrack.detect.markers import MarkerSettings
from videotrack.detect.run import detect_video
from videotrack.detect.video import VideoSource
from videotrack.detect.views import View
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import bundled_chain, locust_cameras
from videotrack.synth.project import (
    SynthOptions,
    VideoSink,
    camera_sizes,
    iter_frames,
    simulate,
    view_rois,
)

AXES = ("φ", "ψ", "α", "β", "α+β", "γ")
PAPER = {
    "both views": (1.7, 1.5, 4.7, 4.9, 0.7, 0.7),
    "side view": (20.8, 17.4, 3.9, 3.6, 3.1, 3.5),
    "top view": (14.7, 10.4, 23.7, 29.6, 23.4, 52.4),
}
#: Posture columns of φ, ψ, α, β, γ in the locust chain, and α+β as a combination of them.
COLUMNS = (0, 1, 2, 5, 8)
ALPHA_BETA = np.array([0, 0, 1, 1, 0])


class OneView:
    """The detections of a single view, as a detections-like record for a one-camera fit."""

    def __init__(self, det, view: int) -> None:
        counts = det.counts()[:, view]
        self.points = np.concatenate([det.points_of(r, view) for r in range(det.n_records)])
        self.offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.view_names = [det.view_names[view]]


def render_and_detect(body, cams, angles, options: SynthOptions, folder: Path,
                      weighting: str = "intensity"):
    """Synthetic video of the chain through the cameras, then marker detection."""
    scene = simulate(body, cams, angles, options)
    sizes = camera_sizes(cams)
    path = folder / f"table2_{options.seed}_{options.static_ghosts}.avi"
    with VideoSink(path, 50.0, "ffv1") as sink:
        for frame in iter_frames(scene, sizes, options):
            sink.write(frame[0])
        sink.commit()
    views = tuple(View(name, roi) for name, roi in zip(cams, view_rois(sizes, options.layout),
                                                       strict=True))
    settings = DetectSettings(views, FilterChain([{"type": "threshold", "value": 125}]),
                              MarkerSettings(min_area=2, weighting=weighting))
    return scene, detect_video(VideoSource(path), settings)


#: A detected centroid farther than this from its marker's true image is a fused or
#: disturbed marker, not centroid noise.
FUSED_PX = 0.3


def centroid_residuals(scene, det) -> np.ndarray:
    """Detected minus true marker images, shape (n_frames, n_views, n_markers, 2); NaN where
    the marker is occluded or no detection lies within 2 px."""
    out = np.full(scene.projections.shape, np.nan)
    for r in range(det.n_records):
        for v in range(det.n_views):
            pts = det.points_of(r, v)
            if not len(pts):
                continue
            for m in np.flatnonzero(scene.visible[r, v]):
                d = np.linalg.norm(pts - scene.projections[r, v, m], axis=1)
                if d.min() <= 2.0:
                    out[r, v, m] = pts[d.argmin()] - scene.projections[r, v, m]
    return out


def noise_model(res: np.ndarray) -> tuple[float, float, np.ndarray, int]:
    """The measured centroid noise: RMS per coordinate over all found images, the same
    without fused images, the correlation of each image coordinate between the two views
    (the side and top views share u at the same pixel phase), and the fused count."""
    flat = res.reshape(-1, 2)
    found = np.isfinite(flat).all(axis=1)
    fused = found & (np.abs(flat).max(axis=1) > FUSED_PX)
    clean = found & ~fused
    sigma_all = float(np.sqrt(np.mean(flat[found] ** 2)))
    sigma = float(np.sqrt(np.mean(flat[clean] ** 2)))
    r = np.where((np.abs(res) <= FUSED_PX).all(axis=-1, keepdims=True), res, np.nan)
    rho = np.array([np.ma.corrcoef(np.ma.masked_invalid(r[:, 0, :, c].ravel()),
                                   np.ma.masked_invalid(r[:, 1, :, c].ravel()))[0, 1]
                    for c in range(2)])
    return sigma_all, sigma, rho, int(fused.sum())


def covariance(sigma: float, rho: np.ndarray, n_markers: int) -> np.ndarray:
    """Centroid covariance in :func:`kinematics.fit.refine.projection_jacobian` row order (view,
    marker, coordinate) for two views: σ² on the diagonal, ρ_c σ² between the two views'
    coordinate c of the same marker."""
    n = 2 * 2 * n_markers
    cov = sigma**2 * np.eye(n)
    for m in range(n_markers):
        for c in range(2):
            a, b = (0 * n_markers + m) * 2 + c, (1 * n_markers + m) * 2 + c
            cov[a, b] = cov[b, a] = rho[c] * sigma**2
    return cov


def angle_errors(results, truth) -> np.ndarray:
    """Signed errors of φ, ψ, α, β, α+β, γ per frame, shape (n_frames, 6); NaN rows for
    frames without a fit."""
    ang = np.array([r.angles_deg for r in results])
    err = ang[:, COLUMNS] - truth[:, COLUMNS]
    return np.column_stack([err[:, :4], err[:, 2] + err[:, 3], err[:, 4]])


def rmse_row(results, truth) -> tuple[np.ndarray, float, float, int, int]:
    err = angle_errors(results, truth)
    ok = np.isfinite(err).all(axis=1)
    e = np.array([r.error for r in results])[ok]
    failed = sum(r.status == "failed" for r in results)
    rerun = sum(r.runs > 1 for r in results)
    return np.sqrt((err[ok] ** 2).mean(axis=0)), float(e.mean()), float(e.std()), rerun, failed


def bounds(fitter, truth, visible, noise) -> np.ndarray:
    """Cramér-Rao bounds of φ, ψ, α, β, α+β, γ per frame, shape (n_frames, 6)."""
    out = []
    for k in range(len(truth)):
        b = cramer_rao_bound(fitter, truth[k], noise, visible=visible[k], combos=[ALPHA_BETA])
        out.append(b[[0, 1, 2, 3, 5, 4]])
    return np.array(out)


def rms(a, axis=0):
    return np.sqrt(np.mean(np.square(a), axis=axis))


def crb_block(fitter, results, truth, scene, res, label) -> None:
    """Refined RMSE against the Cramér-Rao bound, on the frames the fit calls good."""
    sigma_all, sigma, rho, n_fused = noise_model(res)
    err = angle_errors(results, truth)
    good = np.array([r.ok for r in results]) & np.isfinite(err).all(axis=1)
    b_iid = bounds(fitter, truth, scene.visible, sigma)
    b_cor = bounds(fitter, truth, scene.visible, covariance(sigma, rho, 4))
    mirror = good & (np.abs(err) > 6 * b_cor).any(axis=1)
    kept = good & ~mirror
    print(f"\nAgainst the Cramér-Rao bound ({label}). Centroid noise: {sigma_all:.3f} px RMS per "
          f"coordinate over all found marker images, {sigma:.4f} px without the {n_fused} "
          f"fused ones (> {FUSED_PX} px off); correlation between the views: u {rho[0]:.2f}, "
          f"v {rho[1]:.2f}. Frames: {good.sum()} of {len(results)} good (status ok or "
          f"re-analysed), {mirror.sum()} of them in a mirror posture (error > 6 bounds: "
          f"frames {np.flatnonzero(mirror).tolist()}).\n")
    print(f"| refined, good frames | {' | '.join(AXES)} |")
    print("| --- " * (len(AXES) + 1) + "|")
    rm, rk = rms(err[good]), rms(err[kept])
    cb_i, cb_c = rms(b_iid[good]), rms(b_cor[good])
    print(f"| RMSE, all {good.sum()} good frames | {fmt(rm)} |")
    print(f"| RMSE without the {mirror.sum()} mirror postures | {fmt(rk)} |")
    print(f"| bound, independent noise {sigma:.4f} px | {fmt(cb_i)} |")
    print(f"| bound, with the measured view correlation | {fmt(cb_c)} |")
    print(f"| ratio (without mirror postures) / correlated bound | "
          f"{fmt(rk / rms(b_cor[kept]), 2)} |")
    # The estimator alone: the true images plus independent Gaussian noise of that sigma.
    rng = np.random.default_rng(1)
    planted = []
    for k in range(len(truth)):
        planted.append([scene.projections[k, v][scene.visible[k, v]]
                        + rng.normal(0, sigma, (scene.visible[k, v].sum(), 2))
                        for v in range(2)])
    p_res = fitter.fit(planted)
    p_err = angle_errors(p_res, truth)
    p_good = np.array([r.ok for r in p_res]) & np.isfinite(p_err).all(axis=1)
    p_good &= ~(np.abs(p_err) > 6 * b_iid).any(axis=1)
    print(f"| planted images + independent noise {sigma:.4f} px: RMSE / bound "
          f"({p_good.sum()} frames) | {fmt(rms(p_err[p_good]) / rms(b_iid[p_good]), 2)} |")


def fmt(values, digits: int | None = None) -> str:
    """Table cells; small values get more digits."""
    out = []
    for v in values:
        d = digits if digits is not None else (2 if abs(v) >= 0.1 else 3)
        out.append(f"{v:.{d}f}")
    return " | ".join(out)


def print_header() -> None:
    print(f"| fit | {' | '.join(AXES)} | E mean ± SD (px) | re-run | failed | fit time |")
    print("| --- " * (len(AXES) + 5) + "|")


def run_fit(name, body, cams, det, params, truth) -> tuple[np.ndarray, Fitter, list]:
    fitter = Fitter(body, cams, params)
    t0 = time.perf_counter()
    results = fitter.fit(det)
    dt = time.perf_counter() - t0
    rmse, e_mean, e_sd, rerun, failed = rmse_row(results, truth)
    print(f"| {name} | {fmt(rmse)} | {e_mean:.2f} ± {e_sd:.2f} | {rerun} | {failed} | "
          f"{dt:.1f} s |")
    return rmse, fitter, results


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=668)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threshold", type=float, default=1.0,
                    help="re-analysis threshold (px) of the refined fits; about 10x the "
                         "typical refined E")
    ap.add_argument("--cap", type=float, default=10.0,
                    help="marker cap (px) of the recommended fit with ghosts and occlusions")
    ap.add_argument("--sweep", default="20000,10000,5000,2000,1000,500,300",
                    help="N_end values of the schedule sweep with refinement ('' to skip)")
    args = ap.parse_args()
    with bundled_chain("locust_hindleg.xml") as path:
        body = load_body(path)
    cams = locust_cameras()
    truth = smooth_random_motion(body, args.frames, 10, seed=args.seed)
    table1 = AnnealParams.paper()
    refined = AnnealParams.paper(refine=True, reanalysis_threshold=args.threshold)
    robust = replace(refined, error=ErrorOptions(cap_px=args.cap))
    clean = SynthOptions(marker_diameter=4.0, seed=args.seed)
    scenarios = [  # label, video, centroid rule, full analysis
        ("clean", clean, "intensity", True),
        ("2 static + 2 flickering ghosts per view, 2 % occlusions", SynthOptions(
            marker_diameter=4.0, seed=args.seed, static_ghosts=2, flicker_ghosts=2,
            occlusion_fraction=0.02), "intensity", True),
        ("clean, binary centroids (paper-like detection noise)", clean, "binary", False),
    ]
    print(f"Table 2 analogue: {args.frames} frames in 10 sequences, seed {args.seed}, "
          f"{numba.get_num_threads()} threads; {platform.machine()}, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.2f} at the start")
    with tempfile.TemporaryDirectory() as tmp:
        for label, options, weighting, full in scenarios:
            t0 = time.perf_counter()
            scene, det = render_and_detect(body, cams, truth, options, Path(tmp), weighting)
            res = centroid_residuals(scene, det)
            sigma_all, sigma, _, n_fused = noise_model(res)
            print(f"\n### {label}\n\nRendered and detected in {time.perf_counter() - t0:.1f} s;"
                  f" centroid noise {sigma_all:.3f} px RMS per coordinate ({sigma:.4f} px "
                  f"without the {n_fused} fused marker images).\n")
            print_header()
            run_fit("both views (Table 1)", body, cams, det, table1, truth)
            if not full:
                run_fit("both views + refine", body, cams, det, replace(table1, refine=True),
                        truth)
                run_fit("both views + refine, threshold 5 px", body, cams, det,
                        replace(refined, reanalysis_threshold=5.0), truth)
                continue
            run_fit("side view only", body, {"side": cams["side"]}, OneView(det, 0), table1,
                    truth)
            run_fit("top view only", body, {"top": cams["top"]}, OneView(det, 1), table1, truth)
            run_fit("both views + refine", body, cams, det, replace(table1, refine=True),
                    truth)
            best = refined if label == "clean" else robust
            what = (f"refine, threshold {args.threshold:g} px" if label == "clean" else
                    f"refine, threshold {args.threshold:g} px, cap {args.cap:g} px")
            _, fitter, results = run_fit(f"both views + {what}", body, cams, det, best, truth)
            for name, paper in PAPER.items():
                extra = "2.9 ± 1.1" if name == "both views" else ""
                print(f"| paper, {name} | {fmt(paper, 1)} | {extra} | | | |")
            crb_block(fitter, results, truth, scene, res, f"both views + {what}")
            if args.sweep:
                print(f"\nSchedule sweep, both views + {what} (N_l, N_τ scaled):\n")
                print_header()
                for n_end in (int(v) for v in args.sweep.split(",")):
                    run_fit(f"N_end {n_end}", body, cams, det, best.with_schedule(n_end), truth)
    return 0


if __name__ == "__main__":
    sys.exit(main())
