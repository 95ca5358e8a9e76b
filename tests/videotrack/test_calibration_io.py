"""Other tools' camera files: round trips and clear errors for malformed files."""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np
import pytest

from kinematics.cameras import PinholeCamera
from kinematics.cameras.files import import_anipose_toml, import_opencv_yaml, load_camera_file
from kinematics.errors import KinematicsError
from videotrack.calibration.formats import guess_format, read_cameras
from videotrack.io.camera_formats import (
    load_dlt_csv,
    load_qca,
    save_anipose_toml,
    save_dlt_csv,
    save_opencv_yaml,
)

DATA = Path(__file__).parents[2] / ".." / "shared" / "data"
QCA = DATA / "pose2sim_demo" / "calibration" / "Calib.qca.txt"


def cameras():
    rng = np.random.default_rng(0)
    out = []
    for i in range(3):
        K = [[800.0 + i, 0, 320.5], [0, 805.0, 240.25], [0, 0, 1]]
        t = rng.normal(0, 100, 3) + np.array([0, 0, 900.0])
        out.append(PinholeCamera(f"cam{i}", K, [-0.21, 0.1, 0.001, -0.002, 0.01 * i],
                                 rvec=rng.normal(0, 0.4, 3), t=t, size=(640, 480)))
    return out


def points():
    return np.random.default_rng(1).normal(0, 80, (30, 3))


def same_projection(a: PinholeCamera, b: PinholeCamera, tol=1e-6):
    return np.allclose(a.project(points()), b.project(points()), atol=tol, equal_nan=True)


def test_anipose_round_trip(tmp_path):
    cams = cameras()
    save_anipose_toml(tmp_path / "calibration.toml", cams, error=0.3)
    back = import_anipose_toml(tmp_path / "calibration.toml")
    assert list(back) == [c.name for c in cams]
    for c in cams:
        assert back[c.name] == c  # exact: repr floats, rvec kept


def test_opencv_yaml_round_trip(tmp_path):
    for cam in cameras():
        path = tmp_path / f"{cam.name}.yml"
        save_opencv_yaml(path, cam)
        back = import_opencv_yaml(path, cam.name)[cam.name]
        assert np.array_equal(back.K, cam.K) and np.array_equal(back.dist, cam.dist)
        assert np.allclose(back.R, cam.R, atol=1e-15) and np.array_equal(back.t, cam.t)
        assert back.image_size == cam.image_size
    import cv2

    fs = cv2.FileStorage(str(tmp_path / "cam0.yml"), cv2.FILE_STORAGE_READ)  # OpenCV reads it
    assert fs.getNode("camera_matrix").mat().shape == (3, 3)


@pytest.mark.parametrize("origin", ["bottom-left", "top-left"])
def test_dlt_round_trip(tmp_path, origin):
    cams = cameras()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        save_dlt_csv(tmp_path / "dlt.csv", cams, origin=origin)
    assert len(caught) == 3 and "distortion" in str(caught[0].message)
    rows = (tmp_path / "dlt.csv").read_text().splitlines()
    assert len(rows) == 11 and all(len(r.split(",")) == 3 for r in rows)
    back = load_dlt_csv(tmp_path / "dlt.csv", [c.name for c in cams],
                        [c.image_size for c in cams], origin=origin)
    for c in cams:
        plain = PinholeCamera(c.name, c.K, (), R=c.R, t=c.t, size=c.image_size)
        got = back[c.name]
        assert same_projection(plain, got)
        assert np.allclose(got.centre, c.centre, atol=1e-6)
        assert np.allclose(got.K, c.K, atol=1e-6)


def test_dlt_bottom_left_convention_flips_v(tmp_path):
    cam = cameras()[0]
    plain = PinholeCamera("c", cam.K, (), R=cam.R, t=cam.t, size=cam.image_size)
    save_dlt_csv(tmp_path / "d.csv", [plain])
    L = np.loadtxt(tmp_path / "d.csv")
    X = points()[0]
    uv = plain.project(X)
    den = L[8] * X[0] + L[9] * X[1] + L[10] * X[2] + 1
    u = (L[0] * X[0] + L[1] * X[1] + L[2] * X[2] + L[3]) / den
    v = (L[4] * X[0] + L[5] * X[1] + L[6] * X[2] + L[7]) / den
    assert np.allclose([u, v], [uv[0] + 1, cam.image_size[1] - uv[1]])  # DLTdv pixels


