"""A freely moving mouse hind limb: real 3D motion rendered as marker videos and fitted.

Run from the repository root::

    python bench/bench_mouse_free.py [--frames 300] [--side left] [--root both]
                                     [--n-end 10000] [--threshold 25] [--out DIR]

Data: ``../shared/data/mouse_marker_mocap_oist/*.mat`` (Qualisys, 300 Hz, 10 500 frames, 11
labelled markers in mm with gaps; ../shared/data/README.md item 2), read at run time; the
benchmark exits 0 with a message when it is absent. Nothing of it is copied into the
repository: every derived file (points, cameras, chain, videos) goes to ``--out`` (default a
temporary folder).

Protocol:

1. The stretch of ``--frames`` frames where the hip, knee and ankle of ``--side`` and the four
   pelvis markers (both hips, both coord markers: rigid within 0.2-0.6 mm IQR; the back
   markers sit on the flexible spine and are left out) are most often all valid.
2. A chain is built from the frames outside that stretch (never the rendered ones): root =
   the hip marker of that side; root joint = pelvis orientation (3 axes) whose zero-length
   segment carries the four pelvis markers at their median offsets in a pelvis frame (origin
   at the hip, z from left to right hip, x toward the coord markers); hip joint (3 axes) ->
   femur (median hip-knee length; knee marker) -> knee hinge (one free axis, the knee angle)
   -> tibia (median knee-ankle length; ankle marker). Default orientations are the mean
   pelvis and femur orientations; ranges are the 0.5-99.5 percentiles of the observed angles
   +- ``--margin`` degrees.
3. Three pinhole cameras (1280x1024 px, f = 1500 px, 340-450 mm from the mouse) around the
   treadmill on the side of the leg, written as a camera TOML; every marker is checked to
   stay inside every image.
4. The stretch (world: x anterior, y up, z right; mm) is written as a points CSV and rendered
   by ``videotrack synth --points`` (``videotrack.synth.project.write_points_project``),
   6-px markers,
   one FFV1 video per camera; markers absent in the mocap are not drawn. Markers are detected
   with the written project file (``videotrack detect``: ``detect_project``).
5. Fits (refinement on, the schedule shortened to ``--n-end`` with N_l, N_tau scaled, re-
   analysis threshold ``--threshold`` px on E summed over 3 views x 6 markers, marker cost
   capped at ``--cap`` px): ``--root true``: root mode fixed, the true hip marker passed as
   the root of each frame (``Fitter.fit_frame``), the pelvis orientation fitted by its three
   axes; ``--root free``: ``<root mode="free" marker=HIP/>``, ``Fitter.iter_fit`` places the
   body itself (only once the fitter supports the free root; else reported as unavailable).
   The floor: the same chain fitted directly to the true 3D points by scipy least squares over
   the root position and all angles, per frame.

Reported, on the frames where every marker is seen by >= 2 cameras: median, p95 and max 3D
error of the fitted hip, knee and ankle markers against the true ones (mm), knee-angle RMSE
(the angle between hip->knee and knee->ankle, true vs fitted; degrees), frames/s of fitting.
A PNG of the knee angle and the 3D errors over time goes to ``--out``.
"""

from __future__ import annotations

import argparse
import glob
import os
import sys
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import in_out_folder, machine, print_table  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "mouse_marker_mocap_oist"
PELVIS = ("left_hip", "right_hip", "left_coord", "right_coord")
TARGETS = {"median": 1.0, "p95": 2.0, "max": 5.0, "knee": 4.0}
FPS = 300.0


# -- data --------------------------------------------------------------------------------------
def load_mocap(folder: Path) -> tuple[list[str], np.ndarray]:
    """Labels and marker positions (n_frames, n_markers, 3) in the chain's world frame (mm):
    x anterior (Qualisys x), y up (Qualisys z), z to the right (-Qualisys y)."""
    import scipy.io as sio

    m = sio.loadmat(glob.glob(str(folder / "*.mat"))[0], struct_as_record=False)
    s = m[next(k for k in m if not k.startswith("__"))][0, 0]
    lab = s.Trajectories[0, 0].Labeled[0, 0]
    labels = [str(x[0]) for x in lab.Labels.ravel()]
    xyz = lab.Data[:, :3, :].transpose(2, 0, 1)
    return labels, np.stack([xyz[..., 0], xyz[..., 2], -xyz[..., 1]], axis=-1)


