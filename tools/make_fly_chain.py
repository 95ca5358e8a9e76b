"""Write chains/fly_six_legs.xml: a six-legged fruit fly (Drosophila) body, 30 joints.

Coxa positions and segment lengths (mm) are rounded from the NeuroMechFly model (flygym,
Apache-2.0: NeLy-EPFL/flygym, ``neuromechfly_seqik_kinorder_ypr.xml``); the five tarsal
segments are merged into one. Converted to VideoTrack's world axes (x anterior, y up,
z right). Each leg is a chain whose fixed root is the thorax-coxa joint:

* ThC (3 DOF): ``roll`` about the vertical (y), ``yaw`` about x, ``pitch`` about z; its
  default orientation points the coxa straight down.
* CTr (coxa-trochanter/femur): ``roll`` (x, along the leg) and ``pitch`` (z); y locked.
* FTi (femur-tibia) and TiTa (tibia-tarsus): hinges about z.

Markers (``<leg>_<keypoint>_mk``) sit at every joint centre and the tarsus tip, like
DeepFly3D's 5 keypoints per leg.

The angle ranges cover real fly movement: :data:`MEASURED` holds the angles observed in the
flygym spotlight clip, and :data:`RANGES` is every measured range widened by
:data:`MARGIN_DEG` on both sides, rounded outward to 5 deg, and joined with the earlier
generic ranges (:data:`GENERIC`), so no range got narrower. Left legs mirror right legs:
mirroring z (left to right) negates rotations about y and x and keeps those about z.
This tool reads no data; ``python bench/bench_fly.py --measure-ranges`` measures again.

Usage: python tools/make_fly_chain.py
"""

from __future__ import annotations

import math
from pathlib import Path

from kinematics.model import Axis, Body, Chain, Joint, Marker, Root, Segment
from kinematics.model.chain_xml import save_body

REPO = Path(__file__).resolve().parents[1]
DESCRIPTION = (
    "Six-legged fruit fly made by tools/make_fly_chain.py. Coxa positions and segment lengths "
    "are rounded from the NeuroMechFly model (flygym, NeLy-EPFL, Apache-2.0); the angle ranges "
    "cover the joint angles of a real fly's legs (flygym spotlight clip) with 10 degrees to "
    "spare."
)

# Thorax-coxa positions in NeuroMechFly's thorax frame (x fwd, y left, z up), right legs.
COXA_MJCF = {"F": (-0.161, -0.172, -0.230), "M": (-0.557, -0.125, -0.482),
             "H": (-0.784, -0.087, -0.497)}
AXES = ("ThC.roll", "ThC.yaw", "ThC.pitch", "CTr.roll", "CTr.pitch", "FTi.pitch",
        "TiTa.pitch")
MIRRORED = ("ThC.roll", "ThC.yaw", "CTr.roll")  # rotations about y or x: sign flips for left legs
MARGIN_DEG = 10.0
# Angle ranges (deg) observed in the flygym spotlight clip (NeLy-EPFL, Apache-2.0; a tethered
# fly, 660 frames at 330 Hz: ../shared/data/flygym_fly_kinematics/spotlight_behavior_clip.npz),
# right-leg convention, left and right legs of a pair together. Measured by
# ``python bench/bench_fly.py --measure-ranges``: this chain with its roots at the clip's
# median thorax-coxa keypoints and its segment lengths the median keypoint distances, each leg
# fitted by least squares to the clip's 5 keypoints in every frame, the ranges opened to
# +-250 deg (a pull of 2e-4 mm/deg toward the range centres picks one of the postures that
# differ only in how ThC and CTr roll share the coxa's twist); frames with a segment of that
# leg more than 25 % off its median length are mispredicted keypoints and left out (1-16 of 660
# per leg: e.g. a tarsus at 0.6x its length gave TiTa -69 and +118 deg). The split of the
# coxa's twist (ThC roll, yaw, pitch and CTr roll) follows the pull, so those four move by a
# few degrees when the ranges' centres move; the margin absorbs that.
MEASURED = {
    "F": {"ThC.roll": (-50.4, -21.0), "ThC.yaw": (-18.1, 24.8), "ThC.pitch": (-44.1, -4.9),
          "CTr.roll": (-10.6, 16.3), "CTr.pitch": (88.3, 184.9), "FTi.pitch": (-136.3, -11.5),
          "TiTa.pitch": (-2.1, 53.1)},
    "M": {"ThC.roll": (-109.0, -78.3), "ThC.yaw": (-16.3, 43.2), "ThC.pitch": (-23.0, 30.1),
          "CTr.roll": (-6.2, 16.9), "CTr.pitch": (71.6, 167.8), "FTi.pitch": (-137.9, -46.6),
          "TiTa.pitch": (-9.9, 47.0)},
    "H": {"ThC.roll": (-153.5, -131.6), "ThC.yaw": (-31.9, 8.6), "ThC.pitch": (-7.0, 43.4),
          "CTr.roll": (-12.9, 5.4), "CTr.pitch": (44.9, 141.3), "FTi.pitch": (-146.7, -9.3),
          "TiTa.pitch": (-31.0, 115.6)},
}
# The earlier generic ranges (right legs). ThC roll turns the plane in which the leg swings
# out, so front legs reach forward, middle legs sideways, hind legs backward. CTr pitch 180
# folds the femur back along the coxa (front legs do, past it by a few degrees); FTi 0 is a
# straight femur-tibia.
GENERIC = {
    pos: {"ThC.roll": roll, "ThC.yaw": (-60, 60), "ThC.pitch": (-40, 60), "CTr.roll": (-90, 90),
          "CTr.pitch": (20, 160), "FTi.pitch": (-170, 0), "TiTa.pitch": (-30, 120)}
    for pos, roll in (("F", (-60, 0)), ("M", (-120, -60)), ("H", (-170, -130)))
}


