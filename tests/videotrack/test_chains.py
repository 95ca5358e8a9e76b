"""The shipped fly chain: built by tools/make_fly_chain.py, per-leg chains with fixed roots at
the thorax-coxa joints, mirrored left to right, ranges covering the measured fly movement."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from kinematics.model.chain_xml import load_body
from kinematics.model.fk import forward_kinematics

REPO = Path(__file__).resolve().parents[2]
FLY = REPO / "chains" / "fly_six_legs.xml"


@pytest.fixture(scope="module")
def tool():
    spec = importlib.util.spec_from_file_location("make_fly_chain",
                                                  REPO / "tools" / "make_fly_chain.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def fly():
    return load_body(FLY)


def leg_ranges(body, chain_name):
    """{'ThC.roll': (lo, hi), ...} of a chain's free axes."""
    out = {}
    for ref in body.axis_refs():
        if ref.chain == chain_name and not ref.axis.locked:
            out[f"{ref.joint.split('_', 1)[1]}.{ref.axis.name}"] = (ref.axis.min_deg,
                                                                    ref.axis.max_deg)
    return out


def test_shipped_file_is_what_the_tool_builds(tool, fly):
    assert fly == tool.build_body(), "run python tools/make_fly_chain.py"


def test_one_chain_per_leg_with_a_fixed_root_at_the_thorax_coxa_joint(fly):
    assert [c.name for c in fly.chains] == [f"{s}{p}_leg" for s in "lr" for p in "fmh"]
    assert all(c.root.mode == "fixed" for c in fly.chains)
    assert len(fly.marker_names) == 30 and int((~fly.locked_mask()).sum()) == 42
    rng = np.random.default_rng(3)
    lo, hi = fly.ranges_deg().T
    pose = forward_kinematics(fly, rng.uniform(lo, hi, (10, fly.n_axes)))
    thc = [fly.marker_names.index(f"{c.name[:2].upper()}_ThC_mk") for c in fly.chains]
    np.testing.assert_allclose(pose.markers[:, thc],
                               np.broadcast_to(fly.root_positions(), (10, 6, 3)), atol=1e-12)


def test_left_legs_mirror_the_right_legs(fly):
    for pos in "fmh":
        left, right = fly.chains["fmh".index(pos)], fly.chains[3 + "fmh".index(pos)]
        np.testing.assert_allclose(left.root.position, np.array(right.root.position) * [1, 1, -1])
        lr, rr = leg_ranges(fly, left.name), leg_ranges(fly, right.name)
        for axis, (lo, hi) in rr.items():
            mirrored = axis in ("ThC.roll", "ThC.yaw", "CTr.roll")  # rotations about y, x
            assert lr[axis] == ((-hi, -lo) if mirrored else (lo, hi)), (pos, axis)


def test_ranges_cover_the_measured_fly_movement_with_the_margin(tool, fly):
    """Issue 10 item 5: the angles of the real flygym clip are inside every range, 10 deg from
    its limits (the measurement is in the tool; bench/bench_fly.py --measure-ranges)."""
    assert tool.MARGIN_DEG >= 10
    for side_pos, chain in zip(("LF", "LM", "LH", "RF", "RM", "RH"), fly.chains, strict=True):
        side, pos = side_pos
        ranges = leg_ranges(fly, chain.name)
        assert set(ranges) == set(tool.AXES)
        for axis, (m_lo, m_hi) in tool.MEASURED[pos].items():
            if side == "L" and axis in tool.MIRRORED:
                m_lo, m_hi = -m_hi, -m_lo
            lo, hi = ranges[axis]
            assert lo <= m_lo - tool.MARGIN_DEG and m_hi + tool.MARGIN_DEG <= hi, (
                side_pos, axis, (lo, hi), (m_lo, m_hi))
            # and no range got narrower than the earlier generic ones
            g_lo, g_hi = tool.GENERIC[pos][axis]
            if side == "L" and axis in tool.MIRRORED:
                g_lo, g_hi = -g_hi, -g_lo
            assert lo <= g_lo and g_hi <= hi


def test_covering_rounds_outward_and_writes_no_negative_zero(tool):
    assert tool.covering((-11.5, -1.5), (-20.0, -5.0)) == (-25.0, 10.0)
    lo, hi = tool.covering((-136.3, -11.5), (-170.0, 0.0))
    assert (lo, hi) == (-170.0, 0.0) and str(hi) == "0.0"
    assert 'max="-0"' not in FLY.read_text()