def choose_stretch(valid: np.ndarray, n: int) -> int:
    """First frame of the n-frame window with the most all-valid frames."""
    counts = np.convolve(valid.astype(float), np.ones(n), "valid")
    return int(np.argmax(counts))


# -- geometry ----------------------------------------------------------------------------------
def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def frames_from(x, z_hint):
    """Rotation matrices (..., 3, 3) whose columns are x (unit x), y = z × x, z (z_hint made
    orthogonal to x)."""
    x = unit(x)
    z = unit(z_hint - (z_hint * x).sum(-1, keepdims=True) * x)
    return np.stack([x, np.cross(z, x), z], axis=-1)


def pelvis_frames(p):
    """World orientation of the pelvis frame per frame from the four pelvis markers
    (n, 4, 3) in PELVIS order: z from left to right hip, x toward the coord markers."""
    lh, rh, lc, rc = p[:, 0], p[:, 1], p[:, 2], p[:, 3]
    z = unit(rh - lh)
    forward = 0.5 * (lc + rc) - 0.5 * (lh + rh)
    return frames_from(np.cross(np.cross(z, forward), z), z)


def femur_frames(hip, knee, ankle):
    """x along hip -> knee, z the knee hinge axis (femur × tibia), per frame."""
    f, t = knee - hip, ankle - knee
    return frames_from(f, np.cross(f, t))


def knee_angle_deg(hip, knee, ankle):
    """Angle between hip -> knee and knee -> ankle (0 = straight leg), degrees."""
    f, t = unit(knee - hip), unit(ankle - knee)
    return np.degrees(np.arccos(np.clip((f * t).sum(-1), -1, 1)))


def euler_deg(R):
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_euler("YXZ", degrees=True)  # R = Ry·Rx·Rz


def mean_rotation(R):
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).mean().as_matrix()


def fmt3(v):
    return " ".join(f"{x:.6g}" for x in v)


def build_chain(cal, side: str, margin: float, root_xml: str) -> tuple[str, dict]:
    """Chain XML from calibration frames ``cal`` (name -> (n, 3) all valid)."""
    hip, knee, ankle = cal[f"{side}_hip"], cal[f"{side}_knee"], cal[f"{side}_ankle"]
    P = pelvis_frames(np.stack([cal[m] for m in PELVIS], axis=1))
    offsets = {m: np.median(np.einsum("nji,nj->ni", P, cal[m] - hip), axis=0) for m in PELVIS}
    F = femur_frames(hip, knee, ankle)
    femur = float(np.median(np.linalg.norm(knee - hip, axis=1)))
    tibia = float(np.median(np.linalg.norm(ankle - knee, axis=1)))
    p0 = mean_rotation(P)
    h_rel = np.einsum("nji,njk->nik", P, F)  # femur frame in the pelvis frame
    h0 = mean_rotation(h_rel)
    pelvis_ang = euler_deg(P @ p0.T)
    hip_ang = euler_deg(h_rel @ h0.T)
    knee_ang = knee_angle_deg(hip, knee, ankle)

    def ranges(a, lo=-180.0, hi=180.0):  # robust to the odd mislabelled mocap frame
        q = np.percentile(a, [0.5, 99.5], axis=0).T
        return [(max(lo, a0 - margin), min(hi, a1 + margin)) for a0, a1 in q]

    pr, hr = ranges(pelvis_ang), ranges(hip_ang)
    kr = ranges(knee_ang[:, None], 0.0, 180.0)[0]
    names = ("yaw", "roll", "pitch")

    def axes(rs, names):
        return "\n".join(f'      <axis rot="{r}" name="{n}" min="{lo:.2f}" max="{hi:.2f}"/>'
                         for r, n, (lo, hi) in zip("yxz", names, rs, strict=True))

    markers = "\n".join(f'        <marker name="{m}" offset="{fmt3(offsets[m])}"/>'
                        for m in PELVIS)
    xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<body name="mouse {side} hind limb" units="mm" format="1">
  <description>Built by bench/bench_mouse_free.py from {len(hip)} frames of the OIST mouse
    mocap (MIT) that are not rendered: median lengths and pelvis marker offsets.</description>
  <chain name="{side}_leg">
    {root_xml}
    <joint name="pelvis" orientation="{fmt3(euler_deg(p0))}">
{axes(pr, names)}
      <segment name="pelvis" length="0">
{markers}
        <joint name="hip" orientation="{fmt3(euler_deg(h0))}">
  {axes(hr, ("flex", "abd", "rot")).replace(chr(10), chr(10) + "  ")}
          <segment name="femur" length="{femur:.6g}">
            <marker name="{side}_knee"/>
            <joint name="knee">
              <axis rot="y" name="ry" locked="0"/>
              <axis rot="x" name="rx" locked="0"/>
              <axis rot="z" name="angle" min="{kr[0]:.2f}" max="{kr[1]:.2f}"/>
              <segment name="tibia" length="{tibia:.6g}">
                <marker name="{side}_ankle"/>
              </segment>
            </joint>
          </segment>
        </joint>
      </segment>
    </joint>
  </chain>
