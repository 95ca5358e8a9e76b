"""A fruit fly, six legs: the real flygym clip rendered as marker videos and fitted.

Run from the repository root::

    python bench/bench_fly.py [--cameras 6] [--frames 0:660:10] [--n-end 10000]
                              [--threshold 4] [--cap 0] [--error paper]
                              [--param NAME=VALUE ...] [--leg LF] [--fits floor,body,...]
                              [--out DIR]
    python bench/bench_fly.py --param partitions=none --param threshold_mode=auto  # e.g.
    python bench/bench_fly.py --measure-ranges      # re-measure the chain's angle ranges
    python bench/bench_fly.py --frames 0:660:10 --param match=3d --param start_samples=64 \
        --param partition_rounds=3 --param max_unexplained=0   # the best measured (3D)

Data: ``../shared/data/flygym_fly_kinematics/spotlight_behavior_clip.npz`` (flygym,
Apache-2.0; ../shared/data/README.md item 1: a tethered fly, 660 frames at 330 Hz,
``rawpred_egoxyz`` 30 keypoints in mm, 5 per leg: thorax-coxa, coxa-trochanter,
femur-tibia, tibia-tarsus, tarsus tip), read at run time; the benchmark exits 0 with a
message when it is absent. Nothing of it is copied into the repository: every derived file
(points, cameras, chains, videos, figure) goes to ``--out`` (default a temporary folder).

Protocol:

1. The clip's keypoints in the chains' world axes (x anterior, y up, z right: the clip's ego
   frame is x forward, y left, z up), in the marker order of ``chains/fly_six_legs.xml``.
2. The chain: the shipped ``chains/fly_six_legs.xml`` adapted to this fly: each leg's fixed
   root at the median thorax-coxa keypoint, its coxa, femur, tibia and tarsus lengths the
   median keypoint distances; its ranges unchanged (``fly_adapted.xml`` in ``--out``).
3. Range check (issue 10 item 5): each leg of that chain fitted by least squares to the true
   3D keypoints of every fitted frame within the shipped ranges; frames whose fit ends within
   0.5 deg of an axis limit are counted. The fit has a weak pull (``REG`` mm per degree)
   toward the range centres: the ThC joint's three axes and the CTr roll span one rotation
   of the coxa about its own axis twice, and the pull picks one of those equal postures.
   ``--measure-ranges`` fits all 660 frames with the ranges opened to +-250 deg around their
   centres and prints per leg pair (left legs mirrored onto the right) the observed minimum
   and maximum of every axis: the numbers in tools/make_fly_chain.py (frames whose keypoints
   are mispredicted, a leg segment > 25 % off its median length, left out).
4. ``--cameras`` (6 or 3) pinhole cameras (640x640 px, 60 mm from the fly, ``--px-per-mm``
   100 at the fly) on a ring around it at elevations alternating 15 and 40 deg; the true 3D
   keypoints of ``--frames`` are written as a points CSV, rendered by ``videotrack synth --points``
   (``videotrack.synth.project.write_points_project``) as ``--diameter`` px markers (4), one FFV1
   video per camera, and detected with the written project (``videotrack detect``). A
   second video draws only ``--leg``'s 5 markers.
5. Fits, all frame-independent (``start="mean"``), unlabelled markers, refinement on (and,
   where markers are matched in 3D, the final polish: ``--param final_polish_px=None`` for
   the fit without it), the
   Table 1 schedule shortened to ``--n-end`` (N_l, N_tau scaled; with ``--profile best``
   the defaults' schedule unless given), re-analysis threshold
   ``--threshold`` px per marker image (times markers x views of that fit; with
   ``--param match=3d`` times markers: E then sums one distance per marker), marker cost
   capped at ``--cap`` px (0: no cap; a 10-px cap ruins even the lone leg, whose correct
   posture costs ~3 px per marker image at 100 px/mm), error ``--error``;
   ``--param NAME=VALUE`` sets any other
   AnnealParams field (``error.NAME=VALUE`` an ErrorOptions field):

   * ``floor``: the chain fitted to the true 3D points (step 3), the best any fit can do;
   * ``whole body``: the six leg chains in one body, all 30 markers drawn;
   * ``LEG among six``: only ``--leg``'s chain fitted, all 30 markers drawn (a leg must not
     take its neighbours' markers);
   * ``LEG alone``: the same chain, only its own 5 markers drawn.

Reported: median 3D joint error (the 5 keypoints of each fitted leg, all frames), share of
frames with every joint within 0.2 mm, femur-tibia angle RMSE (the angle between CTr->FTi and
FTi->TiTa, true vs fitted, over the fitted legs), fitting speed on ``--threads`` threads (2),
which off frames have a fitted joint on another leg's keypoint or on another keypoint of its
own leg (folded), and the status: recall (share of frames off by > 0.2 mm on some joint that
end ``failed``, or ``failed`` or ``ambiguous``: the frames a user is told to look at) and
precision (share of those frames that are off); of the whole body's off frames, how many the
floor leaves off too (the rigid chain's misfit, which no fit can mend), and the recall on
the others (the fit's own errors). A PNG of every fit's
per-frame worst joint error and of ``--leg``'s femur-tibia angle goes to ``--out``. Targets
(issue 10): median <= 0.03 mm (floor ~0.024), >= 98 % of frames within 0.2 mm, femur-tibia RMSE
<= 5 deg, >= 30 frames/s on 2 cores; one leg among six <= 2 % of frames off; status recall >=
95 %, precision >= 60 %.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
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

DATA = ROOT.parent / "shared" / "data" / "flygym_fly_kinematics" / "spotlight_behavior_clip.npz"
CHAIN = ROOT / "chains" / "fly_six_legs.xml"
LEGS = ("LF", "LM", "LH", "RF", "RM", "RH")  # the clip's order (lf lm lh rf rm rh)
KEYPOINTS = ("ThC", "CTr", "FTi", "TiTa", "Tip")  # 5 per leg, proximal to distal
FPS = 330.0
OFF_MM = 0.2  # a joint farther than this from the truth makes a frame "off"
LENGTH_TOL = 0.25  # a leg segment this far off its median length: mispredicted keypoints
REG = 2e-4  # mm of residual per degree from the range centre (resolves the roll redundancy)
TARGETS = {"median": "<= 0.03 (floor ~0.024)", "within": ">= 98", "off": "<= 2 (one leg)",
           "fti": "<= 5", "fps": ">= 30 (body)", "recall": ">= 95", "precision": ">= 60",
           "recall_look": ">= 95", "precision_look": ">= 60"}


# -- data --------------------------------------------------------------------------------------
def load_clip(path: Path) -> np.ndarray:
    """Keypoints (660, 30, 3) in mm in the chains' world axes: x anterior, y up, z right."""
    with np.load(path, allow_pickle=True) as c:
        ego = np.asarray(c["rawpred_egoxyz"], dtype=float)  # x forward, y left, z up
        legs = [str(s).upper() for s in c["legs"]]
    if tuple(legs) != LEGS or ego.shape[1:] != (30, 3):
        raise SystemExit(f"unexpected clip layout: legs {legs}, keypoints {ego.shape}")
    return np.stack([ego[..., 0], ego[..., 2], -ego[..., 1]], axis=-1)