def covering(measured: tuple[float, float], generic: tuple[float, float]) -> tuple[float, float]:
    """The measured range widened by the margin, rounded outward to 5 deg, joined with the
    generic range."""
    lo = 5.0 * math.floor((measured[0] - MARGIN_DEG) / 5.0)
    hi = 5.0 * math.ceil((measured[1] + MARGIN_DEG) / 5.0)
    return min(lo, generic[0]) + 0.0, max(hi, generic[1]) + 0.0  # + 0.0: no "-0" in the file


# Ranges of the right legs (deg); every one covers MEASURED with MARGIN_DEG to spare.
RANGES = {pos: {a: covering(MEASURED[pos][a], GENERIC[pos][a]) for a in AXES} for pos in "FMH"}


def leg_ranges(side: str, pos: str) -> dict[str, tuple[float, float]]:
    """The ranges of one leg: the right leg's, mirrored for a left leg."""
    right = RANGES[pos]
    if side == "R":
        return dict(right)
    return {a: (-hi, -lo) if a in MIRRORED else (lo, hi) for a, (lo, hi) in right.items()}


# Coxa, femur, tibia, tarsus (sum of tarsus 1-5) lengths.
LENGTHS = {"F": (0.365, 0.705, 0.518, 0.565), "M": (0.181, 0.784, 0.667, 0.607),
           "H": (0.199, 0.836, 0.684, 0.698)}


def hinge(name: str, rng: tuple[float, float], segment: Segment) -> Joint:
    return Joint(name, (Axis.fixed("ry", "y"), Axis.fixed("rx", "x"),
                        Axis.free("pitch", "z", *rng)), segments=(segment,))


def leg(side: str, pos: str) -> Chain:
    p = f"{side}{pos}"
    coxa, femur, tibia, tarsus = LENGTHS[pos]
    x, y_left, z_up = COXA_MJCF[pos]
    if side == "L":
        y_left = -y_left
    root = Root("fixed", (x, z_up, -y_left))
    rng = leg_ranges(side, pos)
    tarsus_seg = Segment(f"{p}_tarsus", tarsus, markers=(Marker(f"{p}_Tip_mk"),))
    tita = hinge(f"{p}_TiTa", rng["TiTa.pitch"], tarsus_seg)
    tibia_seg = Segment(f"{p}_tibia", tibia, markers=(Marker(f"{p}_TiTa_mk"),), joints=(tita,))
    fti = hinge(f"{p}_FTi", rng["FTi.pitch"], tibia_seg)
    femur_seg = Segment(f"{p}_femur", femur, markers=(Marker(f"{p}_FTi_mk"),), joints=(fti,))
    ctr = Joint(f"{p}_CTr", (Axis.fixed("ry", "y"), Axis.free("roll", "x", *rng["CTr.roll"]),
                             Axis.free("pitch", "z", *rng["CTr.pitch"])), segments=(femur_seg,))
    coxa_seg = Segment(f"{p}_coxa", coxa,
                       markers=(Marker(f"{p}_ThC_mk", (-coxa, 0.0, 0.0)), Marker(f"{p}_CTr_mk")),
                       joints=(ctr,))
    thc = Joint(f"{p}_ThC", (Axis.free("roll", "y", *rng["ThC.roll"]),
                             Axis.free("yaw", "x", *rng["ThC.yaw"]),
                             Axis.free("pitch", "z", *rng["ThC.pitch"])),
                orientation_deg=(0.0, 0.0, -90.0), segments=(coxa_seg,))
    return Chain(f"{p.lower()}_leg", thc, root)


def build_body() -> Body:
    """The fly: one chain per leg, in the order LF, LM, LH, RF, RM, RH."""
    chains = tuple(leg(s, p) for s in "LR" for p in "FMH")
    body = Body("fly-six-legs", chains, units="mm", description=DESCRIPTION)
    body.validate()
    return body


def main() -> None:
    out = REPO / "chains" / "fly_six_legs.xml"
    save_body(out, build_body())
    print(out)


if __name__ == "__main__":
    main()