</body>
"""
    info = {"femur": femur, "tibia": tibia, "n_cal": len(hip), "pelvis_ranges": pr,
            "hip_ranges": hr, "knee_range": kr,
            "spread": float(np.median([np.linalg.norm(np.einsum("nji,nj->ni", P, cal[m] - hip)
                                                      - offsets[m], axis=1) for m in PELVIS]))}
    return xml, info


def look_at(name, centre, azimuth_deg, elevation_deg, distance, f=1500.0, size=(1280, 1024)):
    """A pinhole camera ``distance`` from ``centre``, at an azimuth (from +x anterior toward
    -z, the left) and elevation, looking at the centre, image up = world up."""
    from kinematics.cameras import PinholeCamera

    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    d = np.array([np.cos(el) * np.cos(az), np.sin(el), -np.cos(el) * np.sin(az)])
    c = centre + distance * d
    zc = unit(centre - c)
    xc = unit(np.cross([0.0, -1.0, 0.0], zc))
    yc = np.cross(zc, xc)
    R = np.stack([xc, yc, zc])
    K = [[f, 0, (size[0] - 1) / 2], [0, f, (size[1] - 1) / 2], [0, 0, 1]]
    return PinholeCamera(name, K, R=R, t=-R @ c, size=size)


def place_cameras(points, side: str):
    """Three cameras on the leg's side of the treadmill: beside, behind-above, in front-above."""
    centre = np.nanmedian(points.reshape(-1, 3), axis=0)
    s = 1.0 if side == "left" else -1.0
    specs = [("side", 90 * s, 10, 400), ("rear", 150 * s, 35, 450), ("front", 35 * s, 40, 340)]
    cams = {}
    for name, a, e, d in specs:  # moved back (10 % at a time) until every marker stays in
        for step in range(8):
            cam = look_at(name, centre, a, e, d * 1.1 ** step)
            uv = cam.project(points)
            w, h = cam.image_size
            ok = np.isnan(uv).any(-1) | ((uv[..., 0] > 10) & (uv[..., 0] < w - 11)
                                          & (uv[..., 1] > 10) & (uv[..., 1] < h - 11))
            if ok.all():
                cams[name] = cam
                break
        else:
            raise SystemExit(f"a marker leaves camera {name}'s image: move the cameras")
    return cams


# -- fits ----------------------------------------------------------------------------------------
def fit_true_root(body, cams, det, params, true_root, frames):
    from kinematics.fit import Fitter

    fitter = Fitter(body, cams, params)
    out = {}
    t0 = time.perf_counter()
    for r in frames:
        pts = [det.points_of(r, v) for v in range(det.n_views)]
        out[r] = fitter.fit_frame(pts, frame=int(r), root_positions=true_root[r][None])
    return out, time.perf_counter() - t0


def fit_free_root(body, cams, det, params, frames):
    from kinematics.fit import Fitter

    fitter = Fitter(body, cams, params)
    t0 = time.perf_counter()
    res = list(fitter.iter_fit(det, frames=frames))
    return {r.frame: r for r in res}, time.perf_counter() - t0


def fit_observations(body, cams, obs, params):
    from kinematics.fit import Fitter

    fitter = Fitter(body, cams, params)
    t0 = time.perf_counter()
    res = list(fitter.iter_fit(obs))
    return {r.frame: r for r in res}, time.perf_counter() - t0