def marker_names() -> list[str]:
    return [f"{leg}_{k}_mk" for leg in LEGS for k in KEYPOINTS]


#: ``--colours``: which legs' markers share a colour
COLOUR_SCHEMES = {
    "none": (),
    "tripods": (("red", ("LF", "RM", "LH")), ("green", ("RF", "LM", "RH"))),
    "sides": (("red", ("LF", "LM", "LH")), ("green", ("RF", "RM", "RH"))),
    "segments": (("red", ("LF", "RF")), ("green", ("LM", "RM")), ("blue", ("LH", "RH"))),
    "legs": tuple(zip(("red", "yellow", "green", "cyan", "blue", "magenta"),
                      ((leg,) for leg in LEGS), strict=True)),
}


def colours_of(scheme: str, names) -> tuple:
    """SynthOptions.colours for the markers ``names`` (a colour none of them has is left
    out)."""
    out = []
    for colour, legs in COLOUR_SCHEMES[scheme]:
        mine = tuple(m for m in names if m[:2] in legs)
        if mine:
            out.append((colour, mine))
    return tuple(out)


def fit_views(cams, colours, body_markers):
    """The fit's views of a video drawn with ``colours``: (view name -> camera, view name ->
    the body's markers it shows or None), as ``videotrack synth`` names them."""
    if not colours:
        return cams, None
    views, shows = {}, {}
    for cam, camera in cams.items():
        for colour, markers in colours:
            views[f"{cam}_{colour}"] = camera
            shows[f"{cam}_{colour}"] = [m for m in body_markers if m in markers]
    return views, shows


def parse_frames(spec: str, n: int) -> np.ndarray:
    """``A:B:S`` (a slice of the clip) or a comma list of frame numbers."""
    try:
        if ":" in spec:
            parts = [int(p) if p.strip() else None for p in spec.split(":")]
            frames = np.arange(n)[slice(*parts)]
        else:
            frames = np.array(sorted({int(p) for p in spec.split(",")}))
    except ValueError:
        raise SystemExit(f"--frames: expected A:B:S or a comma list, got {spec!r}") from None
    if frames.size == 0 or frames.min() < 0 or frames.max() >= n:
        raise SystemExit(f"--frames {spec!r} selects no frame of 0..{n - 1}")
    return frames


