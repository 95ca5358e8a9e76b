"""Forward kinematics: hand-computed postures of the paper's chains, numba == NumPy twin."""

from pathlib import Path

import numpy as np
import pytest

from kinematics.model.fk import forward_kinematics, forward_kinematics_reference
from kinematics.model.packing import pack_body
from kinematics.model.rotations import euler_yxz, rot_x, rot_y, rot_z

CHAINS = Path(__file__).resolve().parents[2] / "chains"


def test_euler_order_is_ry_rx_rz():
    a, b, c = 0.3, -0.7, 1.1
    np.testing.assert_allclose(euler_yxz(a, b, c), rot_y(a) @ rot_x(b) @ rot_z(c))
    # Active right-handed rotations: +90 deg about z turns x into y.
    np.testing.assert_allclose(rot_z(np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rot_y(np.pi / 2) @ [0, 0, 1], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(rot_x(np.pi / 2) @ [0, 1, 0], [0, 0, 1], atol=1e-15)


def locust_by_hand(phi, psi, alpha, beta, gamma):
    """Planar leg geometry, worked out without rotation matrices.

    Ry(phi)·Rx(psi) spans the leg plane with in-plane unit vectors ex, ey; alpha, beta and
    gamma are z rotations, so segment directions are angles within that plane. The
    femur-tibia joint's default orientation adds 180 deg (gamma = femur-tibia angle).
    """
    p, s = np.deg2rad(phi), np.deg2rad(psi)
    ex = np.array([np.cos(p), 0.0, -np.sin(p)])
    ey = np.array([np.sin(s) * np.sin(p), np.cos(s), np.sin(s) * np.cos(p)])

    def direction(angle_deg):
        a = np.deg2rad(angle_deg)
        return np.cos(a) * ex + np.sin(a) * ey

    j0 = np.zeros(3)
    j1 = j0 + 13 * direction(alpha)
    j2 = j1 + 91 * direction(alpha + beta)
    tip = j2 + 77 * direction(alpha + beta + gamma + 180)
    return np.array([j0, j1, j2, tip])


@pytest.mark.parametrize("posture", [
    (180, 0, 0, 0, 90),
    (150, 0, 0, 30, 20),
    (200, 30, -10, 45, 150),
    (125, -35, 8, -25, 60),
])
def test_locust_hand_computed(locust, posture):
    phi, psi, alpha, beta, gamma = posture
    angles = np.array([phi, psi, alpha, 0, 0, beta, 0, 0, gamma], dtype=float)
    expected = locust_by_hand(*posture)
    for pose in (forward_kinematics_reference(locust, angles), forward_kinematics(locust, angles)):
        np.testing.assert_allclose(pose.markers, expected, atol=1e-9)
        np.testing.assert_allclose(pose.joints, expected[:3], atol=1e-9)
        np.testing.assert_allclose(pose.segment_ends, expected[1:], atol=1e-9)


def test_locust_rest_posture_numbers(locust):
    # phi = 180 turns the leg backwards; gamma = 90 points the tibia straight down.
    angles = np.array([180, 0, 0, 0, 0, 0, 0, 0, 90], dtype=float)
    pose = forward_kinematics(locust, angles)
    np.testing.assert_allclose(pose.markers[-1], [-104.0, -77.0, 0.0], atol=1e-9)


def test_root_position_offsets_everything(locust):
    angles = locust.mean_posture_deg()
    base = forward_kinematics(locust, angles)
    moved = forward_kinematics(locust, angles, root_positions=[[5.0, -2.0, 7.0]])
    np.testing.assert_allclose(moved.markers - base.markers, np.tile([5.0, -2.0, 7.0], (4, 1)))


def random_postures(body, n, rng):
    lo, hi = body.ranges_deg().T
    return rng.uniform(lo - 30, hi + 30, size=(n, body.n_axes))


def test_numba_matches_numpy_reference_over_random_postures(locust):
    rng = np.random.default_rng(7)
    angles = random_postures(locust, 200, rng)
    roots = rng.normal(0, 50, size=(200, 1, 3))
    batch = forward_kinematics(pack_body(locust), angles, roots)
    for k in range(angles.shape[0]):
        ref = forward_kinematics_reference(locust, angles[k], roots[k])
        np.testing.assert_allclose(batch.markers[k], ref.markers, atol=1e-9, rtol=0)
        np.testing.assert_allclose(batch.joints[k], ref.joints, atol=1e-9, rtol=0)
        np.testing.assert_allclose(batch.segment_ends[k], ref.segment_ends, atol=1e-9, rtol=0)


def test_rejects_wrong_posture_length(locust):
    from kinematics.errors import KinematicsError

    with pytest.raises(KinematicsError, match="9 angles"):
        forward_kinematics(locust, np.zeros(5))
    with pytest.raises(KinematicsError, match="9 angles"):
        forward_kinematics_reference(locust, np.zeros(5))


def stick_insect_by_hand(pi, rho, alpha, beta, gamma):
    """Leg direction in the body's horizontal plane is 270 - alpha deg right of forward;
    beta levates the femur in the vertical leg plane, gamma + 180 turns the tibia in it
    (psi = 0). The body orientation Ry(pi)·Rz(rho) then turns everything."""
    th, b = np.deg2rad(270.0 - alpha), np.deg2rad(beta)
    d = np.array([np.cos(th), 0.0, np.sin(th)])
    up = np.array([0.0, 1.0, 0.0])
    femur = np.cos(b) * d + np.sin(b) * up
    t = np.deg2rad(beta + gamma + 180.0)
    tibia = np.cos(t) * d + np.sin(t) * up
    j1 = np.array([12.0, 0.0, 0.0])
    j2 = j1 + 16 * femur
    body_frame = np.array([[0, 0, 0], [9, 0, 0], j1 + 10 * femur, j2 + 10 * tibia])
    turn = rot_y(np.deg2rad(pi)) @ rot_z(np.deg2rad(rho))
    return body_frame @ turn.T


@pytest.mark.parametrize("posture", [(0, 0, 195, 0, 90), (20, 10, 160, 40, 30),
                                     (-30, 5, 230, -20, 120)])
def test_stick_insect_hand_computed(stick_insect, posture):
    pi, rho, alpha, beta, gamma = posture
    angles = np.array([pi, 0, rho, alpha, 0, beta, 0, 0, gamma], dtype=float)
    expected = stick_insect_by_hand(*posture)
    for pose in (forward_kinematics_reference(stick_insect, angles),
                 forward_kinematics(stick_insect, angles)):
        np.testing.assert_allclose(pose.markers, expected, atol=1e-9)


def test_branched_multichain_body_numba_matches_reference():
    """Every constant of Eq. 1/2 non-trivial: R^d, T, R^s, offsets, branches, two chains."""
    from kinematics.model import Axis, Body, Chain, Joint, Marker, Root, Segment

    rng = np.random.default_rng(3)

    def vec(scale):
        return tuple(float(v) for v in rng.normal(0, scale, 3))

    def joint(name, depth):
        segs = []
        for k in range(2 if depth < 2 else 1):
            kids = (joint(f"{name}{k}", depth + 1),) if depth < 2 else ()
            segs.append(Segment(f"s{name}{k}", float(rng.uniform(1, 20)), vec(40),
                                (Marker(f"m{name}{k}", vec(5)),), kids))
        axes = (Axis.free("a", "y", -90, 90), Axis.free("b", "x", -90, 90),
                Axis.free("c", "z", -90, 90))
        return Joint(name, axes, vec(40), vec(3), tuple(segs))

    body = Body("tree", (Chain("left", joint("L", 0), Root("fixed", vec(10))),
                         Chain("right", joint("R", 0), Root("fixed", vec(10)))))
    body.validate()
    angles = random_postures(body, 50, rng)
    batch = forward_kinematics(body, angles)
    assert batch.markers.shape == (50, len(body.marker_names), 3)
    for k in range(50):
        ref = forward_kinematics_reference(body, angles[k])
        np.testing.assert_allclose(batch.markers[k], ref.markers, atol=1e-9, rtol=0)
        np.testing.assert_allclose(batch.joints[k], ref.joints, atol=1e-9, rtol=0)


def test_bundled_chains_load_and_fly_body_scales():
    from kinematics.model.chain_xml import load_body

    fly = load_body(CHAINS / "fly_six_legs.xml")
    assert len(fly.chains) == 6 and len(fly.marker_names) == 30 and fly.n_axes == 72
    assert "NeuroMechFly" in fly.description
    rng = np.random.default_rng(11)
    angles = random_postures(fly, 20, rng)
    batch = forward_kinematics(fly, angles)
    for k in range(20):
        ref = forward_kinematics_reference(fly, angles[k])
        np.testing.assert_allclose(batch.markers[k], ref.markers, atol=1e-9, rtol=0)
    # legs hang from their fixed roots: the thorax-coxa markers never move
    np.testing.assert_allclose(batch.markers[:, ::5], np.broadcast_to(
        batch.markers[:1, ::5], batch.markers[:, ::5].shape), atol=1e-12)


def test_stick_insect_file_matches_the_python_built_chain(stick_insect):
    from kinematics.model.chain_xml import load_body

    assert load_body(CHAINS / "stick_insect_frontleg.xml") == stick_insect


def test_marker_may_not_share_a_joint_name(locust):
    import dataclasses

    from kinematics.errors import KinematicsError
    from kinematics.model import Marker

    j0 = locust.chains[0].root_joint
    coxa = dataclasses.replace(j0.segments[0], markers=(Marker("J1"),))
    chain = dataclasses.replace(locust.chains[0], root_joint=dataclasses.replace(
        j0, segments=(coxa,)))
    with pytest.raises(KinematicsError, match="name of a joint"):
        dataclasses.replace(locust, chains=(chain,)).validate()


def test_axis_may_not_be_named_like_a_coordinate(locust):
    import dataclasses

    from kinematics.errors import KinematicsError
    from kinematics.model import Axis

    j0 = locust.chains[0].root_joint
    bad = dataclasses.replace(j0, axes=(j0.axes[0], j0.axes[1], Axis.free("z", "z", -10, 10)))
    chain = dataclasses.replace(locust.chains[0], root_joint=bad)
    with pytest.raises(KinematicsError, match="like a 3D coordinate"):
        dataclasses.replace(locust, chains=(chain,)).validate()