def labelled_inputs(body, cams, truth, args):
    """Labelled 2D keypoints (true projections + ``--kp-noise`` px, ``--kp-missing`` of them
    NaN) and labelled 3D points (truth + ``--noise-3d`` mm), as Observations."""
    from kinematics.observe.observations import Observations

    rng = np.random.default_rng(args.seed + 1)
    names = body.marker_names
    kp = np.stack([c.project(truth) for c in cams.values()], axis=1)  # (n, views, m, 2)
    kp = kp + rng.normal(0.0, args.kp_noise, kp.shape)
    kp[rng.uniform(size=kp.shape[:3]) < args.kp_missing] = np.nan
    keypoints = Observations.keypoints(kp, list(cams), names, names)
    p3 = truth + rng.normal(0.0, args.noise_3d, truth.shape)
    points3d = Observations.points_3d(p3, names, names)
    return keypoints, points3d


def floor_fit(body, truth, frames):
    """Least squares of the chain to the true 3D markers: root position + all free angles."""
    from scipy.optimize import least_squares

    from kinematics.model.fk import forward_kinematics
    from kinematics.model.packing import pack_body

    arrays = pack_body(body)
    free = ~body.locked_mask()
    mean = body.mean_posture_deg()
    lo, hi = body.ranges_deg()[free].T
    out = {}
    prev = None
    t0 = time.perf_counter()
    for r in frames:
        target = truth[r]

        def resid(x, target=target):
            a = mean.copy()
            a[free] = x[3:]
            m = forward_kinematics(arrays, a, x[None, :3]).markers
            return (m - target).ravel()

        best = None
        for start in [mean[free]] + ([prev] if prev is not None else []):
            x0 = np.r_[target[0], np.clip(start, lo + 1e-6, hi - 1e-6)]
            sol = least_squares(resid, x0, bounds=(np.r_[[-np.inf] * 3, lo],
                                                   np.r_[[np.inf] * 3, hi]), x_scale="jac")
            if best is None or sol.cost < best.cost:
                best = sol
        prev = best.x[3:]
        a = mean.copy()
        a[free] = best.x[3:]
        out[r] = (a, best.x[:3])
    return out, time.perf_counter() - t0


def fitted_markers(body, fits):
    """(frame -> (n_markers, 3)) of fitted postures and roots."""
    from kinematics.model.fk import forward_kinematics

    frames = sorted(fits)
    if not frames:
        return {}
    ang = np.array([fits[r][0] for r in frames])
    roots = np.array([fits[r][1] for r in frames])[:, None]
    m = forward_kinematics(body, ang, roots).markers
    return dict(zip(frames, m, strict=True))


def metrics(names, side, truth, fitted, frames):
    """Per-frame 3D errors of hip, knee, ankle and knee angles (NaN where not fitted)."""
    idx = [names.index(f"{side}_{j}") for j in ("hip", "knee", "ankle")]
    err = np.full((len(frames), 3), np.nan)
    k_true = knee_angle_deg(*(truth[frames][:, i] for i in idx))
    k_fit = np.full(len(frames), np.nan)
    for n, r in enumerate(frames):
        if r in fitted and np.isfinite(fitted[r]).all():
            err[n] = np.linalg.norm(fitted[r][idx] - truth[r][idx], axis=1)
            k_fit[n] = knee_angle_deg(*(fitted[r][i] for i in idx))
    return err, k_true, k_fit


def summary(err, k_true, k_fit):
    ok = np.isfinite(err).all(axis=1)
    e = err[ok]
    stats = {}
    for j, name in enumerate(("hip", "knee", "ankle")):
        stats[name] = (np.median(e[:, j]), np.percentile(e[:, j], 95), e[:, j].max()) if len(
            e) else (np.nan,) * 3
    stats["knee_rmse"] = float(np.sqrt(np.mean((k_fit[ok] - k_true[ok]) ** 2))) if ok.any() \
        else np.nan
    stats["n"] = int(ok.sum())
    return stats


