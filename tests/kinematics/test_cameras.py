"""Camera models: Eq. 3 views, OpenCV pinhole == cv2.projectPoints, numba kernels == NumPy."""

import re

import cv2
import numpy as np
import pytest
from numba import njit

from kinematics._kernels.camera import project_point
from kinematics.cameras import (
    CameraArrays,
    OrthographicCamera,
    PinholeCamera,
    describe_camera,
    pack_cameras,
    project_packed,
)
from kinematics.errors import KinematicsError

K = np.array([[800.0, 0.0, 320.0], [0.0, 780.0, 240.0], [0.0, 0.0, 1.0]])


def random_pinhole(rng, n_dist=8, name="cam", use_rvec=True):
    """A camera about 50 units from the origin, looking at it, with mild distortion."""
    rvec = rng.normal(0.0, 1.0, 3)
    t = np.array([*rng.normal(0.0, 2.0, 2), 50.0])
    dist = rng.normal(0.0, 0.05, n_dist)
    if use_rvec:
        return PinholeCamera(name, K, dist, t=t, rvec=rvec, size=(640, 480))
    return PinholeCamera(name, K, dist, cv2.Rodrigues(rvec)[0], t, size=(640, 480))


def random_points(rng, n=500):
    return rng.uniform(-15.0, 15.0, (n, 3))  # all within 35 units of the origin: in front


# --- orthographic ---------------------------------------------------------------------------


def test_eq3_is_axes_x_y():
    cam = OrthographicCamera.from_axes("eq3", 3.0, ("x", "y"))
    np.testing.assert_array_equal(cam.P, [[3.0, 0, 0, 0], [0, 3.0, 0, 0]])
    np.testing.assert_array_equal(cam.project([1.0, 2.0, 5.0]), [3.0, 6.0])


def test_side_and_top_views():
    side = OrthographicCamera.from_axes("side", 2.86, ("x", "-y"), (360.0, 430.0))
    top = OrthographicCamera.from_axes("top", 3.0, ("x", "z"), (360.0, 150.0))
    p = np.array([10.0, 5.0, -2.0])  # anterior, up, to the left
    np.testing.assert_allclose(side.project(p), [360 + 28.6, 430 - 14.3])  # up is -v
    np.testing.assert_allclose(top.project(p), [360 + 30.0, 150 - 6.0])
    np.testing.assert_array_equal(side.view_direction, [0, 0, -1])  # from the right
    np.testing.assert_array_equal(top.view_direction, [0, -1, 0])  # from above
    assert side.axes_form.axes == ("x", "-y") and top.axes_form.scale == 3.0


def test_matrix_form_equals_axes_form_projection():
    front = OrthographicCamera.from_axes("front", 3.0, ("-z", "+y"), (1.0, 2.0))
    same = OrthographicCamera("front", front.P)
    pts = random_points(np.random.default_rng(1))
    np.testing.assert_array_equal(front.project(pts), same.project(pts))
    assert same.axes_form is None and same != front  # the form is part of the camera


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"axes": ("x", "x")}, "axes"),
        ({"axes": ("x", "-x")}, "axes"),
        ({"axes": ("x", "w")}, "axes"),
        ({"axes": ("x",)}, "axes"),
        ({"axes": "xy"}, "axes"),
        ({"scale": 0.0}, "scale"),
        ({"scale": -1.0}, "scale"),
        ({"scale": float("nan")}, "scale"),
        ({"scale": True}, "scale"),
        ({"offset": (0.0, float("inf"))}, "offset"),
        ({"offset": (0.0,)}, "offset"),
        ({"size": (720, 0)}, "size"),
        ({"size": (720.5, 576)}, "size"),
        ({"name": ""}, "name"),
    ],
)
def test_from_axes_rejects(kwargs, field):
    args = {"name": "v", "scale": 1.0, "axes": ("x", "-y"), "offset": (0.0, 0.0)} | kwargs
    with pytest.raises(KinematicsError) as err:
        OrthographicCamera.from_axes(**args)
    assert err.value.field == field


@pytest.mark.parametrize(
    "P",
    [
        np.zeros((3, 4)),
        [[1.0, 0, 0, 0], [0, float("nan"), 0, 0]],
        [[1.0, 0, 0, 0], [2.0, 0, 0, 5]],  # parallel rows: degenerate
        [[1.0, 0, 0, 0], [0, 1.0, 0]],  # ragged
        [["1", 0, 0, 0], [0, 1, 0, 0]],
    ],
)
def test_matrix_rejects(P):
    with pytest.raises(KinematicsError) as err:
        OrthographicCamera("v", P)
    assert err.value.field == "P"