# -- the chain -----------------------------------------------------------------------------------
def adapt_body(body, pts: np.ndarray):
    """The shipped fly adapted to the clip: roots at the median ThC keypoints, segment lengths
    the median distances between consecutive keypoints (the ThC marker stays at the root)."""
    from kinematics.model import Body

    chains = []
    for k, chain in enumerate(body.chains):
        leg = pts[:, 5 * k: 5 * k + 5]
        lengths = np.median(np.linalg.norm(np.diff(leg, axis=1), axis=-1), axis=0)

        def seg(s, depth, lengths=lengths):
            n = float(lengths[depth])
            mk = tuple(dataclasses.replace(m, offset=(-n, 0.0, 0.0)) if m.offset[0] != 0 else m
                       for m in s.markers)
            return dataclasses.replace(s, length=n, markers=mk,
                                       joints=tuple(joint(j, depth + 1) for j in s.joints))

        def joint(j, depth):
            return dataclasses.replace(j, segments=tuple(seg(s, depth) for s in j.segments))

        root = tuple(float(v) for v in np.median(leg[:, 0], axis=0))
        chains.append(dataclasses.replace(chain, root_joint=joint(chain.root_joint, 0),
                                          root=dataclasses.replace(chain.root, position=root)))
    out = Body(f"{body.name} (adapted to the flygym clip)", tuple(chains), units=body.units,
               description=body.description + " Roots and lengths adapted to the flygym "
               "spotlight clip by bench/bench_fly.py.")
    out.validate()
    return out


def sub_body(body, legs):
    from kinematics.model import Body

    keep = tuple(c for c in body.chains if c.name[:2].upper() in legs)
    return Body(f"{body.name}: {', '.join(legs)}", keep, units=body.units,
                description=body.description)


# -- least squares to the true 3D points ------------------------------------------------------
class LegFit:
    """One leg chain fitted to its 5 true keypoints by scipy least squares (fixed root)."""

    def __init__(self, chain, units="mm", widen=None):
        from kinematics.model import Body
        from kinematics.model.packing import pack_body

        self.body = Body("leg", (chain,), units=units)
        self.arrays = pack_body(self.body)
        self.free = ~self.body.locked_mask()
        self.mean = self.body.mean_posture_deg()
        self.ref = self.mean[self.free]
        ranges = self.body.ranges_deg()[self.free]
        self.lo, self.hi = ranges[:, 0].copy(), ranges[:, 1].copy()
        if widen is not None:  # open every range to +-widen around its centre
            self.lo, self.hi = self.ref - widen, self.ref + widen
        self.root = self.body.root_positions()

    def posture(self, q):
        a = self.mean.copy()
        a[self.free] = q
        return a

    def markers(self, q):
        from kinematics.model.fk import forward_kinematics

        return forward_kinematics(self.arrays, self.posture(q), self.root).markers

    def fit(self, target, starts):
        from scipy.optimize import least_squares

        def resid(q):
            return np.r_[(self.markers(q) - target).ravel(), REG * (q - self.ref)]

        best = None
        for s in starts:
            x0 = np.clip(s, self.lo + 1e-6, self.hi - 1e-6)
            sol = least_squares(resid, x0, bounds=(self.lo, self.hi), diff_step=1e-6)
            if best is None or sol.cost < best.cost:
                best = sol
        return best.x


def floor_fit(body, truth, frames, n_random=2, widen=None, seed=0):
    """Every leg fitted to the true points of ``frames``: postures (n, n_axes) in the body's
    order, and a (n, n_legs) mask of legs whose fit ends within 0.5 deg of an axis limit."""
    rng = np.random.default_rng(seed)
    angles, at_limit = [], []
    for k, chain in enumerate(body.chains):
        lf = LegFit(chain, body.units, widen)
        span = np.c_[lf.lo, lf.hi] if widen is None else body_ranges_free(chain, body.units)
        prev, leg_angles, leg_lim = None, [], []
        for r in frames:
            starts = [lf.ref] + ([prev] if prev is not None else [])
            starts += [rng.uniform(span[:, 0], span[:, 1]) for _ in range(n_random)]
            q = lf.fit(truth[r, 5 * k: 5 * k + 5], starts)
            prev = q
            leg_angles.append(lf.posture(q))
            leg_lim.append(bool(((q - lf.lo < 0.5) | (lf.hi - q < 0.5)).any()))
        angles.append(np.array(leg_angles))
        at_limit.append(leg_lim)
    return np.concatenate(angles, axis=1), np.array(at_limit).T


def body_ranges_free(chain, units):
    from kinematics.model import Body

    b = Body("leg", (chain,), units=units)
    return b.ranges_deg()[~b.locked_mask()]


def plausible(truth) -> np.ndarray:
    """(n, 6): every segment of the leg within ``LENGTH_TOL`` of its median length (a frame
    outside that has mispredicted keypoints: the merged tarsus at 0.6x its length...)."""
    leg = truth.reshape(len(truth), len(LEGS), 5, 3)
    seg = np.linalg.norm(np.diff(leg, axis=2), axis=-1)
    return (np.abs(seg / np.median(seg, axis=0) - 1) <= LENGTH_TOL).all(axis=-1)