# -- main ----------------------------------------------------------------------------------------
def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=300, help="rendered frames (300 = 1 s)")
    ap.add_argument("--start", type=int, default=None,
                    help="first rendered frame (default: the best-covered stretch)")
    ap.add_argument("--side", choices=("left", "right"), default="left")
    ap.add_argument("--root", choices=("true", "free", "both"), default="both")
    ap.add_argument("--profile", choices=("paper", "defaults"), default="paper",
                    help="paper: AnnealParams.paper(refine=True) with --n-end, --threshold and "
                         "--cap; defaults: AnnealParams() as a user runs it (those three unused)")
    ap.add_argument("--n-end", type=int, default=10000, help="annealing iterations per run")
    ap.add_argument("--threshold", type=float, default=25.0,
                    help="re-analysis threshold on E (px, summed over 18 marker images)")
    ap.add_argument("--cap", type=float, default=20.0, help="largest cost of one marker (px)")
    ap.add_argument("--margin", type=float, default=15.0,
                    help="degrees added to each side of the observed angle ranges")
    ap.add_argument("--diameter", type=float, default=6.0, help="marker diameter (px)")
    ap.add_argument("--gap", type=int, default=300,
                    help="frames left out on each side of the stretch when building the chain")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-labelled", dest="labelled", action="store_false",
                    help="skip the fits to labelled 2D keypoints and 3D points")
    ap.add_argument("--kp-noise", type=float, default=1.0, help="keypoint noise (px)")
    ap.add_argument("--kp-missing", type=float, default=0.05, help="share of keypoints NaN")
    ap.add_argument("--kp-threshold", type=float, default=60.0,
                    help="re-analysis threshold of the keypoint fit (px)")
    ap.add_argument("--noise-3d", type=float, default=0.2, help="3D point noise (mm)")
    ap.add_argument("--tau0-3d", type=float, default=5.0,
                    help="start temperature of the 3D-point fit (mm of E)")
    ap.add_argument("--threshold-3d", type=float, default=4.0,
                    help="re-analysis threshold of the 3D-point fit (mm)")
    ap.add_argument("--cap-3d", type=float, default=5.0,
                    help="largest cost of one 3D point, and the refinement gate (mm)")
    ap.add_argument("--data", type=Path, default=DATA,
                    help="folder of the mocap .mat file (default: ../shared/data/"
                         "mouse_marker_mocap_oist beside the repository)")
    ap.add_argument("--out", type=Path, default=None,
                    help="folder for the derived files and the figure (default: temporary)")
    args = ap.parse_args()
    if not glob.glob(str(args.data / "*.mat")):
        print(f"skipped: no mouse mocap data in {args.data} (../shared/data is absent)")
        return 0
    return in_out_folder(args.out, "bench_mouse_", lambda folder, keep: run(args, folder, keep))


