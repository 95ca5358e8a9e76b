"""Validation where chain files and histograms are read (issue 16): histogram values within
bounds, histograms with mass inside their axis's range, and nesting limits stated in joints."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from kinematics.errors import KinematicsError
from kinematics.model import Root, safe_xml, validate_body
from kinematics.model.chain_xml import body_to_string, load_body, loads_body, save_body
from kinematics.model.histogram_xml import (
    HistogramArchive,
    apply_archive,
    load_archive,
    loads_archive,
)
from kinematics.model.histograms import MAX_BIN_VALUE, Histogram

BETA = ("hindleg", "J1", "beta")


def spine(n: int) -> str:
    """A chain file of ``n`` nested joints, one marker each (a spine)."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<body name="spine" units="mm" format="1">', '  <chain name="spine">']
    for k in range(n):
        lines.append(f'<joint name="V{k}"><axis rot="y" name="ry" locked="0"/>'
                     f'<axis rot="x" name="rx" locked="0"/>'
                     f'<axis rot="z" name="flex" min="-10" max="10"/>')
        lines.append(f'<segment name="S{k}" length="1"><marker name="M{k}"/>')
    lines += ["</segment></joint>"] * n + ["  </chain>", "</body>", ""]
    return "\n".join(lines)


def with_section(body_text: str, runs: str, joint="J1", axis="beta") -> str:
    return body_text.replace("</body>", f"""  <histograms>
    <histogram chain="hindleg" joint="{joint}" axis="{axis}" trials="3">
      {runs}
    </histogram>
  </histograms>
</body>""")


# -- values --------------------------------------------------------------------------------------
def test_huge_bin_values_are_refused_without_a_numpy_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "overflow encountered in reduce" would raise
        with pytest.raises(KinematicsError, match=r"bin value 1e\+308 is too large"):
            Histogram(np.full(360, 1e308))
        counts = Histogram(np.r_[np.full(180, MAX_BIN_VALUE), np.zeros(180)])
    assert counts.values.sum() == pytest.approx(1.0)


def test_huge_run_value_in_a_file_names_the_line(locust):
    text = with_section(body_to_string(locust), '<run from="-30" to="60" value="1e308"/>')
    with pytest.raises(KinematicsError) as info:
        loads_body(text, "legs.xml")
    assert str(info.value).startswith("legs.xml:")
    assert "histogram chain 'hindleg' joint 'J1' axis 'beta': run value 1e+308 is too large" \
        in str(info.value)
    archive = ('<histogram-archive format="1">\n<histogram chain="c" joint="j" axis="a">\n'
               '<run from="0" to="10" value="2e12"/>\n</histogram>\n</histogram-archive>\n')
    with pytest.raises(KinematicsError, match=r"^a\.xml:3: .*run value 2000000000000\.0 is too"):
        loads_archive(archive, "a.xml")


# -- mass inside the range -----------------------------------------------------------------------
@pytest.mark.parametrize("lo, hi, expected", [
    (120, 220, 1.0), (170, 200, 0.31), (-180, -160, 0.21), (100, 120, 0.01), (220, 230, 0.0),
    (221, 300, 0.0), (-100, 100, 0.0), (0, 360, 1.0), (-150, -150, 0.01), (119.5, 119.5, 0.0),
    (119.5, 120, 0.01),
])
def test_mass_in_range(lo, hi, expected):
    # bins [120, 121) ... [219, 220), wrapping through ±180; a bin counts when it holds an
    # angle of the closed range (so [170, 200] reaches 31 bins)
    h = Histogram.uniform(120, 220)
    assert h.mass_in_range(lo, hi) == pytest.approx(expected)


def test_histogram_outside_the_range_is_refused_where_it_is_read(locust, tmp_path):
    text = with_section(body_to_string(locust), '<run from="90" to="120" value="1"/>')
    with pytest.raises(KinematicsError) as info:
        loads_body(text, "legs.xml")
    msg = str(info.value)
    line = text.splitlines().index('    <histogram chain="hindleg" joint="J1" axis="beta" '
                                   'trials="3">') + 1
    assert msg.startswith(f"legs.xml:{line}: histogram chain 'hindleg' joint 'J1' axis 'beta': "
                          "histogram lies entirely outside the axis range [-30, 60] deg")
    assert "[90, 120]" in msg and "every frame would fail" in msg
    # touching the range is enough: the bin [60, 61) holds the angle 60
    loads_body(with_section(body_to_string(locust), '<run from="60" to="70" value="1"/>'))

    outside = Histogram(np.r_[np.zeros(270), np.ones(30), np.zeros(60)])  # 90..120
    path = tmp_path / "learned.xml"
    from kinematics.model.histogram_xml import save_archive

    save_archive(path, HistogramArchive({BETA: outside}))
    with pytest.raises(KinematicsError, match=rf"^{path}: chain 'hindleg' joint 'J1' axis "
                                              r"'beta': histogram lies entirely outside"):
        apply_archive(locust, load_archive(path))
    with pytest.raises(KinematicsError, match="entirely outside"):  # the fit's own check
        validate_body(locust.with_histograms({"J1.beta": outside}))


def test_locked_axes_and_free_roots_are_not_judged(locust):
    far = Histogram(np.r_[np.zeros(10), np.ones(1), np.zeros(349)])  # -170 only
    validate_body(locust.with_histograms({"J1.rx": far}))  # locked at 0
    chain = locust.chains[0]
    free = replace(locust, chains=(replace(chain, root=Root("free")),))
    validate_body(free.with_histograms({"J0.psi": far}))  # searched around a seed instead


# -- nesting limits, in joints -------------------------------------------------------------------
def test_a_60_joint_spine_loads_and_saves(tmp_path):
    body = loads_body(spine(60))
    assert len(body.joint_names) == 60
    save_body(tmp_path / "spine.xml", body)
    assert load_body(tmp_path / "spine.xml") == body
    loads_body(spine(safe_xml.MAX_JOINT_DEPTH))


@pytest.mark.parametrize("n", [safe_xml.MAX_JOINT_DEPTH + 1, 300])
def test_too_deep_a_chain_is_refused_in_joints(n):
    with pytest.raises(KinematicsError) as info:
        loads_body(spine(n), "spine.xml")
    msg = str(info.value)
    assert msg.startswith("spine.xml:") and "\n" not in msg
    assert f"a chain may nest at most {safe_xml.MAX_JOINT_DEPTH} joints" in msg
    if n == safe_xml.MAX_JOINT_DEPTH + 1:
        assert f"this line is {n} joints down" in msg


def test_deep_archive_is_refused_in_levels():
    doc = '<histogram-archive format="1">' + "<a>" * 300 + "</a>" * 300 + "</histogram-archive>"
    with pytest.raises(KinematicsError, match=r"nested too deeply \(more than \d+ levels\)"):
        loads_archive(doc)