def measure_ranges(body, truth, frames) -> None:
    """Print the observed range of every free axis per leg pair, left legs mirrored onto the
    right (rotations about y and x change sign), for tools/make_fly_chain.py."""
    angles, _ = floor_fit(body, truth, frames, n_random=3, widen=250.0)
    fitted = fitted_markers(body, angles)
    err = np.linalg.norm(fitted - truth[frames], axis=-1)
    ok = plausible(truth[frames])
    labels = body.axis_labels
    free = ~body.locked_mask()
    rot = np.array([r.axis.rot for r in body.axis_refs()])
    ranges = body.ranges_deg()
    per_leg = len(labels) // len(body.chains)
    print(f"Observed angles (deg) over {len(frames)} frames, least squares with the ranges "
          f"opened to +-250 deg; worst joint per frame median {np.median(err.max(1)):.3f} mm, "
          f"p99 {np.percentile(err.max(1), 99):.3f} mm. Frames left out per leg (a segment "
          f"> {100 * LENGTH_TOL:.0f} % off its median length): "
          + ", ".join(f"{lg} {c}" for lg, c in zip(LEGS, (~ok).sum(0), strict=True))
          + ". Right-leg convention (left legs: rotations about y and x negated).\n")
    rows = []
    for pos in "FMH":
        li, ri = LEGS.index(f"L{pos}"), LEGS.index(f"R{pos}")
        for j in range(per_leg):
            if not free[j]:
                continue
            a_l = angles[ok[:, li], li * per_leg + j] * (-1 if rot[j] in "yx" else 1)
            a_r = angles[ok[:, ri], ri * per_leg + j]
            a_all = np.r_[angles[:, li * per_leg + j] * (-1 if rot[j] in "yx" else 1),
                          angles[:, ri * per_leg + j]]
            both = np.r_[a_l, a_r]
            lo, hi = ranges[ri * per_leg + j]
            name = labels[ri * per_leg + j].split("_", 1)[1]
            rows.append((f"{pos} {name}", f"{a_l.min():.1f} .. {a_l.max():.1f}",
                         f"{a_r.min():.1f} .. {a_r.max():.1f}",
                         f"{both.min():.1f} .. {both.max():.1f}",
                         f"{a_all.min():.1f} .. {a_all.max():.1f}", f"{lo:g} .. {hi:g}"))
    print_table(rows, "shipped range (right)",
                results=("left (mirrored)", "right", "both", "both, all frames"))


# -- cameras, rendering, detection -----------------------------------------------------------------
def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def look_at(name, centre, azimuth_deg, elevation_deg, distance, f, size=(640, 640)):
    """A pinhole camera ``distance`` from ``centre`` at an azimuth (from +x anterior toward +z,
    the right) and elevation, looking at the centre, image up = world up."""
    from kinematics.cameras import PinholeCamera

    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    c = centre + distance * np.array([np.cos(el) * np.cos(az), np.sin(el),
                                      np.cos(el) * np.sin(az)])
    zc = unit(centre - c)
    xc = unit(np.cross([0.0, -1.0, 0.0], zc))
    R = np.stack([xc, np.cross(zc, xc), zc])
    K = [[f, 0, (size[0] - 1) / 2], [0, f, (size[1] - 1) / 2], [0, 0, 1]]
    return PinholeCamera(name, K, R=R, t=-R @ c, size=size)


def place_cameras(points, n: int, px_per_mm: float, distance=60.0, size=(640, 640)):
    """``n`` cameras ``distance`` mm from the fly on a ring around it, elevations alternating
    15 and 40 deg, focal length ``px_per_mm`` x distance; every marker must stay inside every
    image with a 20-px border."""
    centre = 0.5 * (np.nanmin(points.reshape(-1, 3), 0) + np.nanmax(points.reshape(-1, 3), 0))
    specs = [(f"cam{k}", 30 + 360 * k / n, 15 if k % 2 == 0 else 40) for k in range(n)]
    cams = {name: look_at(name, centre, az, el, distance, px_per_mm * distance, size)
            for name, az, el in specs}
    for cam in cams.values():
        uv = cam.project(points)
        if not ((uv > 20) & (uv < np.array(size) - 21)).all():
            raise SystemExit(f"a marker leaves camera {cam.name}'s image: lower --px-per-mm")
    return cams


def render_and_detect(out: Path, names, points, cams, diameter, seed, colours=()):
    """Render points (n, m, 3) as a marker video per camera (markers in ``colours``: one
    view per camera and colour), detect them; (detections, seconds to render, seconds to
    detect)."""
    from videotrack.detect.run import detect_project
    from videotrack.project.folders import command_config
    from videotrack.results.tables import write_table
    from videotrack.synth.project import SynthOptions, read_points, write_points_project

    out.mkdir(parents=True, exist_ok=True)
    cols = ["frame"] + [f"{m}.{a}" for m in names for a in "xyz"]
    n = points.shape[0]
    write_table(out / "points.csv", cols, np.column_stack([np.arange(n),
                                                           points.reshape(n, -1)]))
    t0 = time.perf_counter()
    pnames, pts = read_points(out / "points.csv")
    project = write_points_project(out / "video", pnames, pts, cams,
                                   SynthOptions(marker_diameter=diameter, seed=seed,
                                                layout="separate", colours=colours),
                                   fps=FPS, units="mm")
    t_render = time.perf_counter() - t0
    t0 = time.perf_counter()
    det, _, _ = detect_project(command_config(project.config, None), force=True)
    return det, t_render, time.perf_counter() - t0