def run(args, out: Path, keep: bool) -> int:
    import kinematics.model as km
    from kinematics.cameras.files import save_cameras
    from kinematics.fit import AnnealParams
    from kinematics.fit.error_function import ErrorOptions
    from kinematics.model.chain_xml import loads_body
    from videotrack.detect.run import detect_project
    from videotrack.project.folders import command_config
    from videotrack.results.tables import read_table, write_table
    from videotrack.synth.project import SynthOptions, read_points, write_points_project

    side = args.side
    labels, xyz = load_mocap(args.data)
    names = [*PELVIS, f"{side}_knee", f"{side}_ankle"]
    pts = xyz[:, [labels.index(n) for n in names]]
    valid = np.isfinite(pts).all(axis=(1, 2))
    n = args.frames
    start = choose_stretch(valid, n) if args.start is None else args.start
    stop = start + n
    if not (start >= 0 and stop <= len(pts)):
        raise SystemExit(f"--start/--frames outside the {len(pts)} frames")
    cal_mask = valid.copy()
    cal_mask[max(0, start - args.gap): stop + args.gap] = False
    cal = {m: pts[cal_mask, k] for k, m in enumerate(names)}
    hip_name = f"{side}_hip"
    free_ok = "free" in getattr(km, "ROOT_MODES", ())
    fixed_xml = f'<root mode="fixed" position="{fmt3(np.median(cal[hip_name], axis=0))}"/>'
    chain_text, info = build_chain(cal, side, args.margin, fixed_xml)
    body = loads_body(chain_text, source="mouse chain")
    body_names = body.marker_names
    order = [names.index(m) for m in body_names]
    truth = pts[start:stop][:, order]  # (n, 6, 3) in the body's marker order
    hip_i = body_names.index(hip_name)

    print(f"Freely moving mouse {side} hind limb: frames {start}:{stop} of {len(pts)} "
          f"({n / FPS:.2f} s at 300 Hz; {valid[start:stop].sum()} with all 6 markers); chain from "
          f"{info['n_cal']} other frames (femur {info['femur']:.2f} mm, tibia "
          f"{info['tibia']:.2f} mm; pelvis markers {info['spread']:.2f} mm median off their "
          f"rigid offsets); {machine()}, {numba.get_num_threads()} threads")

    # cameras, points file, rendering, detection
    cams = place_cameras(truth, side)
    save_cameras(out / "cameras.toml", cams, units="mm")
    cols = ["frame"] + [f"{m}.{a}" for m in body_names for a in "xyz"]
    write_table(out / "points.csv", cols, np.column_stack([np.arange(start, stop),
                                                           truth.reshape(n, -1)]))
    (out / "chain_true_root.xml").write_text(chain_text)
    t0 = time.perf_counter()
    pnames, points = read_points(out / "points.csv")
    project = write_points_project(out / "video", pnames, points, cams,
                                   SynthOptions(marker_diameter=args.diameter, seed=args.seed,
                                                layout="separate"), fps=FPS, units="mm")
    t_render = time.perf_counter() - t0
    t0 = time.perf_counter()
    det, _, _ = detect_project(command_config(project.config, None), force=True)
    t_detect = time.perf_counter() - t0
    tcols, ttab = read_table(project.truth)
    vis = np.array([[ttab[:, tcols.index(f"{v}.{m}.visible")] == 1 for m in body_names]
                    for v in cams]).transpose(2, 0, 1)  # (n, views, markers)
    seen = (vis.sum(axis=1) >= 2).all(axis=1) & np.isfinite(truth).all(axis=(1, 2))
    frames = np.flatnonzero(seen)
    counts = det.counts()
    print(f"Rendered {n} frames x {len(cams)} views (1280x1024, {args.diameter:g}-px markers) "
          f"in {t_render:.1f} s, detected in {t_detect:.1f} s: {counts.sum()} detections for "
          f"{int(vis.sum())} drawn marker images ({int((counts < vis.sum(axis=2)).sum())} view "
          f"images with fused markers); {len(frames)} frames with every marker in >= 2 views.")

    if args.profile == "defaults":
        params = AnnealParams(seed=args.seed)
        print("Fit: AnnealParams() (the defaults).\n")
    else:
        params = AnnealParams.paper(refine=True, reanalysis_threshold=args.threshold,
                                    seed=args.seed, error=ErrorOptions(cap_px=args.cap)
                                    ).with_schedule(args.n_end)
        print(f"Fit: AnnealParams.paper(refine=True, n_end={params.n_end}, n_l={params.n_l}, "
              f"n_tau={params.n_tau}, reanalysis_threshold={args.threshold:g} px, cap_px="
              f"{args.cap:g}, max_runs={params.max_runs}).\n")

    columns, results, series = [], {}, {}
    floor, t_floor = floor_fit(body, truth, frames)
    fm = fitted_markers(body, floor)
    results["floor (3D least squares)"] = (summary(*metrics(body_names, side, truth, fm,
                                                            frames)), len(frames) / t_floor, "",
                                           "")
    series["floor"] = metrics(body_names, side, truth, fm, frames)
    fit_frames = np.flatnonzero(np.isfinite(truth[:, hip_i]).all(axis=1))
    if args.root in ("true", "both"):
        res, dt = fit_true_root(body, cams, det, params, truth[:, hip_i], fit_frames)
        fm = fitted_markers(body, {r: (x.angles_deg, x.root_positions[0])
                                   for r, x in res.items()})
        m = metrics(body_names, side, truth, fm, frames)
        results["root true"] = (summary(*m), len(fit_frames) / dt, status_line(res, frames),
                                gap_line(body_names, side, truth, fm, frames, res),
                                trust(res, m[0], frames))
        series["root true"] = m
    if args.root in ("free", "both"):
        if not free_ok:
            print("root free: not available yet (kinematics.model.ROOT_MODES has no 'free')\n")
        else:
            free_xml = fixed_xml.replace('mode="fixed"', f'mode="free" marker="{hip_name}"')
            free_text = chain_text.replace(fixed_xml, free_xml)
            (out / "chain_free_root.xml").write_text(free_text)
            free_body = loads_body(free_text, source="mouse chain (free root)")
            try:
                res, dt = fit_free_root(free_body, cams, det, params, np.arange(n))
            except Exception as err:  # the free root is being written: report, don't crash
                print(f"root free: the fitter failed: {type(err).__name__}: {err}\n")
            else:
                fm = fitted_markers(free_body, {r: (x.angles_deg, x.root_positions[0])
                                                for r, x in res.items()})
                m = metrics(body_names, side, truth, fm, frames)
                write_frames(out / "frames_root_free.csv", body_names, side, truth, fm, res,
                             vis)
                results["root free"] = (summary(*m), n / dt, status_line(res, frames),
                                        gap_line(body_names, side, truth, fm, frames, res),
                                        trust(res, m[0], frames))
                series["root free"] = m

    if args.root in ("free", "both") and free_ok and args.labelled:
        from dataclasses import replace

        keypoints, points3d = labelled_inputs(free_body, cams, truth, args)
        kp_params = replace(params, reanalysis_threshold=args.kp_threshold)
        p3_params = replace(params, tau0=args.tau0_3d, reanalysis_threshold=args.threshold_3d,
                            refine_gate_px=args.cap_3d,
                            error=ErrorOptions(cap_px=args.cap_3d))
        for label, obs, prm in (("keypoints (free)", keypoints, kp_params),
                                ("3D points (free)", points3d, p3_params)):
            res, dt = fit_observations(free_body, cams if obs.n_views else {}, obs, prm)
            fm = fitted_markers(free_body, {r: (x.angles_deg, x.root_positions[0])
                                            for r, x in res.items()})
            m = metrics(body_names, side, truth, fm, frames)
            results[label] = (summary(*m), n / dt, status_line(res, frames),
                              gap_line(body_names, side, truth, fm, frames, res),
                              trust(res, m[0], frames))
            series[label] = m
        print(f"Labelled inputs: 2D keypoints = true projections + {args.kp_noise:g} px noise, "
              f"{100 * args.kp_missing:g} % missing (re-analysis threshold "
              f"{args.kp_threshold:g} px); 3D points = truth + {args.noise_3d:g} mm noise "
              f"(tau0 {args.tau0_3d:g} mm, threshold {args.threshold_3d:g} mm, cap "
              f"{args.cap_3d:g} mm). Goal: median within 1.2x of the floor, >= 200 frames/s.\n")

    columns = list(results)
    rows = []
    for j in ("hip", "knee", "ankle"):
        for q, label in enumerate(("median", "p95", "max")):
            rows.append((f"{j} 3D error, {label} (mm)",
                         *(f"{results[c][0][j][q]:.2f}" for c in columns),
                         f"<= {TARGETS[label]:g}"))
    rows.append(("knee-angle RMSE (deg)", *(f"{results[c][0]['knee_rmse']:.2f}"
                                            for c in columns), f"<= {TARGETS['knee']:g}"))
    rows.append(("frames scored", *(str(results[c][0]["n"]) for c in columns), ""))
    rows.append(("fitting speed (frames/s)", *(f"{results[c][1]:.0f}" for c in columns), ""))
    rows.append(("frames ok / re-analysed / ambiguous / failed (scored)",
                 *(results[c][2] or "-" for c in columns), ""))
    rows.append(("other frames (a marker absent): beyond 3 mm",
                 *(results[c][3] or "-" for c in columns), ""))
    rows += trust_rows(results, columns)
    print_table(rows, "target", results=columns)
    png = plot(series, frames, start, out / "mouse_free.png")
    print(f"\nFigure: {png}" + ("" if keep else " (temporary; give --out to keep it)"))
    return 0


