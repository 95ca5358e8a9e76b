"""Camera files: the documented example, exact round trips, located errors, imports."""

import os
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinematics.cameras import OrthographicCamera, PinholeCamera
from kinematics.cameras.files import (
    camera_from_table,
    camera_to_table,
    import_anipose_toml,
    import_opencv_yaml,
    load_camera_file,
    load_cameras,
    save_cameras,
)
from kinematics.errors import KinematicsError, LocatedError

REPO = Path(__file__).resolve().parents[2]
SHARED_DATA = REPO.parent / "shared" / "data"

K = [[1850.5, 0.0, 719.5], [0.0, 1850.5, 539.5], [0.0, 0.0, 1.0]]


def toml_blocks(markdown: Path) -> list[str]:
    return re.findall(r"^```toml\n(.*?)^```", markdown.read_text(encoding="utf-8"), re.M | re.S)


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


# --- the documented example -----------------------------------------------------------------


def test_docs_example_loads(tmp_path):
    (block,) = toml_blocks(REPO / "docs" / "cameras.md")
    loaded = load_camera_file(write(tmp_path / "cameras.toml", block))
    cams = loaded.cameras
    assert loaded.units == "mm" and list(cams) == ["side", "top", "front", "overhead"]
    np.testing.assert_array_equal(cams["side"].project([0.0, 0.0, 0.0]), [360.0, 430.0])
    np.testing.assert_array_equal(cams["side"].project([0.0, 1.0, 0.0]), [360.0, 430.0 - 2.86])
    np.testing.assert_array_equal(cams["top"].project([1.0, 0.0, 2.0]), [363.0, 156.0])
    front = OrthographicCamera.from_axes("front", 3.0, ("-z", "-y"), (360.0, 430.0))
    np.testing.assert_array_equal(cams["front"].P, front.P)  # as the comment says
    overhead = cams["overhead"]
    np.testing.assert_allclose(overhead.centre, [0.0, 400.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(overhead.view_direction, [0.0, -1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(overhead.project([0.0, 0.0, 0.0]), [719.5, 539.5], atol=1e-9)
    # image u = world x, image v = world z, as the comment says
    u, v = overhead.project([[10.0, 0.0, 0.0], [0.0, 0.0, 10.0]]) - [719.5, 539.5]
    assert u[0] > 0 and abs(u[1]) < 1e-9 and v[1] > 0 and abs(v[0]) < 1e-9


def test_save_load_round_trip_keeps_forms(tmp_path):
    (block,) = toml_blocks(REPO / "docs" / "cameras.md")
    cams = load_cameras(write(tmp_path / "in.toml", block))
    out = tmp_path / "out.toml"
    save_cameras(out, cams, units="mm")
    again = load_camera_file(out)
    assert again.units == "mm" and again.cameras == cams
    text = out.read_text()
    assert 'axes = ["x", "-y"]' in text and "matrix = [" in text and "rvec = " in text
    assert "dist = [-0.19, 0.02, 0.0, 0.0]\n" in text  # trailing zero k3 dropped
    save_cameras(tmp_path / "again.toml", list(again.cameras.values()), units="mm")
    assert (tmp_path / "again.toml").read_text() == text
    assert camera_from_table("x", camera_to_table(cams["overhead"]))


finite = st.floats(-1e6, 1e6, allow_nan=False, allow_subnormal=True)
positive = st.floats(1e-3, 1e6)
names = st.text(st.characters(codec="utf-8", categories=("L", "N", "P", "S", "Zs")),
                min_size=1, max_size=8).filter(lambda s: s.strip() and s.isprintable())


@st.composite
def cameras(draw):
    name = draw(names)
    kind = draw(st.sampled_from(["axes", "matrix", "rvec", "R"]))
    size = draw(st.none() | st.tuples(st.integers(1, 10_000), st.integers(1, 10_000)))
    if kind == "axes":
        axes = draw(st.sampled_from([("x", "-y"), ("+z", "x"), ("-y", "-z")]))
        return OrthographicCamera.from_axes(name, draw(positive), axes,
                                            draw(st.tuples(finite, finite)), size=size)
    if kind == "matrix":
        P = [[draw(positive), 0.0, draw(finite), draw(finite)],
             [0.0, draw(positive), draw(finite), draw(finite)]]
        return OrthographicCamera(name, P, size=size)
    k = [[draw(positive), 0.0, draw(finite)], [0.0, draw(positive), draw(finite)], [0, 0, 1]]
    dist = draw(st.lists(st.floats(-1, 1), min_size=8, max_size=8))[: draw(st.sampled_from(
        [0, 4, 5, 8]))]
    rvec = draw(st.lists(st.floats(-3, 3), min_size=3, max_size=3))
    t = draw(st.lists(finite, min_size=3, max_size=3))
    if kind == "rvec":
        return PinholeCamera(name, k, dist, t=t, size=size, rvec=rvec)
    return PinholeCamera(name, k, dist, cv2.Rodrigues(np.array(rvec))[0], t, size)


@settings(max_examples=60, deadline=None)
@given(st.lists(cameras(), min_size=1, max_size=4, unique_by=lambda c: c.name),
       st.sampled_from([None, "px", "mm"]))
def test_round_trip_is_exact(tmp_path_factory, cams, units):
    path = tmp_path_factory.mktemp("rt") / "cameras.toml"
    save_cameras(path, cams, units=units)
    loaded = load_camera_file(path)
    assert loaded.units == units
    assert list(loaded.cameras) == [c.name for c in cams]
    assert list(loaded.cameras.values()) == cams


def test_save_is_atomic(tmp_path, monkeypatch):
    path = tmp_path / "cameras.toml"
    cam = OrthographicCamera.from_axes("side", 2.0, ("x", "-y"))
    save_cameras(path, [cam])
    before = path.read_text()

    def fail(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(LocatedError, match="disk full") as err:
        save_cameras(path, [OrthographicCamera.from_axes("side", 3.0, ("x", "-y"))])
    assert err.value.file == str(path)
    assert path.read_text() == before and os.listdir(tmp_path) == ["cameras.toml"]


def test_save_rejects(tmp_path):
    cam = OrthographicCamera.from_axes("side", 2.0, ("x", "-y"))
    with pytest.raises(KinematicsError, match="name"):
        save_cameras(tmp_path / "c.toml", {"top": cam})
    with pytest.raises(KinematicsError, match="two cameras"):
        save_cameras(tmp_path / "c.toml", [cam, cam])
    with pytest.raises(KinematicsError, match="units"):
        save_cameras(tmp_path / "c.toml", [cam], units="inch")
    with pytest.raises(KinematicsError, match="no cameras"):
        save_cameras(tmp_path / "c.toml", [])
    with pytest.raises(LocatedError, match="cannot write"):
        save_cameras(tmp_path / "missing" / "c.toml", [cam])
    assert not (tmp_path / "c.toml").exists()


# --- located errors -------------------------------------------------------------------------

SIDE = '[cameras.side]\ntype = "orthographic"\nscale = 2.0\naxes = ["x", "-y"]\n'
PIN = '[cameras.cam]\ntype = "pinhole"\nK = [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0, 0, 1]]\n'


@pytest.mark.parametrize(
    ("text", "line", "field", "message"),
    [
        ('units = "mm"\nframe_rate = 25\n' + SIDE, 2, "frame_rate", "unknown key"),
        ('units = "inch"\n' + SIDE, 1, "units", "px, mm"),
        ('units = "mm"\n', None, "cameras", "at least one"),
        (SIDE + "mirror = true\n", 5, "cameras.side.mirror", "unknown key 'mirror'"),
        (SIDE.replace('type = "orthographic"\n', ""), 1, "cameras.side.type", "missing key"),
        (SIDE.replace("orthographic", "fisheye"), 2, "cameras.side.type", "'fisheye'"),
        (SIDE.replace("scale = 2.0", "scale = nan"), 3, "cameras.side.scale", "finite"),
        (SIDE.replace("scale = 2.0", 'scale = "2"'), 3, "cameras.side.scale", "numbers"),
        (SIDE.replace("scale = 2.0", "scale = 1e308"), 3, "cameras.side.scale",
         "1e+308 is out of range"),
        (PIN.replace("800.0, 0.0, 320.0", "8e300, 0.0, 320.0") + "rvec = [0, 0, 0]\n"
         "t = [0, 0, 1]\n", 3, "cameras.cam.K", "out of range"),
        (SIDE.replace("scale = 2.0\n", ""), 1, "cameras.side.scale", "missing key 'scale'"),
        (SIDE.replace('"-y"', '"up"'), 4, "cameras.side.axes", "signed world axis"),
        (SIDE + "matrix = [[1.0, 0, 0, 0], [0, 1.0, 0, 0]]\n", 3, "cameras.side.scale",
         "either matrix"),
        (SIDE.replace("scale = 2.0\naxes", "matrix = [[1.0, 0, 0]]\nnot").split("not")[0],
         3, "cameras.side.matrix", "shape (2, 4)"),
        (SIDE + "size = [720, true]\n", 5, "cameras.side.size", "numbers"),
        ("[cameras]\nside = 3\n", 2, "cameras.side", "expected a table"),
        (PIN + "t = [0, 0, 1]\n", 1, "cameras.cam.R", "missing key 'R' or 'rvec'"),
        (PIN + "R = [[1, 0, 0], [0, 1, 0], [0, 0, 1.1]]\nt = [0, 0, 1]\n", 4, "cameras.cam.R",
         "orthonormal"),
        (PIN + "rvec = [0, 0, 0]\nt = [0, 0]\n", 5, "cameras.cam.t", "shape (3,)"),
        (PIN + "rvec = [0, 0, 0]\nt = [0, 0, 1]\ndist = [0.1, 0.1]\n", 6, "cameras.cam.dist",
         "0, 4, 5 or 8"),
        (SIDE + "scale = 3.0\n", 5, None, "invalid TOML"),
        (SIDE + "x = " + "[" * 1000 + "]" * 1000 + "\n", 5, None, "nested too deep"),
    ],
)
def test_load_errors_are_located(tmp_path, text, line, field, message):
    path = write(tmp_path / "cameras.toml", text)
    with pytest.raises(KinematicsError, match=re.escape(message)) as err:
        load_cameras(path)
    e = err.value
    assert (e.file, e.line, e.field) == (str(path), line, field)
    prefix = f"{path}:{line}" if line else str(path)
    assert str(e).startswith(prefix + ": " + (f"{field}: " if field else ""))


def test_load_missing_file(tmp_path):
    with pytest.raises(KinematicsError, match="cannot read") as err:
        load_cameras(tmp_path / "nope.toml")
    assert err.value.file == str(tmp_path / "nope.toml")


# --- OpenCV FileStorage ---------------------------------------------------------------------


def write_storage(path: Path, **values) -> Path:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in values.items():
        fs.write(key, value)
    fs.release()
    return path


def assert_projects_like_cv2(cam, rvec, tvec, k, dist, rng):
    pts = cam.centre + cam.view_direction * 100.0 + rng.uniform(-20, 20, (50, 3))
    ref = cv2.projectPoints(pts, np.asarray(rvec, float), np.asarray(tvec, float),
                            np.asarray(k, float), np.asarray(dist, float))[0][:, 0]
    np.testing.assert_allclose(cam.project(pts), ref, rtol=0, atol=1e-9)


def test_opencv_mono_calibration_sample(tmp_path):
    dist = np.array([[-0.28, 0.07, 1e-4, -2e-4, 0.01]])
    path = write_storage(tmp_path / "left.yml", image_width=640, image_height=480,
                         camera_matrix=np.array(K), distortion_coefficients=dist,
                         avg_reprojection_error=0.41)
    (cam,) = import_opencv_yaml(path).values()
    assert cam.name == "left" and cam.image_size == (640, 480)
    np.testing.assert_array_equal(cam.K, K)
    np.testing.assert_array_equal(cam.dist[:5], dist[0])
    np.testing.assert_array_equal(cam.R, np.eye(3))
    assert_projects_like_cv2(cam, np.zeros(3), np.zeros(3), K, dist, np.random.default_rng(0))


@pytest.mark.parametrize(("rows", "data", "says"), [
    (2, "800., 0., 320., 0., 800., 240., 0., 0., 1.", "of 2 x 3 holds 9 numbers"),
    (3, "800., 0., 320., 0., 800.", "of 3 x 3 holds 5 numbers"),
    ("abc", "800., 0., 320., 0., 800., 240., 0., 0., 1.", "of abc x 3 holds 9")])
def test_opencv_matrix_that_does_not_hold_its_data_is_named(tmp_path, rows, data, says):
    # OpenCV asserts on such a matrix ("internal error" before); a located one-line error now
    path = tmp_path / "cam.yml"
    path.write_text(f"%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: "
                    f"!!opencv-matrix\n   rows: {rows}\n   cols: 3\n   dt: d\n"
                    f"   data: [ {data} ]\n")
    with pytest.raises(KinematicsError, match=says) as err:
        import_opencv_yaml(path)
    assert (err.value.file, err.value.field) == (str(path), "camera_matrix")


@pytest.mark.parametrize("pose", ["R", "rvec", "R as Rodrigues"])
def test_opencv_with_pose(tmp_path, pose):
    rvec, tvec = np.array([[0.3], [-0.2], [0.1]]), np.array([[5.0], [-3.0], [400.0]])
    rot = {"R": cv2.Rodrigues(rvec)[0], "rvec": rvec, "R as Rodrigues": rvec}[pose]
    key = "rvec" if pose == "rvec" else "R"
    path = write_storage(tmp_path / "cam.yml", K=np.array(K), D=np.zeros((1, 4)),
                         **{key: rot, "tvec": tvec, "image_size": np.array([1440, 1080])})
    cam = import_opencv_yaml(path, name="c1")["c1"]
    assert cam.image_size == (1440, 1080)
    assert_projects_like_cv2(cam, rvec, tvec, K, np.zeros(4), np.random.default_rng(1))


def test_opencv_stereo(tmp_path):
    rvec, T = np.array([0.05, -0.6, 0.02]), np.array([[-120.0], [1.5], [30.0]])
    R = cv2.Rodrigues(rvec)[0]
    d1, d2 = np.array([[-0.2, 0.05, 0, 0, 0]]), np.array([[-0.25, 0.08, 0, 0, 0.01]])
    k2 = np.array([[1800.0, 0, 700], [0, 1801, 530], [0, 0, 1]])
    one = write_storage(tmp_path / "stereo.yml", M1=np.array(K), D1=d1, M2=k2, D2=d2, R=R, T=T)
    cams = import_opencv_yaml(one, name="rig")
    assert list(cams) == ["rig_1", "rig_2"]
    np.testing.assert_array_equal(cams["rig_1"].t, 0.0)
    np.testing.assert_array_equal(cams["rig_2"].R, R)
    rng = np.random.default_rng(2)
    assert_projects_like_cv2(cams["rig_1"], np.zeros(3), np.zeros(3), K, d1, rng)
    assert_projects_like_cv2(cams["rig_2"], cv2.Rodrigues(R)[0], T, k2, d2, rng)
    # OpenCV's stereo sample: intrinsics.yml + extrinsics.yml
    intr = write_storage(tmp_path / "intrinsics.yml", M1=np.array(K), D1=d1, M2=k2, D2=d2)
    extr = write_storage(tmp_path / "extrinsics.yml", R=R, T=T, R1=np.eye(3))
    assert import_opencv_yaml(intr, "rig", extrinsics=extr) == cams
    with pytest.raises(KinematicsError, match="R") as err:
        import_opencv_yaml(intr)
    assert err.value.file == str(intr)
    bad = write_storage(tmp_path / "bad_extrinsics.yml", R=R * 1.01, T=T)
    with pytest.raises(KinematicsError, match="orthonormal") as err:
        import_opencv_yaml(intr, extrinsics=bad)
    assert (err.value.file, err.value.field) == (str(bad), "R")


def test_opencv_handwritten_yaml_1_0(tmp_path):
    path = write(tmp_path / "calib.yaml", """%YAML:1.0
---
image_width: 640
image_height: 480
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 533.0, 0., 341.6, 0., 533.2, 234.3, 0., 0., 1. ]
dist_coeffs: [ -0.289, 0.1, 0.0, 0.0 ]
""")
    cam = import_opencv_yaml(path, "left")["left"]
    assert cam.image_size == (640, 480) and cam.K[0, 2] == 341.6
    np.testing.assert_array_equal(cam.dist[:4], [-0.289, 0.1, 0.0, 0.0])


ROS_YAML = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [500.0, 0.0, 320.0, 0.0, 501.0, 240.0, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.1, -0.2, 0.0, 0.0, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
"""


def test_ros_camera_info_yaml(tmp_path):
    cam = import_opencv_yaml(write(tmp_path / "ost.yaml", ROS_YAML))["ost"]
    np.testing.assert_array_equal(cam.K, [[500.0, 0.0, 320.0], [0.0, 501.0, 240.0], [0, 0, 1]])
    np.testing.assert_array_equal(cam.dist[:2], [0.1, -0.2])
    assert cam.image_size == (640, 480)
    fisheye = write(tmp_path / "fish.yaml", ROS_YAML.replace("plumb_bob", "equidistant"))
    with pytest.raises(KinematicsError, match="equidistant") as err:
        import_opencv_yaml(fisheye)
    assert err.value.field == "distortion_model"


def test_opencv_errors(tmp_path):
    with pytest.raises(KinematicsError, match="not found"):
        import_opencv_yaml(tmp_path / "nope.yml")
    bad = write(tmp_path / "bad.yml", "%YAML:1.0\nK: [1, 2\n")
    with pytest.raises(KinematicsError, match="cannot parse") as err:
        import_opencv_yaml(bad)
    assert err.value.file == str(bad) and err.value.line == 2
    nok = write_storage(tmp_path / "nok.yml", image_width=640)
    with pytest.raises(KinematicsError, match="none of the keys") as err:
        import_opencv_yaml(nok)
    assert err.value.field == "camera_matrix"
    six = write_storage(tmp_path / "six.yml", cameraMatrix=np.array(K), distCoeffs=np.zeros(6))
    with pytest.raises(KinematicsError, match="0, 4, 5 or 8") as err:
        import_opencv_yaml(six)
    assert (err.value.file, err.value.field) == (str(six), "distCoeffs")


# --- Anipose --------------------------------------------------------------------------------

ANIPOSE = """[cam_0]
name = "A"
size = [ 1440, 1080,]
matrix = [ [ 1852.4, 0.0, 719.5,], [ 0.0, 1852.4, 539.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.036, 0.0, 0.0, 0.0, 0.0,]
rotation = [ -0.0017, -0.0018, -0.0046,]
translation = [ 2.55, -2.77, 1000.0,]

[cam_1]
name = "B"
size = [ 1440, 1080,]
matrix = [ [ 1935.9, 0.0, 719.5,], [ 0.0, 1935.9, 539.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.31, 0.0, 0.0, 0.0, 0.0,]
rotation = [ -0.2257, -2.982, 0.3874,]
translation = [ 117.4, 262.5, 1478.8,]

[metadata]
adjusted = true
error = 1.668
"""


def test_anipose_synthetic(tmp_path):
    path = write(tmp_path / "calibration.toml", ANIPOSE)
    cams = import_anipose_toml(path)
    assert list(cams) == ["A", "B"]
    b = cams["B"]
    assert b.image_size == (1440, 1080)
    np.testing.assert_array_equal(b.rvec, [-0.2257, -2.982, 0.3874])
    assert_projects_like_cv2(b, b.rvec, b.t, b.K, b.dist[:5], np.random.default_rng(3))
    save_cameras(tmp_path / "cameras.toml", cams, units="mm")
    assert load_cameras(tmp_path / "cameras.toml") == cams


@pytest.mark.parametrize(
    ("edit", "line", "field", "message"),
    [
        (("[metadata]", "fisheye = true\n[metadata]"), 17, "cam_1.fisheye", "fisheye"),
        (('name = "B"', 'name = "B"\nlens = 1'), 11, "cam_1.lens", "unknown key 'lens'"),
        (('name = "B"', 'name = "A"'), 10, "cam_1.name", "duplicate"),
        (("distortions = [ -0.31, 0.0, 0.0, 0.0, 0.0,]", "distortions = [ -0.31, 0.0,]"), 13,
         "cam_1.distortions", "0, 4, 5 or 8"),
        (("rotation = [ -0.2257, -2.982, 0.3874,]", ""), 9, "cam_1.rotation", "missing key"),
        (("translation = [ 117.4, 262.5, 1478.8,]", "translation = 5"), 15,
         "cam_1.translation", "shape (3,)"),
    ],
)
def test_anipose_errors(tmp_path, edit, line, field, message):
    path = write(tmp_path / "calibration.toml", ANIPOSE.replace(*edit))
    with pytest.raises(KinematicsError, match=re.escape(message)) as err:
        import_anipose_toml(path)
    assert (err.value.file, err.value.line, err.value.field) == (str(path), line, field)


REAL_CALIBRATIONS = {
    "aniposelib_mouse_calib/calib__7cam-allen-mouse__calibration.toml": 7,
    "aniposelib_mouse_calib/calib__12cam-allen-mouse__calibration.toml": 12,
    "aniposelib_mouse_calib/calib__mouse-outdoor__calibration_right_4_10_2026_adjusted.toml": 12,
    "sleap_anipose_mouse4cam/calibration.toml": 4,
    "fly_5cam_video_kinematics3d/calibration_init.toml": 5,
    "pose2sim_demo/calibration/Calib_qualisys_converted_by_pose2sim.toml": 4,
}


def test_real_aniposelib_files_are_all_covered():
    folder = SHARED_DATA / "aniposelib_mouse_calib"
    if not folder.is_dir():
        pytest.skip(f"{folder} not present")
    found = {f"aniposelib_mouse_calib/{p.name}" for p in folder.glob("*calibration*.toml")}
    assert found and found <= set(REAL_CALIBRATIONS)


@pytest.mark.parametrize(("relpath", "n_cameras"), REAL_CALIBRATIONS.items())
def test_real_anipose_calibrations(tmp_path, relpath, n_cameras):
    path = SHARED_DATA / relpath
    if not path.is_file():
        pytest.skip(f"{path} not present")
    cams = import_anipose_toml(path)
    assert len(cams) == n_cameras
    rng = np.random.default_rng(4)
    for cam in cams.values():
        assert cam.image_size is not None
        distance = np.linalg.norm(cam.t)  # in front, about as far as the world origin
        on_axis = cam.centre + distance * cam.view_direction
        np.testing.assert_allclose(cam.project(on_axis), cam.K[:2, 2], atol=1e-6)
        assert_projects_like_cv2(cam, cam.rvec, cam.t, cam.K, cam.dist, rng)
    save_cameras(tmp_path / "cameras.toml", cams)
    assert load_cameras(tmp_path / "cameras.toml") == cams