# -- fitting and scoring -------------------------------------------------------------------------
def parse_param(text: str):
    """``NAME=VALUE``: the value by ast.literal_eval, else the string."""
    name, eq, value = text.partition("=")
    if not eq or not name.strip():
        raise SystemExit(f"--param: expected NAME=VALUE, got {text!r}")
    try:
        v = ast.literal_eval(value.strip())
    except (ValueError, SyntaxError):
        v = value.strip()
    return name.strip(), v


def build_params(args, threshold_px: float):
    """AnnealParams of the command line, with the re-analysis threshold of one fit."""
    from kinematics.errors import KinematicsError
    from kinematics.fit import AnnealParams, ErrorOptions

    error = {"mode": args.error, "cap_px": args.cap if args.cap > 0 else None}
    kw = {"refine": True, "reanalysis_threshold": threshold_px, "seed": args.seed}
    a_fields = {f.name for f in dataclasses.fields(AnnealParams)}
    e_fields = {f.name for f in dataclasses.fields(ErrorOptions)}
    scheduled = {}
    for text in args.param:
        name, value = parse_param(text)
        if name.startswith("error."):
            if name[6:] not in e_fields:
                raise SystemExit(f"--param {name}: unknown ErrorOptions field (known: "
                                 f"{', '.join(sorted(e_fields))})")
            error[name[6:]] = value
        elif name not in a_fields or name == "error":
            raise SystemExit(f"--param {name}: unknown AnnealParams field (known: "
                             f"{', '.join(sorted(a_fields - {'error'}))}; error.NAME for "
                             f"ErrorOptions)")
        elif name in ("n_l", "n_tau"):
            scheduled[name] = value
        else:
            kw[name] = value
    try:
        best = args.profile == "best"
        if best:  # the defaults; --error, --cap and --threshold not applied
            given = {parse_param(text)[0] for text in args.param}
            if "reanalysis_threshold" not in given:
                kw.pop("reanalysis_threshold")
            params = AnnealParams(**kw)
            given_error = {k: error[k] for k in error if f"error.{k}" in given}
            params = dataclasses.replace(params, error=dataclasses.replace(params.error,
                                                                           **given_error))
        else:
            params = AnnealParams.paper(error=ErrorOptions(**error), **kw)
        n_end = kw.get("n_end", args.n_end)
        if n_end is None and not best:
            n_end = 10000  # Table 1 shortened
        if n_end is not None:
            params = params.with_schedule(n_end)
        if params.match == "3d" and not best:  # E sums one distance per marker
            scheduled["reanalysis_threshold"] = threshold_px / args.cameras
        return dataclasses.replace(params, **scheduled)
    except (KinematicsError, TypeError) as err:
        raise SystemExit(f"--param: {err}") from None


def fit(body, cams, det, params, colours=()):
    from kinematics.fit import Fitter

    views, shows = fit_views(cams, colours, body.marker_names)
    fitter = Fitter(body, views, params, view_markers=shows)
    fitter.fit_frame([det.points_of(0, v) for v in range(det.n_views)], frame=0)  # compile
    t0 = time.perf_counter()
    res = list(fitter.iter_fit(det))
    dt = time.perf_counter() - t0
    angles = np.array([r.angles_deg for r in res])
    roots = np.array([r.root_positions for r in res])
    return res, angles, roots, dt


def fitted_markers(body, angles, roots=None):
    from kinematics.model.fk import forward_kinematics

    if roots is None:
        roots = np.broadcast_to(body.root_positions(), (len(angles), len(body.chains), 3))
    return forward_kinematics(body, np.asarray(angles), np.ascontiguousarray(roots)).markers


def fti_angle_deg(leg5):
    """Angle between femur (CTr->FTi) and tibia (FTi->TiTa) vectors, (..., 5, 3) -> (...)."""
    f = unit(leg5[..., 2, :] - leg5[..., 1, :])
    t = unit(leg5[..., 3, :] - leg5[..., 2, :])
    return np.degrees(np.arccos(np.clip((f * t).sum(-1), -1.0, 1.0)))


