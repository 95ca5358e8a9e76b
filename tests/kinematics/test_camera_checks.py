"""Cameras that look wrong are named: two identical cameras, one whose errors stand out."""

from __future__ import annotations

import numpy as np

from kinematics.cameras import PinholeCamera
from kinematics.cameras.checks import camera_warnings, identical_cameras, outlying_cameras
from tests.fixtures.cameras import three_pinholes


def test_a_copied_camera_is_named():
    a, b, c = three_pinholes()
    copy = PinholeCamera("side", c.K, c.dist, R=c.R, t=c.t, size=c.image_size)
    cams = {a.name: a, b.name: b, c.name: c, "side": copy}
    assert identical_cameras(cams) == [(c.name, "side")]
    assert identical_cameras([a, b, c]) == []
    moved = PinholeCamera("side", c.K, c.dist, R=c.R, t=c.t + np.array([0.0, 0.0, 1e-3]),
                          size=c.image_size)
    assert identical_cameras([a, b, c, moved]) == []  # 1 µm apart is another camera
    (line,) = camera_warnings(cams)
    assert f"cameras {c.name} and side are identical" in line


def test_a_camera_whose_errors_stand_out_is_named():
    assert outlying_cameras({"back": 2.6, "mid": 3.7, "side": 83.9, "top": 10.8}) == ["side"]
    assert outlying_cameras({"a": 1.0, "b": 2.9, "c": 1.1}) == []  # under 2 px: noise
    assert outlying_cameras({"a": 0.4, "b": 0.5, "c": 1.9}) == []
    (line,) = camera_warnings([], {"back": 2.6, "mid": 3.7, "side": 83.9, "top": 10.8})
    assert line.startswith("camera side reprojects with a median error of 83.9 px")
    (line,) = camera_warnings([], {"a": 0.0, "b": 0.0, "c": 5.0})  # others exact
    assert "5.0 px, above the other cameras' (0.0 px)" in line