def write_frames(path, names, side, truth, fitted, res, vis) -> None:
    """Per frame: status, E, the 3D error of hip, knee and ankle (NaN where unknown), and
    per marker the views it is drawn in (for a look at where a fit went wrong)."""
    from videotrack.results.tables import write_table

    idx = [names.index(f"{side}_{j}") for j in ("hip", "knee", "ankle")]
    statuses = ("ok", "reanalysed", "ambiguous", "failed", "no-detections")
    rows = []
    for r in range(len(truth)):
        e = (np.linalg.norm(fitted[r][idx] - truth[r][idx], axis=1) if r in fitted
             else np.full(3, np.nan))
        st = statuses.index(res[r].status) if r in res else -1
        rows.append([r, st, res[r].error if r in res else np.nan, *e, *vis[r].sum(axis=0)])
    write_table(path, ["frame", "status", "E", "hip", "knee", "ankle",
                       *(f"{m}.views" for m in names)], np.array(rows, float))


def gap_line(names, side, truth, fitted, frames, res=None, limit=3.0) -> str:
    """Frames outside the scored ones (a marker absent in the mocap or seen by fewer than two
    cameras) with the true knee known: how many put a known leg joint (hip, knee, ankle)
    more than ``limit`` mm off, and of those how many are not flagged (``ok`` or
    ``reanalysed``)."""
    idx = [names.index(f"{side}_{j}") for j in ("hip", "knee", "ankle")]
    scored = set(frames.tolist())
    other = [r for r in np.flatnonzero(np.isfinite(truth[:, idx[1]]).all(axis=1))
             if r not in scored and r in fitted and np.isfinite(fitted[r]).all()]
    off = [r for r in other
           if np.nanmax(np.linalg.norm(fitted[r][idx] - truth[r][idx], axis=1)) > limit]
    said = f"{len(off)} of {len(other)}"
    if res is not None:
        said += f" ({sum(res[r].status in ('ok', 'reanalysed') for r in off)} not flagged)"
    return said


