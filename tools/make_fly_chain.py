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
Usage: python tools/make_fly_chain.py
"""

from __future__ import annotations

from pathlib import Path

from kinematics.chain_xml import save_body
from kinematics.model import Axis, Body, Chain, Joint, Marker, Root, Segment

REPO = Path(__file__).resolve().parents[1]
DESCRIPTION = (
    "Six-legged fruit fly made by tools/make_fly_chain.py. Coxa positions and segment lengths "
    "are rounded from the NeuroMechFly model (flygym, NeLy-EPFL, Apache-2.0)."
)

# Thorax-coxa positions in NeuroMechFly's thorax frame (x fwd, y left, z up), right legs.
COXA_MJCF = {"F": (-0.161, -0.172, -0.230), "M": (-0.557, -0.125, -0.482),
             "H": (-0.784, -0.087, -0.497)}
# ThC roll range of the right legs (left legs mirrored): it turns the plane in which the
# leg swings out, so front legs reach forward, middle legs sideways, hind legs backward.
ROLL_RIGHT = {"F": (-60, 0), "M": (-120, -60), "H": (-170, -130)}
# Coxa, femur, tibia, tarsus (sum of tarsus 1-5) lengths.
LENGTHS = {"F": (0.365, 0.705, 0.518, 0.565), "M": (0.181, 0.784, 0.667, 0.607),
           "H": (0.199, 0.836, 0.684, 0.698)}


def hinge(name: str, lo: float, hi: float, segment: Segment) -> Joint:
    return Joint(name, (Axis.fixed("ry", "y"), Axis.fixed("rx", "x"),
                        Axis.free("pitch", "z", lo, hi)), segments=(segment,))


def leg(side: str, pos: str) -> Chain:
    p = f"{side}{pos}"
    coxa, femur, tibia, tarsus = LENGTHS[pos]
    x, y_left, z_up = COXA_MJCF[pos]
    if side == "L":
        y_left = -y_left
    root = Root("fixed", (x, z_up, -y_left))
    tarsus_seg = Segment(f"{p}_tarsus", tarsus, markers=(Marker(f"{p}_Tip_mk"),))
    tita = hinge(f"{p}_TiTa", -30, 120, tarsus_seg)
    tibia_seg = Segment(f"{p}_tibia", tibia, markers=(Marker(f"{p}_TiTa_mk"),), joints=(tita,))
    fti = hinge(f"{p}_FTi", -170, 0, tibia_seg)
    femur_seg = Segment(f"{p}_femur", femur, markers=(Marker(f"{p}_FTi_mk"),), joints=(fti,))
    ctr = Joint(f"{p}_CTr", (Axis.fixed("ry", "y"), Axis.free("roll", "x", -90, 90),
                             Axis.free("pitch", "z", 20, 160)), segments=(femur_seg,))
    coxa_seg = Segment(f"{p}_coxa", coxa,
                       markers=(Marker(f"{p}_ThC_mk", (-coxa, 0.0, 0.0)), Marker(f"{p}_CTr_mk")),
                       joints=(ctr,))
    lo, hi = ROLL_RIGHT[pos] if side == "R" else (-ROLL_RIGHT[pos][1], -ROLL_RIGHT[pos][0])
    thc = Joint(f"{p}_ThC", (Axis.free("roll", "y", lo, hi),
                             Axis.free("yaw", "x", -60, 60),
                             Axis.free("pitch", "z", -40, 60)),
                orientation_deg=(0.0, 0.0, -90.0), segments=(coxa_seg,))
    return Chain(f"{p.lower()}_leg", thc, root)


def main() -> None:
    chains = tuple(leg(s, p) for s in "LR" for p in "FMH")
    body = Body("fly-six-legs", chains, units="mm", description=DESCRIPTION)
    body.validate()
    out = REPO / "chains" / "fly_six_legs.xml"
    save_body(out, body)
    print(out)


if __name__ == "__main__":
    main()
