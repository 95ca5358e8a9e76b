"""Chain files: loading, lossless saving, located errors, and the examples of docs/formats.md."""

from __future__ import annotations

import os
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from kinematics.errors import KinematicsError
from kinematics.model import Axis, Body, Chain, Joint, Marker, Root, Segment
from kinematics.model.chain_xml import body_to_string, load_body, loads_body, save_body
from kinematics.model.histogram_xml import loads_archive
from kinematics.model.histograms import Histogram

REPO = Path(__file__).resolve().parents[2]
CHAIN_FILES = sorted((REPO / "chains").glob("*.xml"))
LOCUST_TEXT = (REPO / "chains" / "locust_hindleg.xml").read_text()


def test_bundled_locust_file_is_the_paper_chain(locust):
    assert load_body(REPO / "chains" / "locust_hindleg.xml") == locust


def test_axes_without_histogram_entry_get_the_initial_histograms():
    body = loads_body(LOCUST_TEXT)
    axes = {r.label: r.axis for r in body.axis_refs()}
    assert axes["J0.phi"].histogram == Histogram.uniform(120, 220)
    assert axes["J1.ry"].histogram == Histogram.locked(0)
    assert axes["J1.ry"].locked and axes["J1.ry"].min_deg == axes["J1.ry"].max_deg == 0


@pytest.mark.parametrize("path", CHAIN_FILES, ids=lambda p: p.name)
def test_bundled_chains_round_trip(path, tmp_path):
    body = load_body(path)
    out = tmp_path / path.name
    save_body(out, body)
    assert load_body(out) == body
    assert body_to_string(load_body(out)) == out.read_text()  # saving is idempotent


def awkward_body() -> Body:
    """Every feature, with numbers that only survive an exact writer."""
    rng = np.random.default_rng(7)
    learned = Histogram.uniform(-40, 40).updated(rng.uniform(-40, 40, 50))
    coarse = Histogram(rng.random(7) * (rng.random(7) > 0.3) + np.eye(7)[3], n_trials=12)
    hinge = (Axis.fixed("ry", "y"), Axis.fixed("rx", "x", -0.0),
             replace(Axis.free("gamma", "z", 1 / 3, 170.1), histogram=coarse))
    tip = Segment("tibia", 77.25, (0.0, 1e-300, -0.1),
                  markers=(Marker("M3", (0.1, 0.2, 0.30000000000000004)),))
    j1 = Joint("J1", hinge, (0.0, 0.0, 180.0), (1e20, -2.5, 0.0), (tip,))
    j0 = Joint("J0", (replace(Axis.free("phi", "y", -40, 40), histogram=learned),
                      Axis("psi", "x", -10.0, 10.0, Histogram.locked(2.5), locked_deg=2.5),
                      Axis.free("alpha", "z", 120, 220)),
               segments=(Segment("coxa", 13, markers=(Marker("M0", (-13.0, 0, 0)),),
                                 joints=(j1,)),
                         Segment("spur", 0.0)))
    antenna = Joint("A0", (Axis.free("a", "y", -180, 180), Axis.fixed("b", "x"),
                           Axis.fixed("c", "z", 45)), segments=(Segment("flag", 8.0, markers=(
                               Marker("A1"),)),))
    return Body("awkward body", (
        Chain("leg", j0, Root("marker", (0.1, -7e-5, 3.0), "M0")),
        Chain("antenna", antenna, Root("fixed", (3.0, 1.0, 0.0))),
    ), units="mm")


def test_saved_body_loads_back_equal_and_bit_exact(tmp_path):
    body = awkward_body()
    path = tmp_path / "awkward.xml"
    save_body(path, body)
    loaded = load_body(path)
    assert loaded == body
    for a, b in zip(loaded.histograms(), body.histograms(), strict=True):
        assert a.values.tobytes() == b.values.tobytes() and a.n_trials == b.n_trials
    assert [f for f in os.listdir(tmp_path) if f != "awkward.xml"] == []  # no temp files left


def test_saved_file_is_readable():
    text = body_to_string(awkward_body())
    assert 'length="13"' in text and 'length="77.25"' in text  # ints without ".0"
    assert 'offset="0.1 0.2 0.30000000000000004"' in text  # repr where needed
    assert '<axis rot="x" name="psi" min="-10" max="10" locked="2.5"/>' in text
    assert '<axis rot="y" name="ry" locked="0"/>' in text
    assert '<segment name="spur" length="0"/>' in text
    assert re.search(r'\n {6}<segment name="coxa"', text)  # pretty-printed, 2 spaces a level
    names = re.findall(r'<(?:joint|segment|marker) name="([^"]+)"', text)
    assert names == ["J0", "coxa", "M0", "J1", "tibia", "M3", "spur", "A0", "flag", "A1"]
    # Only histograms that differ from the initial ones are written.
    keys = re.findall(r'<histogram chain="(\w+)" joint="(\w+)" axis="(\w+)"', text)
    assert keys == [("leg", "J0", "phi"), ("leg", "J1", "gamma")]
    assert 'bins="7" trials="12"' in text


