"""``videotrack chain show`` and ``videotrack chain check``."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from videotrack.cli import main

REPO = Path(__file__).resolve().parents[2]
LOCUST = REPO / "chains" / "locust_hindleg.xml"


def test_show_prints_the_tree(capsys):
    assert main(["chain", "show", str(LOCUST)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("body locust-hindleg  [units: px; 1 chain, 3 joints, 5 free axes, "
                          "4 markers]")
    assert "chain hindleg: root fixed at (0, 0, 0) px" in out
    assert re.search(r"axis phi +\(rot y\)  range \[120, 220\] deg  H: 170\.0 ± 28\.9 deg, N=1",
                     out)
    assert re.search(r"axis gamma \(rot z\)  range \[20, 160\] deg", out)
    assert re.search(r"axis ry +\(rot y\)  locked at 0 deg", out)
    assert "joint J2: orientation (0, 0, 180) deg" in out
    assert "segment femur: length 91 px, rotation (0, 0, 0) deg" in out
    assert "marker M0 at (-13, 0, 0) px" in out and "marker M3 at (0, 0, 0) px" in out
    # Nesting is visible: J1 is indented deeper than J0, M3 deeper than M0.
    indent = {m[2]: len(m[1]) for m in re.finditer(r"^( *)(?:joint|marker) (\w+)", out, re.M)}
    assert indent["J0"] < indent["J1"] < indent["J2"] and indent["M0"] < indent["M3"]


def test_show_marker_root_and_locked_axis_with_range(tmp_path, capsys):
    text = LOCUST.read_text().replace(
        '<root mode="fixed" position="0 0 0"/>', '<root mode="marker" position="1 2 3" '
        'marker="M0"/>').replace('name="psi" min="-40" max="40"',
                                 'name="psi" min="-40" max="40" locked="5"')
    path = tmp_path / "leg.xml"
    path.write_text(text)
    assert main(["chain", "show", str(path)]) == 0
    out = capsys.readouterr().out
    assert "chain hindleg: root marker M0, followed from near (1, 2, 3) px in the first frame" \
        in out
    assert "root placement" not in out and "root windows" not in out
    assert "axis psi   (rot x)  locked at 5 deg (range [-40, 40])" in out


FREE_ROOT = """<?xml version="1.0"?>
<body name="mouse" units="mm" format="1">
  <chain name="hindlimb">
    <root mode="free" position="1 2 3" marker="hipR"{windows}/>
    <joint name="body">
      <axis rot="y" name="yaw" min="-180" max="180"/>
      <axis rot="x" name="pitch" min="-90" max="90"/>
      <axis rot="z" name="roll" min="-180" max="180"/>
      <segment name="pelvis" length="0">
        <marker name="hipL" offset="0 0 -8"/>
        <marker name="hipR" offset="0 0 8"/>
        {more}
        <joint name="hip">
          <axis rot="y" name="ry" locked="0"/>
          <axis rot="x" name="rx" locked="0"/>
          <axis rot="z" name="flex" min="-120" max="0"/>
          <segment name="femur" length="20"><marker name="knee"/></segment>
        </joint>
      </segment>
    </joint>
  </chain>
</body>
"""


def test_show_free_root_with_default_windows(tmp_path, capsys):
    from kinematics.fit.placement import root_windows
    from kinematics.model.chain_xml import load_body

    path = tmp_path / "mouse.xml"
    path.write_text(FREE_ROOT.format(windows="", more='<marker name="tail" offset="-22 2 0"/>'))
    assert main(["chain", "show", str(path)]) == 0
    out = capsys.readouterr().out.splitlines()
    w_t, w_r = root_windows(load_body(path))[0]
    assert out[1] == ("chain hindlimb: root free (position and orientation fitted per frame), "
                      "position hint (1, 2, 3) mm")
    # the markers of the root joint's segments place the root; the knee marker does not
    assert out[2] == "  root placement: registered on markers hipL, hipR, tail"
    assert out[3] == (f"  root windows: translation ±{w_t:.4g} mm (default), "
                      f"rotation ±{w_r:.4g} deg (default)")
    assert w_r == 20.0 and out[4].startswith("  joint body:")


def test_show_free_root_with_set_windows_and_two_markers(tmp_path, capsys):
    path = tmp_path / "mouse.xml"
    path.write_text(FREE_ROOT.format(
        windows=' translation_window="2.5" rotation_window_deg="300"', more=""))
    assert main(["chain", "show", str(path)]) == 0
    out = capsys.readouterr().out
    # two root markers seed only the position, from the named root marker
    assert ("  root placement: position from marker hipR; orientation not seeded (root "
            "markers hipL, hipR: fewer than three non-collinear)") in out
    assert "  root windows: translation ±2.5 mm (set), rotation ±180 deg (set 300, capped)" \
        in out


def test_check_ok(capsys):
    assert main(["chain", "check", str(LOCUST)]) == 0
    assert capsys.readouterr().out == (
        f"{LOCUST}: ok (1 chain, 3 joints, 5 free axes, 4 markers)\n")


def test_check_reports_every_file_and_exits_1(tmp_path, capsys):
    broken = tmp_path / "broken.xml"
    text = LOCUST.read_text()
    broken.write_text(text.replace('min="-30" max="60"', 'min="60" max="-30"'))
    line = text[: text.index('min="-30"')].count("\n") + 1
    truncated = tmp_path / "cut.xml"
    truncated.write_text(text[: len(text) // 2])
    assert main(["chain", "check", str(broken), str(LOCUST), str(truncated)]) == 1
    captured = capsys.readouterr()
    assert f"{LOCUST}: ok" in captured.out
    errors = captured.err.splitlines()
    assert errors[0] == (f"{broken}:{line}: joint 'J1' axis 'beta': range min 60 is greater "
                         "than max -30")
    assert re.match(rf"{re.escape(str(truncated))}:\d+: .*truncated", errors[1])
    assert len(errors) == 2 and "Traceback" not in captured.err


def test_show_of_a_broken_file_is_one_line(tmp_path, capsys):
    path = tmp_path / "evil.xml"
    path.write_text('<!DOCTYPE body [<!ENTITY x SYSTEM "file:///etc/passwd">]><body/>')
    assert main(["chain", "show", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"videotrack: error: {path}:1: ") and err.count("\n") == 1
    assert "Traceback" not in err and "root:" not in err


@pytest.mark.parametrize("argv", [["chain", "--help"], ["chain", "show", "--help"],
                                  ["chain", "check", "--help"]])
def test_help_teaches_with_examples(argv, capsys):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "videotrack chain" in out and "example" in out and "chains/" in out