def test_malformed_files_give_located_errors(tmp_path):
    bad = tmp_path / "dlt.csv"
    bad.write_text("1,2\n" * 10)
    with pytest.raises(KinematicsError, match=r"dlt.csv: expected 11 rows"):
        load_dlt_csv(bad)
    bad.write_text("1,2\n" * 5 + "1,x\n" + "1,2\n" * 5)
    with pytest.raises(KinematicsError, match=r"dlt.csv:6: expected numbers"):
        load_dlt_csv(bad)
    bad.write_text("0\n" * 11)
    with pytest.raises(KinematicsError, match="degenerate"):
        load_dlt_csv(bad, origin="top-left")
    qca = tmp_path / "c.qca.txt"
    qca.write_text("<calibration><cameras><camera serial='a'>\n<transform r11='x'/>"
                   "<intrinsic/></camera></cameras></calibration>")
    with pytest.raises(KinematicsError, match=r"c.qca.txt:2: camera a: expected a number"):
        load_qca(qca)
    qca.write_text("<calibration><cameras>")
    with pytest.raises(KinematicsError, match=r"c.qca.txt:1: .*truncated file"):
        load_qca(qca)
    toml = tmp_path / "calibration.toml"
    toml.write_text('[cam_0]\nname = "a"\nmatrix = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n')
    with pytest.raises(KinematicsError, match=r"calibration.toml:1: cam_0.rotation: missing"):
        import_anipose_toml(toml)
    with pytest.raises(KinematicsError, match="cannot tell the camera file format"):
        guess_format(tmp_path / "cams.bin")


@pytest.mark.skipif(not QCA.is_file(), reason="../shared/data/pose2sim_demo absent")
def test_qca_matches_pose2sims_conversion():
    cams = load_qca(QCA)
    ref = import_anipose_toml(QCA.with_name("Calib_qualisys_converted_by_pose2sim.toml"))
    assert list(cams) == list(ref) == ["cam_01", "cam_02", "cam_03", "cam_04"]
    for name, cam in cams.items():
        r = ref[name]
        assert cam.image_size == (1088, 1920)
        assert np.allclose(cam.K, r.K, atol=1e-6)
        assert np.allclose(cam.R, r.R, atol=1e-9)
        assert np.allclose(cam.t / 1000.0, r.t, atol=1e-9)  # mm vs m
    assert np.isclose(cams["cam_01"].dist[0], -0.046183)  # not Pose2Sim's /64


def test_command_converts_a_camera_file(tmp_path, capsys):
    import videotrack.cli as vcli
    from videotrack.commands import calibrate as command

    save_anipose_toml(tmp_path / "in.toml", cameras())
    parser = argparse.ArgumentParser(prog="videotrack")
    command.add_parser(parser.add_subparsers())
    original, vcli.build_parser = vcli.build_parser, lambda: parser
    try:
        code = vcli.main(["calibrate", "--import", str(tmp_path / "in.toml"), "-o",
                          str(tmp_path / "cams.toml"), "--opencv-out", str(tmp_path / "yml"),
                          "--dlt-out", str(tmp_path / "d.csv")])
        assert code == 0
        got = load_camera_file(tmp_path / "cams.toml")
        assert got.units is None  # Anipose files do not say their unit
        assert got.cameras == {c.name: c for c in cameras()}
        assert read_cameras(tmp_path / "yml" / "cam1.yml")["cam1"].image_size == (640, 480)
        assert len(read_cameras(tmp_path / "d.csv", dlt_size=(640, 480))) == 3
        # never over its input
        assert vcli.main(["calibrate", "--import", str(tmp_path / "in.toml"), "-o",
                          str(tmp_path / "in.toml")]) == 1
        assert "never replaces an input" in capsys.readouterr().err
    finally:
        vcli.build_parser = original


def test_dlt_refuses_a_camera_at_the_world_origin(tmp_path):
    cam = PinholeCamera("ref", [[800.0, 0, 320], [0, 800, 240], [0, 0, 1]], size=(640, 480))
    with pytest.raises(KinematicsError, match=r"d.csv: cameras.ref: DLT-11 cannot describe"):
        save_dlt_csv(tmp_path / "d.csv", [cam])
    assert not (tmp_path / "d.csv").exists()


def test_dlt_coefficients_that_are_not_numbers_are_named():
    from videotrack.io.camera_formats import camera_from_dlt

    good = np.r_[np.ones(7), 1.0, 0.001, 0.002, 0.003]
    bad = good.copy()
    bad[4] = np.nan
    with pytest.raises(KinematicsError, match=r"DLT coefficient 5 of 11 is nan"):
        camera_from_dlt("c", bad, origin="top-left")
    with pytest.raises(KinematicsError, match=r"expected 11 DLT coefficients, got 10"):
        camera_from_dlt("c", good[:10], origin="top-left")