def test_fresh_chain_saves_without_histograms_section():
    assert "<histograms>" not in body_to_string(loads_body(LOCUST_TEXT))


def test_include_histograms_false_leaves_them_out():
    body = awkward_body()
    text = body_to_string(body, include_histograms=False)
    assert "<histogram" not in text
    loaded = loads_body(text)
    assert loaded != body and loaded.axis_labels == body.axis_labels


def test_unsavable_body_leaves_the_file_untouched(tmp_path):
    path = tmp_path / "leg.xml"
    path.write_text("old")
    bad = awkward_body()
    bad = replace(bad, chains=(replace(bad.chains[0], name="left leg"), *bad.chains[1:]))
    with pytest.raises(KinematicsError) as info:
        save_body(path, bad)
    assert str(info.value).startswith(f"{path}: cannot save body:")
    assert "left leg" in str(info.value)
    assert path.read_text() == "old" and os.listdir(tmp_path) == ["leg.xml"]


def test_histogram_section_sets_histograms():
    text = LOCUST_TEXT.replace("</body>", """  <histograms>
    <histogram chain="hindleg" joint="J1" axis="beta" trials="4">
      <run from="0" to="10" value="2"/>
      <run from="10" to="20" value="6"/>
    </histogram>
    <histogram chain="hindleg" joint="J1" axis="ry" bins="4"><run from="-90" to="0" value="1"/>
    </histogram>
  </histograms>
</body>""")
    axes = {r.label: r.axis for r in loads_body(text).axis_refs()}
    beta = axes["J1.beta"].histogram
    assert beta.n_trials == 4
    assert np.array_equal(beta.values[180:190], np.full(10, 0.025))
    assert np.array_equal(beta.values[190:200], np.full(10, 0.075))
    assert beta.values.sum() == pytest.approx(1.0)
    assert axes["J1.ry"].histogram == Histogram(np.array([0.0, 1.0, 0.0, 0.0]))
    assert axes["J0.phi"].histogram == Histogram.uniform(120, 220)


# -- located errors -----------------------------------------------------------------------------
HIST = ('  <histograms>\n    <histogram chain="{}" joint="{}" axis="{}">'
        '<run from="0" to="10" value="1"/></histogram>\n  </histograms>\n</body>')
EXTRA_CHAIN = ('</chain>\n  <chain name="hindleg"><joint name="Q"><axis rot="y" name="a" '
               'locked="0"/><axis rot="x" name="b" locked="0"/><axis rot="z" name="c" '
               'locked="0"/></joint></chain>')

