"""Shared fixtures: the paper's chains built through the Python API (independent of XML)."""

from __future__ import annotations

from pathlib import Path

import pytest

from kinematics.model import Axis, Body, Chain, Joint, Marker, Root, Segment

REPO = Path(__file__).resolve().parents[1]
CHAINS = REPO / "chains"
SHARED_DATA = REPO.parent / "shared" / "data"


def hinge(name: str, axis_name: str, lo: float, hi: float, segment: Segment,
          orientation=(0.0, 0.0, 0.0)) -> Joint:
    """A joint with y and x locked at 0 and a free z axis (the paper's hinge joints)."""
    return Joint(name, (Axis.fixed("ry", "y"), Axis.fixed("rx", "x"),
                        Axis.free(axis_name, "z", lo, hi)), orientation, (0, 0, 0), (segment,))


def locust_body() -> Body:
    """Fig. 5: coxa 13, femur 91, tibia 77 px; markers at J0, J1, J2 and the tibia tip."""
    tibia = Segment("tibia", 77.0, markers=(Marker("M3"),))
    j2 = hinge("J2", "gamma", 20, 160, tibia, orientation=(0.0, 0.0, 180.0))
    femur = Segment("femur", 91.0, markers=(Marker("M2"),), joints=(j2,))
    j1 = hinge("J1", "beta", -30, 60, femur)
    coxa = Segment("coxa", 13.0, markers=(Marker("M0", (-13.0, 0.0, 0.0)), Marker("M1")),
                   joints=(j1,))
    j0 = Joint("J0", (Axis.free("phi", "y", 120, 220), Axis.free("psi", "x", -40, 40),
                      Axis.free("alpha", "z", -10, 10)), segments=(coxa,))
    return Body("locust-hindleg", (Chain("hindleg", j0, Root("fixed")),), units="px")


@pytest.fixture
def locust() -> Body:
    return locust_body()


def stick_insect_body() -> Body:
    """Fig. 7 with the lengths of chains/stick_insect_frontleg.xml (mm)."""
    tibia = Segment("tibia", 14.0, markers=(Marker("M3", (-4.0, 0.0, 0.0)),))
    j2 = hinge("J2", "gamma", 10, 140, tibia, orientation=(0.0, 0.0, 180.0))
    femur = Segment("femur", 16.0, markers=(Marker("M2", (-6.0, 0.0, 0.0)),), joints=(j2,))
    j1 = Joint("J1", (Axis.free("alpha", "y", 150, 240), Axis.free("psi", "x", -30, 50),
                      Axis.free("beta", "z", -45, 75)), segments=(femur,))
    # R^s = Ry(90): the distal frame's z points forward, so -z is straight back.
    thorax = Segment("thorax", 12.0, (90.0, 0.0, 0.0),
                     markers=(Marker("M0", (0, 0, -12.0)), Marker("M1", (0, 0, -3.0))),
                     joints=(j1,))
    j0 = Joint("J0", (Axis.free("pi", "y", -35, 35), Axis.fixed("rx", "x"),
                      Axis.free("rho", "z", 0, 20)), segments=(thorax,))
    chain = Chain("frontleg-right", j0, Root("marker", marker="M0"))
    return Body("stick-insect-frontleg", (chain,), units="mm")


@pytest.fixture
def stick_insect() -> Body:
    return stick_insect_body()