def score(fitted, all_truth, legs, res=None, dt=None, floor_off=None):
    """Metrics of a fit: fitted (n, 5 * len(legs), 3) markers of the legs fitted, all_truth
    (n, 30, 3) every true keypoint; ``floor_off`` (n,): the frames the chain fitted to the
    true points leaves off too (the chain's own misfit, no fit can get them right)."""
    cols = np.concatenate([np.arange(5) + 5 * LEGS.index(lg) for lg in legs])
    truth = all_truth[:, cols]
    err = np.linalg.norm(fitted - truth, axis=-1)  # (n, joints)
    n = len(err)
    worst = err.max(axis=1)
    off = worst > OFF_MM
    ft_true = fti_angle_deg(truth.reshape(n, len(legs), 5, 3))
    ft_fit = fti_angle_deg(fitted.reshape(n, len(legs), 5, 3))
    s = {"median": float(np.median(err)), "within": 100 * float((~off).mean()),
         "off": 100 * float(off.mean()), "n_off": int(off.sum()),
         "fti": float(np.sqrt(np.mean((ft_fit - ft_true) ** 2))), "worst": worst,
         "ft_true": ft_true, "ft_fit": ft_fit, "fps": n / dt if dt else np.nan}
    # failure modes of the off frames: a fitted joint nearest (and within 0.1 mm of) a true
    # keypoint of another leg, or of another joint of its own leg (a folded leg)
    d = np.linalg.norm(fitted[:, :, None] - all_truth[:, None], axis=-1)  # (n, joints, 30)
    near, dist = d.argmin(axis=2), d.min(axis=2)
    own_leg = np.repeat([LEGS.index(lg) for lg in legs], 5)
    wrong = (near != cols) & (dist < 0.1) & (err > OFF_MM)
    other = (wrong & (near // 5 != own_leg)).any(axis=1)
    folded = (wrong & (near // 5 == own_leg)).any(axis=1)
    s["modes"] = f"{other.sum()} / {folded.sum()} / {(off & ~other & ~folded).sum()}"
    if res is not None:
        status = np.array([r.status for r in res])
        failed = status == "failed"
        e = np.array([r.error for r in res])
        s["status"] = (f"{(status == 'ok').sum()} / {(status == 'reanalysed').sum()} / "
                       f"{failed.sum()}")
        s["recall"], s["precision"] = recall_precision(failed, off)
        s["recall_look"], s["precision_look"] = recall_precision(
            failed | (status == "ambiguous"), off)
        if floor_off is not None:
            s["floor_too"] = f"{int((off & floor_off).sum())} of {int(off.sum())}"
            s["recall_fit"] = recall_precision(failed | (status == "ambiguous"),
                                               off & ~floor_off)[0]
        s["e_split"] = f"{_median_text(e[~off])} / {_median_text(e[off])}"
        s["runs"] = f"{np.mean([r.runs for r in res]):.2f}"
    return s


def _median_text(v) -> str:
    return f"{np.median(v):.1f}" if len(v) else "-"


# -- main ----------------------------------------------------------------------------------------
def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="Protocol and reported figures: see the module "
                                        "docstring (python -m pydoc bench/bench_fly.py).")
    ap.add_argument("--cameras", type=int, choices=(6, 3), default=6)
    ap.add_argument("--frames", default="0:660:10",
                    help="frames of the clip to render and fit: A:B:S or a comma list "
                         "(default every 10th: 66 frames)")
    ap.add_argument("--n-end", type=int, default=None,
                    help="annealing iterations per run (default: the defaults' with "
                         "--profile best, 10000 with --profile paper)")
    ap.add_argument("--threshold", type=float, default=4.0,
                    help="re-analysis threshold in px per marker image (E / (markers x "
                         "views)); the fit's reanalysis_threshold is this x markers x views")
    ap.add_argument("--cap", type=float, default=0.0,
                    help="largest cost of one marker (px); 0: no cap (the paper)")
    ap.add_argument("--error", choices=("paper", "bidirectional", "bounded"), default="paper")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="any AnnealParams field (error.NAME: an ErrorOptions field), value "
                         "read as a Python literal, else a string; repeatable; applied last")
    ap.add_argument("--profile", choices=("paper", "best"), default="paper",
                    help="settings the fits start from: the paper's (Table 1, Eq. 5) with "
                         "--error, --cap, --threshold and refinement, or 'best', the "
                         "defaults a user gets (those three options then unused)")
    ap.add_argument("--leg", choices=LEGS, default="LF", help="the leg of the one-leg fits")
    ap.add_argument("--fits", default="floor,body,among,alone",
                    help="comma list of the fits to run: floor, body, among, alone")
    ap.add_argument("--threads", type=int, default=2, help="numba threads of the fits")
    ap.add_argument("--diameter", type=float, default=4.0, help="marker diameter (px)")
    ap.add_argument("--px-per-mm", type=float, default=100.0,
                    help="image scale at the fly (focal length / distance); 100: the fly's "
                         "legs span ~400 px of the 640x640 images, the closest markers of a "
                         "leg (the middle coxa, 0.18 mm) 18 px apart")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--colours", choices=tuple(COLOUR_SCHEMES), default="none",
                    help="draw the markers in colours, one view per camera and colour, each "
                         "matched to its colour's markers: tripods (LF RM LH red, the other "
                         "three green: neighbouring legs differ), sides (left red, right "
                         "green), segments (front, middle, hind legs), legs (six colours)")
    ap.add_argument("--measure-ranges", action="store_true",
                    help="only fit the chain to all 660 frames' true points with opened "
                         "ranges and print the observed angle ranges (~2 min)")
    ap.add_argument("--data", type=Path, default=DATA,
                    help="the clip (default: ../shared/data/flygym_fly_kinematics/"
                         "spotlight_behavior_clip.npz beside the repository)")
    ap.add_argument("--out", type=Path, default=None,
                    help="folder for the derived files and the figure (default: temporary)")
    args = ap.parse_args()
    fits = {f.strip() for f in args.fits.split(",") if f.strip()}
    if not fits <= {"floor", "body", "among", "alone"}:
        raise SystemExit(f"--fits: unknown {sorted(fits - {'floor', 'body', 'among', 'alone'})}")
    args.fit_set = fits
    if not args.data.is_file():
        print(f"skipped: no flygym clip at {args.data} (../shared/data is absent)")
        return 0
    build_params(args, 1.0)  # a bad --param fails before anything runs
    return in_out_folder(args.out, "bench_fly_", lambda folder, keep: run(args, folder, keep))


def recall_precision(flagged: np.ndarray, off: np.ndarray) -> tuple[str, str]:
    """Recall (off frames flagged) and precision (flagged frames off) as table cells."""
    hit = int((flagged & off).sum())
    recall = f"{100 * hit / off.sum():.0f} % ({hit}/{off.sum()})" if off.any() else \
        "- (none off)"
    precision = f"{100 * hit / flagged.sum():.0f} % ({hit}/{flagged.sum()})" if \
        flagged.any() else "- (none flagged)"
    return recall, precision


def run(args, out: Path, keep: bool) -> int:
    from kinematics.model import Body
    from kinematics.model.chain_xml import load_body, save_body

    numba.set_num_threads(max(1, min(args.threads, numba.config.NUMBA_NUM_THREADS)))
    pts = load_clip(args.data)
    names = marker_names()
    shipped = load_body(CHAIN)
    if shipped.marker_names != names:
        raise SystemExit(f"{CHAIN} has markers {shipped.marker_names[:5]}..., expected "
                         f"{names[:5]}...")
    body = adapt_body(shipped, pts)
    save_body(out / "fly_adapted.xml", body)
    if args.measure_ranges:
        measure_ranges(body, pts, np.arange(len(pts)))
        return 0
    frames = parse_frames(args.frames, len(pts))
    truth = pts[frames]
    n = len(frames)
    leg = args.leg
    li = LEGS.index(leg)
    leg_cols = slice(5 * li, 5 * li + 5)
    lengths = {c.name: [s.length for _, s in Body(body.name, (c,), body.units).segments()]
               for c in body.chains}
    print(f"Fly, flygym spotlight clip: {n} of {len(pts)} frames ({args.frames}) at 330 Hz; "
          f"chain {CHAIN.name} adapted (segment lengths mm, coxa/femur/tibia/tarsus: "
          + "; ".join(f"{k[:2].upper()} " + "/".join(f"{v:.3f}" for v in ls)
                      for k, ls in lengths.items())
          + f"); {machine()}, {numba.get_num_threads()} threads")

    results, series = {}, {}
    t0 = time.perf_counter()
    floor_angles, at_limit = floor_fit(body, truth, np.arange(n))
    t_floor = time.perf_counter() - t0
    lim_frames = at_limit.any(axis=1)
    bad = ~plausible(truth)
    per_leg = ", ".join(f"{lg} {c}" for lg, c in zip(LEGS, at_limit.sum(0), strict=True) if c)
    print(f"Range check: the least-squares fit to the true points ends within 0.5 deg of an "
          f"axis limit of the shipped ranges in {int(lim_frames.sum())} of {n} frames "
          f"(per leg: {per_leg or 'none'}; {int((at_limit & bad).any(axis=1).sum())} of them "
          f"where that leg's keypoints are mispredicted, a segment > "
          f"{100 * LENGTH_TOL:.0f} % off its median length).")
    floor_scored = score(fitted_markers(body, floor_angles), truth, LEGS, dt=t_floor)
    if "floor" in args.fit_set:
        results["floor (3D least squares)"] = floor_scored
        series["floor"] = leg_series(floor_scored, li)
    floor_off = floor_scored["worst"] > OFF_MM

    need_video = args.fit_set & {"body", "among", "alone"}
    if need_video:
        cams = place_cameras(pts, args.cameras, args.px_per_mm)
        colours = colours_of(args.colours, names)
        det, t_r, t_d = render_and_detect(out / "all", names, truth, cams, args.diameter,
                                          args.seed, colours)
        counts = det.counts()
        print(f"Rendered {n} frames x {len(cams)} views (640x640, {args.px_per_mm:g} px/mm at "
              f"the fly, 60 mm away, {args.diameter:g}-px markers) in {t_r:.1f} s, "
              f"detected in {t_d:.1f} s: {int(counts.sum())} detections of {n * len(cams) * 30}"
              f" marker images" + (f" in {det.n_views} views ({args.colours}: "
                                  f"{len(colours)} colours)" if colours else
                                  f" ({int((counts < 30).sum())} of {counts.size} view "
                                  f"images with fused markers)") + ".")
    if "alone" in args.fit_set:
        leg_colours = colours_of(args.colours, names[leg_cols])
        det_leg, _, _ = render_and_detect(out / f"{leg}_alone", names[leg_cols],
                                          truth[:, leg_cols], cams, args.diameter, args.seed,
                                          leg_colours)
    p = build_params(args, args.threshold * 30 * args.cameras)
    threshold = ("threshold_mode='auto'" if args.profile == "best" else
                 f"reanalysis_threshold={args.threshold:g} px x markers x views")
    print(f"Fit: {'AnnealParams' if args.profile == 'best' else 'AnnealParams.paper'}"
          f"(refine=True, n_end={p.n_end}, n_l={p.n_l}, n_tau={p.n_tau}, "
          f"max_runs={p.max_runs}, error={p.error.mode!r}, cap_px={p.error.cap_px}, "
          f"match={p.match!r}, {threshold}"
          + (f"; --param {' '.join(args.param)}" if args.param else "") + ").\n")

    if "body" in args.fit_set:
        params = build_params(args, args.threshold * 30 * args.cameras)
        res, ang, roots, dt = fit(body, cams, det, params, colours)
        s = score(fitted_markers(body, ang, roots), truth, LEGS, res, dt, floor_off)
        results[f"whole body ({args.cameras} cams)"] = s
        series["whole body"] = leg_series(s, li)
    one = sub_body(body, (leg,))
    for key, label in (("among", f"{leg} among six"), ("alone", f"{leg} alone")):
        if key not in args.fit_set:
            continue
        params = build_params(args, args.threshold * 5 * args.cameras)
        res, ang, roots, dt = fit(one, cams, det if key == "among" else det_leg, params,
                                  colours if key == "among" else leg_colours)
        fm = fitted_markers(one, ang, roots)
        s = score(fm, truth, (leg,), res, dt)
        results[label] = s
        series[label] = leg_series(s, 0)

    columns = list(results)
    fmt = {"median": "{:.3f}", "within": "{:.1f}", "off": "{:.1f}", "fti": "{:.1f}",
           "fps": "{:.2f}"}
    labels = {"median": "median 3D joint error (mm)",
              "within": "frames with every joint within 0.2 mm (%)",
              "off": "frames with a joint off by > 0.2 mm (%)",
              "fti": "femur-tibia angle RMSE (deg)",
              "fps": f"frames/s ({numba.get_num_threads()} threads)"}
    rows = [(labels[k], *(fmt[k].format(results[c][k]) for c in columns), TARGETS[k])
            for k in fmt]
    for key, label in (("modes", "off frames: on another leg / folded / other"),
                       ("status", "status ok / reanalysed / failed"),
                       ("runs", "runs per frame (mean)"),
                       ("e_split", "median E (px): frames within / off"),
                       ("recall", "status recall: off frames that failed"),
                       ("precision", "status precision: failed frames that are off"),
                       ("recall_look", "recall: off frames failed or ambiguous"),
                       ("precision_look", "precision: failed or ambiguous frames off"),
                       ("floor_too", "off frames the floor leaves off too"),
                       ("recall_fit", "recall on the others (the fit's own errors)")):
        rows.append((label, *(results[c].get(key, "-") for c in columns),
                     TARGETS.get(key, "")))
    print_table(rows, "target", results=columns)
    png = plot(series, frames, leg, out / "fly.png")
    print(f"\nFigure: {png}" + ("" if keep else " (temporary; give --out to keep it)"))
    return 0


def leg_series(s, col):
    """What the figure shows of a fit: worst joint error per frame, the leg's true and
    fitted femur-tibia angle."""
    return s["worst"], s["ft_true"][:, col], s["ft_fit"][:, col]


def plot(series, frames, leg, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    t = frames / FPS
    colours = ("0.5", "tab:blue", "tab:red", "tab:green", "tab:purple")
    for k, ((name, (worst, ft_true, ft_fit)), colour) in enumerate(
            zip(series.items(), colours, strict=False)):
        axes[0].plot(t, worst, ".-", ms=3, lw=0.6, color=colour, label=name)
        if k == 0:
            axes[1].plot(t, ft_true, "k-", lw=1.5, label=f"{leg} true")
        axes[1].plot(t, ft_fit, ".", ms=4, color=colour, label=name)
    axes[0].axhline(OFF_MM, color="k", ls=":", lw=1)
    axes[0].set_yscale("log")
    axes[0].set_ylabel("worst joint 3D error (mm)")
    axes[1].set_ylabel(f"{leg} femur-tibia angle (deg)")
    axes[1].set_xlabel("time in the clip (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    fig.suptitle("Fly, flygym clip rendered as marker videos: fitted vs true")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    raise SystemExit(main())