def status_line(res, frames) -> str:
    s = [res[r].status for r in frames if r in res]
    return (f"{s.count('ok')} / {s.count('reanalysed')} / {s.count('ambiguous')} / "
            f"{s.count('failed')}")


def trust(res, err, frames, limit=3.0) -> dict:
    """The scored frames against ``limit`` mm (hip, knee and ankle all within it): the share
    within, how many beyond it are ``ok`` or ``reanalysed`` (unflagged), and of the flagged
    (``ambiguous`` / ``failed``) how many are beyond (precision)."""
    fitted = np.array([r in res for r in frames])
    off = ~(np.nan_to_num(err, nan=np.inf) <= limit).all(axis=1)
    flagged = np.array([r in res and res[r].status in ("ambiguous", "failed")
                        for r in frames])
    return {"within": 100.0 * float(np.mean(~off)), "off": int(off.sum()),
            "unflagged": int((off & fitted & ~flagged).sum()), "flagged": int(flagged.sum()),
            "flagged_off": int((off & flagged).sum())}


def trust_rows(results, columns):
    """Rows of :func:`trust`'s figures for the columns that have them."""
    t = [results[c][4] if len(results[c]) > 4 else None for c in columns]
    if not any(t):
        return []
    def cell(f):
        return lambda x: "-" if x is None else f(x)

    return [("frames with hip, knee, ankle within 3 mm", *map(cell(
                lambda x: f"{x['within']:.1f} %"), t), ">= 98 %"),
            ("frames beyond 3 mm, not flagged", *map(cell(
                lambda x: f"{x['unflagged']} of {x['off']}"), t), "0"),
            ("flagged frames beyond 3 mm (precision)", *map(cell(
                lambda x: f"{x['flagged_off']} of {x['flagged']}"), t), "")]


def plot(series, frames, start, path):
    from videotrack.results.plots import _pyplot, _save_png

    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(10, 7.5), sharex=True)
    t = (start + frames) / FPS
    first = next(iter(series.values()))
    axes[0].plot(t, first[1], "k-", lw=1.5, label="true")
    colours = ("0.5", "tab:blue", "tab:red", "tab:green", "tab:purple")
    for (name, (err, _, k_fit)), colour in zip(series.items(), colours, strict=False):
        axes[0].plot(t, k_fit, ".", ms=2.5, color=colour, label=name)
        axes[1].plot(t, err[:, 1], ".", ms=2.5, color=colour, label=name)
        axes[2].plot(t, err[:, 2], ".", ms=2.5, color=colour, label=name)
    axes[0].set_ylabel("knee angle (°)")
    axes[1].set_ylabel("knee 3D error (mm)")
    axes[2].set_ylabel("ankle 3D error (mm)")
    axes[2].set_xlabel("time in the recording (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    for ax in axes[1:]:
        ax.set_yscale("log")
    fig.suptitle("Mouse hind limb from rendered real mocap: fitted vs true")
    return _save_png(fig, path, dpi=90)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    raise SystemExit(main())