# name: (replace this, with that, the error's line is the one holding this, words in the message)
BROKEN = {
    "non-numeric": ('min="120"', 'min="abc"', 'min="abc"', "'abc' is not a number"),
    "nan": ('min="120"', 'min="NaN"', "NaN", "'NaN' is not a finite number"),
    "inf": ('max="220"', 'max="INF"', "INF", "'INF' is not a finite number"),
    "-inf locked": ('locked="0"', 'locked="-INF"', "INF", "not a finite number"),
    "overflow": ('length="91"', 'length="1e400"', "1e400", "'1e400' is not a finite number"),
    "huge": ('length="91"', 'length="1e308"', "1e308", "length 1e+308 is out of range"),
    "nan vector": ('orientation="0 0 180"', 'orientation="0 NaN 180"', "NaN", "finite"),
    "vector too short": ('position="0 0 0"', 'position="0 0"', "<root", "has 2 numbers, needs 3"),
    "min > max": ('min="-30" max="60"', 'min="60" max="-30"', 'min="60"', "greater than max"),
    "locked outside range": ('name="beta" min="-30" max="60"',
                             'name="beta" min="-30" max="60" locked="70"', 'locked="70"',
                             "outside"),
    "range over 360": ('min="120" max="220"', 'min="-200" max="200"', 'min="-200"',
                       "wider than 360"),
    "min without max": ('min="-40" max="40"', 'min="-40"', 'name="psi"', "both min and max"),
    "no range": ('rot="z" name="alpha" min="-10" max="10"', 'rot="z" name="alpha"', 'name="alpha"',
                 "needs min and max, or locked"),
    "duplicate joint": ('<joint name="J2"', '<joint name="J1"', 'name="J1" orient',
                        "duplicate joint name 'J1'"),
    "duplicate marker": ('name="M2" offset="0 0 0"', 'name="M1" offset="0 0 0.0"', "0 0 0.0",
                         "duplicate marker name 'M1'"),
    "duplicate axis": ('name="beta"', 'name="ry"', 'rot="z" name="ry"', "duplicate axis names"),
    "duplicate segment": ('name="tibia"', 'name="coxa"', 'name="coxa" length="77"',
                          "duplicate segment name"),
    "duplicate chain": ("</chain>", EXTRA_CHAIN, 'name="Q"', "duplicate chain name"),
    "root marker unknown": ('<root mode="fixed" position="0 0 0"/>',
                            '<root mode="marker" marker="M9"/>', "<root", "'M9' is not a marker"),
    "root marker missing": ('<root mode="fixed" position="0 0 0"/>', '<root mode="marker"/>',
                            "<root", "needs the attribute 'marker'"),
    "axis order": ('rot="y" name="phi"', 'rot="x" name="phi"', '<joint name="J0"',
                   "rotations y, x, z"),
    "negative length": ('length="13"', 'length="-13"', 'length="-13"',
                        "length must be finite and >= 0"),
    "bad rotation": ('rot="z" name="gamma"', 'rot="w" name="gamma"', 'rot="w"',
                     "'w' is not one of"),
    "bad units": ('units="px"', 'units="cm"', "<body", "'cm' is not one of 'px', 'mm'"),
    "name with space": ('name="J1"', 'name="J 1"', "J 1", "not a valid name"),
    "empty name": ('name="M3"', 'name=""', 'name=""', "not a valid name"),
    "unknown attribute": ('<joint name="J0">', '<joint name="J0" speed="3">', "speed",
                          "attribute 'speed' is not allowed"),
    "unknown element": ('<marker name="M3"', '<mark name="M3"', "<mark ", "not allowed here"),
    "missing axis": ('<axis rot="z" name="gamma" min="20" max="160"/>', "", 'name="tibia"',
                     "expected: axis"),
    "histogram for unknown joint": ("</body>", HIST.format("hindleg", "J9", "phi"), "J9",
                                    "not an axis of body"),
    "histogram for unknown chain": ("</body>", HIST.format("foreleg", "J0", "phi"), "foreleg",
                                    "chain 'foreleg' joint 'J0' axis 'phi': not an axis"),
    "histogram for unknown axis": ("</body>", HIST.format("hindleg", "J0", "theta"), "theta",
                                   "not an axis"),
    "format version": ('format="1"', 'format="2"', "<body", "'2' is not one of '1'"),
}


@pytest.mark.parametrize("case", BROKEN, ids=list(BROKEN))
def test_broken_chain_names_file_line_and_element(case):
    old, new, anchor, words = BROKEN[case]
    assert old in LOCUST_TEXT
    text = LOCUST_TEXT.replace(old, new, 1)
    assert text.count(anchor) == 1
    line = text[: text.index(anchor)].count("\n") + 1
    with pytest.raises(KinematicsError) as info:
        loads_body(text, source="legs.xml")
    msg = str(info.value)
    assert msg.startswith(f"legs.xml:{line}: "), msg
    assert words in msg and "\n" not in msg


def test_error_from_a_file_names_the_path(tmp_path):
    path = tmp_path / "legs.xml"
    text = LOCUST_TEXT.replace('min="-30" max="60"', 'min="60" max="-30"')
    path.write_text(text)
    line = text[: text.index('min="60"')].count("\n") + 1
    with pytest.raises(KinematicsError) as info:
        load_body(path)
    assert str(info.value) == (f"{path}:{line}: joint 'J1' axis 'beta': range min 60 is "
                               "greater than max -30")


# -- docs/formats.md --------------------------------------------------------------------------
def test_every_xml_example_in_the_format_docs_loads():
    blocks = re.findall(r"```xml\n(.*?)```", (REPO / "docs" / "formats.md").read_text(), re.S)
    assert len(blocks) >= 3
    kinds = []
    for i, text in enumerate(blocks):
        source = f"formats.md example {i + 1}"
        if "<histogram-archive" in text:
            archive = loads_archive(text, source)
            assert len(archive) > 0
            kinds.append("archive")
        else:
            body = loads_body(text, source)
            assert loads_body(body_to_string(body)) == body
            kinds.append("body")
    assert {"archive", "body"} <= set(kinds)


def test_description_survives_save_and_load(tmp_path, locust):
    import dataclasses

    from kinematics.model.chain_xml import load_body, save_body

    body = dataclasses.replace(locust, description="Lengths from Fig. 5 & the <paper>.")
    save_body(tmp_path / "c.xml", body)
    assert load_body(tmp_path / "c.xml") == body
