"""``videotrack triangulate`` end to end on DeepLabCut CSV files it reads like a user's, and
the pose-3d CSV writer and reader."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics.cameras import PinholeCamera
from kinematics.cameras.files import save_cameras
from kinematics.model.rotations import euler_yxz
from videotrack import cli
from videotrack.errors import VideoTrackError
from videotrack.io.pose3d import is_pose3d, read_pose3d, write_pose3d

NAMES = ("snout", "neck", "hip", "knee")


def test_the_command_is_listed():
    assert "videotrack.commands.triangulate" in cli.COMMAND_MODULES


def cameras():
    k = [[800.0, 0, 639.5], [0, 800.0, 511.5], [0, 0, 1]]
    out = []
    for i in range(3):
        r = euler_yxz(2.1 * i + 0.2, 0.4, 0.0).T
        centre = r.T @ np.array([0.0, 0.0, -300.0])
        out.append(PinholeCamera(f"cam{i}", k, [-0.2, 0.05, 0, 0, 0], R=r, t=-r @ centre,
                                 size=(1280, 1024)))
    return out


def truth(n=30):
    t = np.arange(n)[:, None]
    base = np.array([[0.0, 0, 0], [15, 5, 0], [35, 0, 5], [45, -15, 5]])
    return base[None] + np.stack([3 * np.sin(0.2 * t), 2 * np.cos(0.1 * t),
                                  np.sin(0.3 * t)], -1)


def write_dlc_csv(path, xy, score):
    """A DeepLabCut CSV as DeepLabCut writes it: three header rows, then one row per frame."""
    lines = ["scorer," + ",".join(["dlc"] * 3 * len(NAMES)),
             "bodyparts," + ",".join(n for n in NAMES for _ in range(3)),
             "coords," + ",".join(["x", "y", "likelihood"] * len(NAMES))]
    for f in range(len(xy)):
        vals = []
        for j in range(len(NAMES)):
            vals += ["" if np.isnan(v) else repr(float(v)) for v in (*xy[f, j], score[f, j])]
        lines.append(f"{f}," + ",".join(vals))
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture
def session(tmp_path):
    cams = cameras()
    pts = truth()
    rng = np.random.default_rng(0)
    save_cameras(tmp_path / "cameras.toml", cams, units="mm")
    args = []
    for c, cam in enumerate(cams):
        xy = cam.project(pts) + rng.normal(0, 0.3, (len(pts), len(NAMES), 2))
        score = np.full(xy.shape[:2], 0.9)
        if c == 2:
            xy[5, 1] += 80.0  # an outlier
            score[7, 2] = 0.1
        path = tmp_path / f"{cam.name}DLC.csv"
        write_dlc_csv(path, xy, score)
        args.append(f"{cam.name}={path}")
    return tmp_path, args, pts


def run(argv, capsys):
    code = cli.main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("method", ["linear", "ransac", "optim"])
def test_triangulate_writes_pose3d(session, capsys, method):
    tmp, args, pts = session
    out = tmp / "trial.csv"
    extra = {"linear": [], "ransac": ["--inlier-px", "5", "--good-px", "0"],
             "optim": ["--limbs", "snout,neck", "neck,hip", "--chunk", "20", "--smooth",
                       "0.5", "--init", "ransac", "--inlier-px", "5", "--good-px", "0"]}[method]
    code, stdout, stderr = run(["triangulate", str(tmp / "cameras.toml"), *args, "-o",
                                str(out), "--method", method, "--min-score", "0.5", *extra],
                               capsys)
    assert code == 0, stderr
    assert f"wrote {out}" in stdout and "reprojection error median" in stdout
    pose = read_pose3d(out)
    assert pose.names == NAMES and pose.frames.tolist() == list(range(30))
    err = np.linalg.norm(pose.xyz - pts, axis=-1)
    assert np.median(err) < 0.5
    assert pose.ncams[7, 2] == 2 and np.all(pose.score[pose.ncams == 3] == 0.9)
    if method != "linear":  # RANSAC leaves the outlier out (and the optimisation with it)
        assert err[5, 1] < 1.5 and pose.ncams[5, 1] == 2
    np.testing.assert_array_equal(pose.M, np.eye(3))


def test_project_file_names_the_cameras(session, capsys):
    tmp, args, _ = session
    (tmp / "project.toml").write_text('[cameras]\npath = "cameras.toml"\n')
    code, stdout, stderr = run(["triangulate", str(tmp / "project.toml"), *args, "-o",
                                str(tmp / "p.csv")], capsys)
    assert code == 0 and "wrote" in stdout, stderr


def test_anipose_calibration_and_positional_files(session, capsys):
    tmp, args, pts = session
    import cv2

    lines = []
    for i, cam in enumerate(cameras()):
        rvec = cv2.Rodrigues(cam.R)[0].ravel().tolist()
        lines += [f"[cam_{i}]", f'name = "{cam.name}"', "size = [1280, 1024]",
                  f"matrix = {cam.K.tolist()}", f"distortions = {cam.dist[:5].tolist()}",
                  f"rotation = {rvec}", f"translation = {cam.t.tolist()}", ""]
    lines += ["[metadata]", "adjusted = false"]
    (tmp / "calibration.toml").write_text("\n".join(lines))
    paths = [a.split("=", 1)[1] for a in args]
    out = tmp / "out.csv"
    code, _, stderr = run(["triangulate", str(tmp / "calibration.toml"), *paths, "-o",
                           str(out), "--unweighted"], capsys)
    assert code == 0, stderr
    assert np.median(np.linalg.norm(read_pose3d(out).xyz - pts, axis=-1)) < 0.5


@pytest.mark.parametrize("extra, message", [
    (["cam9=x.csv"], "no camera 'cam9'"),
    (["--limbs", "snout,tail", "--method", "optim"], "--limbs: expected two body parts"),
    (["--method", "optim", "--limbs", "snout,neck", "--limb-lengths", "1", "2"],
     "limb_lengths"),
    (["--min-cams", "1", "--method", "ransac"], "min_cams"),
    (["--limbs", "snout,neck"], "--limbs: limbs constrain only the optimisation"),
])
def test_bad_options_are_one_line(session, capsys, extra, message):
    tmp, args, _ = session
    out = tmp / "x.pose3d.csv"
    code, _, stderr = run(["triangulate", str(tmp / "cameras.toml"), *args, *extra, "-o",
                           str(out)], capsys)
    assert code == 1 and message in stderr and len(stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_never_overwrites_an_input_or_another_kind(session, capsys):
    tmp, args, _ = session
    first = args[0].split("=", 1)[1]
    before = (tmp / "cam0DLC.csv").read_bytes()
    code, _, stderr = run(["triangulate", str(tmp / "cameras.toml"), *args, "-o", first],
                          capsys)
    assert code == 1 and "replaces an input" in stderr.replace("never replaces", "replaces")
    assert (tmp / "cam0DLC.csv").read_bytes() == before
    other = tmp / "notes.txt"
    other.write_text("my notes\n")
    code, _, stderr = run(["triangulate", str(tmp / "cameras.toml"), *args, "-o", str(other)],
                          capsys)
    assert code == 1 and "not a pose-3d CSV" in stderr and other.read_text() == "my notes\n"


def test_bad_camera_file_is_one_line(session, capsys):
    tmp, args, _ = session
    (tmp / "bad.toml").write_text("[cameras.cam0]\ntype = 'pinhole'\nK = 3\n")
    code, _, stderr = run(["triangulate", str(tmp / "bad.toml"), *args[:1], "-o",
                           str(tmp / "o.csv")], capsys)
    assert code == 1 and "bad.toml" in stderr and len(stderr.strip().splitlines()) == 1


def test_pose3d_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    xyz = rng.normal(0, 10, (5, 2, 3))
    xyz[1, 0] = np.nan
    error, score = rng.uniform(0, 3, (5, 2)), rng.uniform(0, 1, (5, 2))
    ncams = np.full((5, 2), 3)
    error[1, 0] = score[1, 0] = np.nan
    m = euler_yxz(0.3, 0.2, 0.1)
    path = tmp_path / "p.csv"
    write_pose3d(path, ["a", "b"], xyz, error, ncams, score, np.arange(10, 15), M=m,
                 center=[1, 2, 3])
    back = read_pose3d(path)
    np.testing.assert_array_equal(back.xyz, xyz)
    np.testing.assert_array_equal(back.error, error)
    np.testing.assert_array_equal(back.score, score)
    np.testing.assert_array_equal(back.ncams, ncams)
    np.testing.assert_array_equal(back.M, m)
    assert back.frames.tolist() == [10, 11, 12, 13, 14] and is_pose3d(path)
    np.testing.assert_allclose(back.world(), (xyz + np.array([1, 2, 3])) @ m)


def test_reads_anipose_pandas_output(tmp_path):
    """As Anipose writes it with pandas: NaN as empty fields, ncams as floats."""
    header = ("nose_x,nose_y,nose_z,nose_error,nose_ncams,nose_score,"
              + ",".join(f"M_{i}{j}" for i in range(3) for j in range(3))
              + ",center_0,center_1,center_2,fnum")
    eye = "1.0,0.0,0.0,0.0,1.0,0.0,0.0,0.0,1.0,0.0,0.0,0.0"
    path = tmp_path / "vid.csv"
    path.write_text(f"{header}\n1.5,2.5,3.5,0.7,3.0,0.95,{eye},0\n,,,,,,{eye},1\n")
    pose = read_pose3d(path)
    assert pose.names == ("nose",) and pose.ncams[0, 0] == 3 and np.isnan(pose.xyz[1]).all()


@pytest.mark.parametrize("text, message", [
    ("a,b\n1,2\n", "bad.csv:1: not an Anipose pose-3d CSV"),
    ("p_x,p_y,p_z,p_error,p_ncams,p_score,fnum\n1,2,3,0,2,1\n", "bad.csv:2: row has 6 cells"),
    ("p_x,p_y,p_z,p_error,p_ncams,p_score,fnum\n1,2,zz,0,2,1,0\n",
     "bad.csv:2: p_z: 'zz' is not a number"),
    ("", "bad.csv: file is empty"),
])
def test_bad_pose3d_files(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(VideoTrackError, match=message):
        read_pose3d(path)
    assert is_pose3d(path) == text.startswith("p_x")