# --- pinhole --------------------------------------------------------------------------------


@pytest.mark.parametrize("n_dist", [0, 4, 5, 8])
@pytest.mark.parametrize("use_rvec", [True, False])
def test_pinhole_matches_cv2_project_points(n_dist, use_rvec):
    rng = np.random.default_rng(n_dist + 10 * use_rvec)
    for _ in range(5):
        cam = random_pinhole(rng, n_dist, use_rvec=use_rvec)
        pts = random_points(rng)
        rvec = cv2.Rodrigues(cam.R)[0] if cam.rvec is None else cam.rvec
        ref = cv2.projectPoints(pts, rvec, cam.t, cam.K, cam.dist[:n_dist])[0][:, 0]
        np.testing.assert_allclose(cam.project(pts), ref, rtol=0, atol=1e-9)


def test_pinhole_geometry():
    rng = np.random.default_rng(2)
    cam = random_pinhole(rng)
    np.testing.assert_allclose(cam.R @ cam.centre + cam.t, 0.0, atol=1e-12)
    on_axis = cam.centre + 7.0 * cam.view_direction  # on the optical axis: no distortion
    np.testing.assert_allclose(cam.project(on_axis), [320.0, 240.0], atol=1e-9)
    behind = cam.centre - 7.0 * cam.view_direction
    sideways = cam.centre + 7.0 * cam.R[0]  # camera-frame z == 0
    uv = cam.project([behind, sideways, [np.nan, 0.0, 0.0]])
    assert np.isnan(uv).all()


def test_pinhole_defaults_and_padding():
    cam = PinholeCamera("c", K, [0.1, 0.01, 0.001, 0.002])
    np.testing.assert_array_equal(cam.R, np.eye(3))
    np.testing.assert_array_equal(cam.t, 0.0)
    np.testing.assert_array_equal(cam.dist, [0.1, 0.01, 0.001, 0.002, 0, 0, 0, 0])
    assert cam.rvec is None and cam.image_size is None
    # OpenCV hands out (1, n) and (n, 1) vectors
    same = PinholeCamera("c", K, [[0.1, 0.01, 0.001, 0.002]], R=np.eye(3), t=np.zeros((3, 1)))
    assert same == cam


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"K": [[800.0, 1.0, 320], [0, 800, 240], [0, 0, 1]]}, "K"),  # skew
        ({"K": [[800.0, 0, 320], [0, 800, 240], [0, 0, 2]]}, "K"),
        ({"K": [[-800.0, 0, 320], [0, 800, 240], [0, 0, 1]]}, "K"),
        ({"K": np.eye(2)}, "K"),
        ({"K": [[True, 0, 0], [0, 1, 0], [0, 0, 1]]}, "K"),
        ({"dist": [0.1, 0.2, 0.0]}, "dist"),
        ({"dist": np.zeros(14)}, "dist"),
        ({"dist": [0.1, float("nan"), 0, 0]}, "dist"),
        ({"R": np.diag([1.0, 1.0, 1.001])}, "R"),
        ({"R": np.diag([1.0, 1.0, -1.0])}, "R"),
        ({"R": np.eye(3), "rvec": [0.0, 0.0, 0.0]}, "rvec"),
        ({"rvec": [0.0, 1.0]}, "rvec"),
        ({"t": [0.0, 0.0, float("inf")]}, "t"),
        ({"t": "0 0 1"}, "t"),
        ({"size": (640,)}, "size"),
    ],
)
def test_pinhole_rejects(kwargs, field):
    with pytest.raises(KinematicsError) as err:
        PinholeCamera(**({"name": "c", "K": K} | kwargs))
    assert err.value.field == field
    assert str(err.value).startswith(f"{field}: ")


def test_cameras_are_immutable_values():
    cam = random_pinhole(np.random.default_rng(3))
    with pytest.raises(AttributeError):
        cam.t = np.zeros(3)
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0
    assert cam == PinholeCamera(cam.name, cam.K, cam.dist, t=cam.t, rvec=cam.rvec, size=(640, 480))
    assert cam != PinholeCamera(cam.name, cam.K, cam.dist, cam.R, cam.t, size=(640, 480))


