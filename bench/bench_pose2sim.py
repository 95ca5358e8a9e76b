"""VideoTrack's triangulation of the Pose2Sim demo against Pose2Sim's own 3D output.

``../shared/data`` item 6 (``pose2sim_demo``): 4 cameras with an independent Qualisys
calibration (``calibration/Calib.qca.txt``, mm, with its true lens distortion; the converted
toml's distortions are divided by 64, so it is not used), OpenPose BODY_25B JSON per camera
(person 0, keypoints with confidence < 0.3 dropped, as Pose2Sim's config does) and Pose2Sim's
TRC files (m, Y-up: trc (X, Y, Z) = Z-up (Y, Z, X)). The JSON is triangulated with the linear
(DLT), RANSAC and optimisation backends of ``kinematics.observe.triangulation`` and every result is
compared, marker by marker (matched by name), with Pose2Sim's raw triangulation
(``*_0-100.trc``) and with its Butterworth-filtered version (``*_filt_butterworth.trc``); the
LSTM file's first 21 markers are the filtered ones and its other 43 are augmented markers
with no keypoint counterpart.

Backends: ``linear`` (DLT weighted by confidence, as Pose2Sim's weighted triangulation),
``linear unweighted`` (the README's plain DLT), ``ransac`` (defaults: the best camera subset,
stopping under 0.5 px), ``ransac 15px`` (stop at the first subset under 15 px and re-solve
over every camera within 15 px: close to Pose2Sim's 15 px camera exclusion) and ``optim``
(Anipose-style, BODY_25B limbs, defaults). Pose2Sim itself used the converted toml without
undistortion; here the qca's true distortion is used, so points seen by all cameras differ
by the lens model (~1-5 mm), and points where Pose2Sim dropped a camera differ by more.

The README's reference figure (a plain DLT with the toml calibration): within ~0.1-6 cm of
the Pose2Sim trc, nose/neck/ankles/wrists < 1 cm, hips/knees/shoulders 2-6 cm. A group
"meets" it when its median distance is below the group's upper bound.

    python bench/bench_pose2sim.py [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _report import machine, print_table

from kinematics.observe.triangulation import (
    triangulate_linear,
    triangulate_optim,
    triangulate_ransac,
)
from videotrack.io.camera_formats import load_qca
from videotrack.io.keypoints import align_cameras, read_keypoints
from videotrack.io.trc import read_trc

DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
MIN_SCORE = 0.3
VIEWS = ("cam01", "cam02", "cam03", "cam04")
BODY_25B_LIMBS = [("LHip", "LKnee"), ("LKnee", "LAnkle"), ("RHip", "RKnee"),
                  ("RKnee", "RAnkle"), ("LShoulder", "LElbow"), ("LElbow", "LWrist"),
                  ("RShoulder", "RElbow"), ("RElbow", "RWrist")]
#: body part groups: (name, keypoints, README's upper bound on the distance in cm)
GROUPS = [
    ("nose/neck/head", ("Nose", "Neck", "Head"), 1.0),
    ("wrists", ("LWrist", "RWrist"), 1.0),
    ("ankles/feet", ("LAnkle", "RAnkle", "LBigToe", "LSmallToe", "LHeel", "RBigToe",
                     "RSmallToe", "RHeel"), 1.0),
    ("hips", ("LHip", "RHip"), 6.0),
    ("knees", ("LKnee", "RKnee"), 6.0),
    ("shoulders/elbows", ("LShoulder", "RShoulder", "LElbow", "RElbow"), 6.0),
]
REFERENCE = {"nose/neck/head": "< 1 cm (nose, neck)", "wrists": "< 1 cm",
             "ankles/feet": "< 1 cm (ankles)", "hips": "2-6 cm", "knees": "2-6 cm",
             "shoulders/elbows": "2-6 cm (shoulders)", "overall": "~0.1-6 cm"}


def trc_to_zup_mm(points: np.ndarray, units: str) -> np.ndarray:
    """Pose2Sim's Y-up TRC (X, Y, Z) = Z-up (Y, Z, X): back to the calibration's Z-up, mm."""
    scale = {"m": 1000.0, "cm": 10.0, "mm": 1.0}[units.strip().lower()]
    return scale * points[..., [2, 0, 1]]


def load(data: Path):
    root = data / "pose2sim_demo"
    cams = load_qca(root / "calibration" / "Calib.qca.txt")
    tracks = {v: read_keypoints(root / "balancing_trial" / "pose_openpose_json" / f"{v}_json",
                                model="BODY_25B", individual=0) for v in VIEWS}
    names, frames, xy, score = align_cameras(tracks)
    out = root / "balancing_trial" / "pose-3d_pose2sim_output"
    trcs = {"raw": read_trc(out / "S00_P00_T01_BalancingTrial_0-100.trc"),
            "Butterworth": read_trc(out / "S00_P00_T01_BalancingTrial_0-100_filt_butterworth.trc")}
    return cams, names, frames, xy, score, trcs


def reference_points(trc, names, frames) -> tuple[np.ndarray, list[str]]:
    """TRC points on our frames and keypoints (NaN where the TRC has no such marker)."""
    ref = np.full((len(frames), len(names), 3), np.nan)
    rows = {int(f): i for i, f in enumerate(trc.frames)}
    pts = trc_to_zup_mm(trc.points, trc.units)
    matched = [n for n in names if n in trc.names]
    for j, n in enumerate(names):
        if n in trc.names:
            k = trc.names.index(n)
            for i, f in enumerate(frames):
                if int(f) in rows:
                    ref[i, j] = pts[rows[int(f)], k]
    return ref, matched


def stats_cm(d: np.ndarray) -> tuple[float, float, int]:
    d = d[np.isfinite(d)]
    if not d.size:
        return np.nan, np.nan, 0
    return float(np.median(d)) / 10.0, float(np.percentile(d, 90)) / 10.0, int(d.size)


def residuals(cams, xy, xyz) -> np.ndarray:
    """(n_cams, n_frames, n_points) pixel distance between projection and keypoint (NaN
    where the keypoint did not pass the score threshold or the point is missing)."""
    proj = np.stack([c.project(xyz.reshape(-1, 3)).reshape((*xyz.shape[:-1], 2))
                     for c in cams])
    return np.linalg.norm(proj - xy, axis=-1)


def median_residual(cams, xy, xyz) -> float:
    """Median over every (camera, frame, keypoint) residual (the README's 12.4 px figure)."""
    err = residuals(cams, xy, xyz)
    return float(np.nanmedian(err)) if np.isfinite(err).any() else np.nan


def median_reprojection(cams, xy, xyz) -> float:
    """Median over (frame, keypoint) of the mean pixel error over the cameras whose keypoint
    passed the score threshold (the same measure for every backend and for Pose2Sim)."""
    err = residuals(cams, xy, xyz)
    with np.errstate(all="ignore"):
        per_point = np.nanmean(np.where(np.isfinite(err), err, np.nan), axis=0)
    per_point = per_point[np.isfinite(per_point)]
    return float(np.median(per_point)) if per_point.size else np.nan


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = ap.parse_args(argv)
    if not (args.data / "pose2sim_demo").is_dir():
        print(f"skipped: {args.data / 'pose2sim_demo'} not found")
        return 0

    print(f"machine: {machine()}")
    cams, names, frames, xy, score, trcs = load(args.data)
    cam_list = list(cams.values())
    print(f"cameras (Qualisys qca, mm, true distortion): {', '.join(cams)} -> "
          f"OpenPose {', '.join(VIEWS)}")
    seen = np.where(np.isfinite(score), score, 0.0) >= MIN_SCORE
    xy = np.where(seen[..., None], xy, np.nan)
    _, n_frames, n_kp, _ = xy.shape
    print(f"{n_frames} frames x {n_kp} BODY_25B keypoints, min score {MIN_SCORE}; keypoints "
          f"kept per camera: "
          + ", ".join(f"{v} {seen[c].mean():.0%}" for c, v in enumerate(VIEWS)))
    limbs = [(names.index(a), names.index(b)) for a, b in BODY_25B_LIMBS]

    results = {}
    opts = dict(score=score, min_score=MIN_SCORE)  # weighted by confidence, like Pose2Sim
    backends = (
        ("linear", lambda: triangulate_linear(cam_list, xy, **opts)),
        ("linear unweighted", lambda: triangulate_linear(cam_list, xy, **opts, weighted=False)),
        ("ransac", lambda: triangulate_ransac(cam_list, xy, **opts)),
        ("ransac 15px", lambda: triangulate_ransac(cam_list, xy, **opts, good_px=15.0,
                                                   inlier_px=15.0)),
        ("optim", lambda: triangulate_optim(cam_list, xy, **opts, limbs=limbs)),
    )
    for label, fn in backends:
        t0 = time.perf_counter()
        res = fn()
        results[label] = (res, time.perf_counter() - t0)

    refs = {}
    for key, trc in trcs.items():
        ref, matched = reference_points(trc, names, frames)
        refs[key] = ref
        unmatched_kp = [n for n in names if n not in trc.names]
        unmatched_trc = [n for n in trc.names if n not in names]
        print(f"\nPose2Sim {key} TRC ({trc.units}, {len(trc.frames)} frames): "
              f"{len(matched)} markers matched by name: {', '.join(matched)}; "
              f"keypoints without a marker: {', '.join(unmatched_kp) or 'none'}; "
              f"markers without a keypoint: {', '.join(unmatched_trc) or 'none'}")
    raw_ok = np.isfinite(refs["raw"]).all(axis=-1)[:, [names.index(n) for n in matched]]
    raw_frames = int(raw_ok.any(axis=1).sum())
    print(f"Pose2Sim raw TRC: {raw_ok.sum()} of {raw_ok.size} matched marker-frames present, "
          f"{raw_frames} frames with any")

    for key, ref in refs.items():
        print(f"\n### Distance to Pose2Sim's {key} TRC (cm): median / 90th percentile\n")
        rows = []
        for group, members, bound in [*GROUPS, ("overall", tuple(names), 6.0)]:
            idx = [names.index(n) for n in members if n in names]
            cells, meets = [], []
            for res, _ in results.values():
                d = np.linalg.norm(res.xyz[:, idx] - ref[:, idx], axis=-1)
                med, p90, n = stats_cm(d)
                cells.append(f"{med:.2f} / {p90:.2f} (n={n})")
                meets.append(med <= bound)
            verdict = "yes" if all(meets) else (
                "no" if not any(meets) else
                "partly: " + ", ".join(lb for lb, m in zip(results, meets, strict=True) if m))
            rows.append((group, *cells, f"{REFERENCE[group]}; meets: {verdict}"))
        print_table(rows, target="README reference", results=tuple(results))

    print("\n### Per keypoint: median distance to Pose2Sim's raw TRC (cm)\n")
    rows = []
    for n in matched:
        j = names.index(n)
        dist = [np.linalg.norm(r.xyz[:, j] - refs["raw"][:, j], axis=-1)
                for r, _ in results.values()]
        rows.append((n, *(f"{stats_cm(d)[0]:.2f}" for d in dist), ""))
    print_table(rows, target="", results=tuple(results))

    print("\n### Reprojection error and frames reconstructed (21 matched keypoints)\n")
    m_idx = [names.index(n) for n in names if n in trcs["raw"].names]
    rows = []
    entries = [(label, res.xyz, f"{np.nanmedian(res.error[:, m_idx]):.2f}", f"{dt:.2f} s", "")
               for label, (res, dt) in results.items()]
    entries.append(("Pose2Sim raw TRC", refs["raw"], "", "",
                    "README: 12.4 px all residuals (unweighted DLT, toml, 25 keypoints)"))
    for label, xyz, used_err, dt, note in entries:
        ok = np.isfinite(xyz[:, m_idx]).all(axis=-1)
        sub_xy, sub_xyz = xy[:, :, m_idx], xyz[:, m_idx]
        rows.append((label, f"{median_reprojection(cam_list, sub_xy, sub_xyz):.2f}",
                     f"{median_residual(cam_list, sub_xy, sub_xyz):.2f}", used_err,
                     f"{int(ok.any(axis=1).sum())} / {n_frames}",
                     f"{int(ok.all(axis=1).sum())}", f"{ok.mean():.1%}", dt, note))
    print_table(rows, target="note", results=(
        "median reproj. px (per point, all cams >= 0.3)",
        "median px (all residuals)", "median reproj. px (per point, cams used)",
        "frames with any point", "frames with all points", "keypoints present",
        "time (first call, incl. compilation)"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