def test_project_shapes():
    cam = random_pinhole(np.random.default_rng(4))
    pts = random_points(np.random.default_rng(5), 24).reshape(2, 3, 4, 3)
    uv = cam.project(pts)
    assert uv.shape == (2, 3, 4, 2)
    np.testing.assert_array_equal(uv[1, 2], cam.project(pts[1, 2]))
    assert cam.project(pts[0, 0, 0]).shape == (2,)
    with pytest.raises(KinematicsError, match="points"):
        cam.project(np.zeros((4, 2)))


def test_describe_camera():
    side = OrthographicCamera.from_axes("side", 2.86, ("x", "-y"), (360, 430), size=(720, 576))
    text = describe_camera(side)
    assert text.startswith("side: orthographic, scale 2.86, axes (x, -y)") and "720x576" in text
    assert "looks along (0, 0, -1)" in text
    assert "P [(1, 0, 0, 0), (0, 0, 1, 0)]" in describe_camera(
        OrthographicCamera("m", [[1, 0, 0, 0], [0, 0, 1, 0]]))
    text = describe_camera(PinholeCamera("c", K, [0.1, 0, 0, 0], t=[0, 0, 5]))
    assert text == ("c: pinhole, f (800, 780) px, c (320, 240), 1 nonzero distortion "
                    "coefficient, centre (0, 0, -5), looks along (0, 0, 1)")
    assert "\n" not in repr(side)


# --- packed arrays and numba kernels --------------------------------------------------------


def mixed_cameras(rng):
    return [
        OrthographicCamera.from_axes("side", 2.86, ("x", "-y"), (360.0, 430.0)),
        random_pinhole(rng, 8, "p8"),
        OrthographicCamera("oblique", rng.normal(0.0, 2.0, (2, 4))),
        random_pinhole(rng, 5, "p5", use_rvec=False),
        random_pinhole(rng, 0, "p0"),
    ]


def test_pack_cameras_layout():
    cams = mixed_cameras(np.random.default_rng(6))
    arrays = pack_cameras({c.name: c for c in cams})
    assert isinstance(arrays, CameraArrays)
    assert arrays.kind.tolist() == [0, 1, 0, 1, 1] and arrays.kind.dtype == np.int64
    shapes = {"P": (5, 2, 4), "K": (5, 3, 3), "dist": (5, 8), "R": (5, 3, 3), "t": (5, 3)}
    for field, shape in shapes.items():
        arr = getattr(arrays, field)
        assert arr.shape == shape and arr.dtype == np.float64 and arr.flags.c_contiguous
    np.testing.assert_array_equal(arrays.P[2], cams[2].P)
    np.testing.assert_array_equal(arrays.R[3], cams[3].R)
    with pytest.raises(KinematicsError, match=r"cameras\[1\]"):
        pack_cameras([cams[0], "not a camera"])


def test_numba_matches_numpy():
    rng = np.random.default_rng(7)
    cams = mixed_cameras(rng)
    arrays = pack_cameras(cams)
    behind = [cam.centre - 5.0 * cam.view_direction for cam in cams if cam.kind == 1]
    pts = np.concatenate([random_points(rng, 797), behind]).reshape(2, 400, 3)
    pts[0, 0] = np.nan
    for c, cam in enumerate(cams):
        expected = cam.project(pts)
        np.testing.assert_allclose(project_packed(arrays, c, pts), expected, rtol=0, atol=1e-9)
        u, v = project_point(*arrays, c, *pts[1, 5])
        np.testing.assert_allclose([u, v], expected[1, 5], rtol=0, atol=1e-9)
    assert np.isnan(project_packed(arrays, 1, pts)).any()  # behind-camera points were drawn


def test_project_point_allocates_nothing():
    # A fresh, uncached compile of the same code, so its LLVM IR can be inspected.
    fresh = njit(project_point.py_func)
    arrays = pack_cameras(mixed_cameras(np.random.default_rng(8)))
    fresh(*arrays, 1, 1.0, 2.0, 3.0)
    ir = fresh.inspect_llvm(fresh.signatures[0])
    assert not re.search(r"NRT_MemInfo_alloc|NRT_Allocate", ir)


@pytest.mark.parametrize("index", [-1, 5, 1.0, True, None])
def test_project_packed_rejects_bad_index(index):
    arrays = pack_cameras(mixed_cameras(np.random.default_rng(9)))
    with pytest.raises(KinematicsError) as err:
        project_packed(arrays, index, np.zeros(3))
    assert err.value.field == "camera_index"
