"""`videotrack synth --points`: given 3D marker trajectories rendered through pinhole cameras,
absent markers left out, detections at the ground truth, bad points files one line."""

import numpy as np
import pytest

from kinematics.cameras import PinholeCamera
from kinematics.cameras.files import save_cameras
from videotrack.cli import main
from videotrack.detect.detections import load_detections
from videotrack.errors import VideoTrackError
from videotrack.results.tables import read_table, write_table
from videotrack.synth.project import SynthOptions, read_points, simulate_points

NAMES = ["hip", "knee", "ankle"]


def cameras():
    """Two 320x240 pinhole cameras 300 mm from the origin, from the side and from above."""
    K = [[600.0, 0.0, 159.5], [0.0, 600.0, 119.5], [0.0, 0.0, 1.0]]
    side = PinholeCamera("side", K, R=np.diag([1.0, -1.0, -1.0]), t=[0, 0, 300], size=(320, 240))
    top = PinholeCamera("top", K, rvec=[-np.pi / 2, 0, 0], t=[0, 0, 300], size=(320, 240))
    return {"side": side, "top": top}


def trajectories(n=10, seed=0):
    """Three markers moving smoothly around the origin (mm), a few absent (NaN)."""
    rng = np.random.default_rng(seed)
    base = np.array([[0.0, 10.0, 0.0], [15.0, -5.0, 5.0], [-12.0, -15.0, -8.0]])
    t = np.arange(n)[:, None, None]
    pts = base[None] + 0.7 * t * rng.uniform(-1, 1, (1, 3, 3))
    pts[3, 1] = np.nan
    pts[6, 2] = np.nan
    return pts


def write_points_csv(path, pts):
    cols = ["frame"] + [f"{m}.{a}" for m in NAMES for a in "xyz"]
    write_table(path, cols, np.column_stack([np.arange(len(pts)), pts.reshape(len(pts), -1)]))
    return path


def test_scene_of_points_projects_and_hides_absent_markers():
    cams, pts = cameras(), trajectories()
    scene = simulate_points(pts, cams, SynthOptions())
    for v, cam in enumerate(cams.values()):
        np.testing.assert_allclose(scene.projections[:, v], cam.project(pts))
    assert not scene.visible[3, :, 1].any() and not scene.visible[6, :, 2].any()
    assert scene.visible.sum() == scene.visible.size - 4
    assert scene.angles_deg.shape == (10, 0) and scene.joints.shape == (10, 0, 3)
    with pytest.raises(VideoTrackError, match="even number"):
        simulate_points(pts[:3], cams, SynthOptions(interlaced=True))


def test_points_csv_and_npz_read_the_same(tmp_path):
    pts = trajectories()
    names, back = read_points(write_points_csv(tmp_path / "p.csv", pts))
    assert names == NAMES
    np.testing.assert_array_equal(back, pts)
    np.savez(tmp_path / "p.npz", frame=np.arange(10),
             **{f"{m}.{a}": pts[:, i, k] for i, m in enumerate(NAMES) for k, a in
                enumerate("xyz")})
    names, back = read_points(tmp_path / "p.npz")
    assert names == NAMES
    np.testing.assert_array_equal(back, pts)


def test_synth_points_renders_and_detects_at_the_truth(tmp_path, capsys):
    save_cameras(tmp_path / "cams.toml", cameras(), units="mm")
    pts = trajectories()
    write_points_csv(tmp_path / "points.csv", pts)
    out = tmp_path / "proj"
    assert main(["synth", str(out), "--points", str(tmp_path / "points.csv"), "--cameras",
                 str(tmp_path / "cams.toml"), "--diameter", "6", "--layout", "separate"]) == 0
    assert "wrote 10 frames" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == [
        "cameras.toml", "project.toml", "truth.csv", "video_side.avi", "video_top.avi"]
    cols, truth = read_table(out / "truth.csv")
    assert cols[:4] == ["frame", "hip.x", "hip.y", "hip.z"] and "top.ankle.visible" in cols
    np.testing.assert_array_equal(truth[:, 1:10].reshape(10, 3, 3), pts)
    assert main(["detect", str(out / "project.toml")]) == 0
    det = load_detections(out / "detections.npz")
    assert det.n_records == 10 and det.view_names == ["side", "top"]
    for v, view in enumerate(det.view_names):
        for r in range(10):
            seen = [m for m in NAMES if truth[r, cols.index(f"{view}.{m}.visible")] == 1]
            planted = np.array([[truth[r, cols.index(f"{view}.{m}.{c}")] for c in "uv"]
                                for m in seen])
            found = det.points_of(r, v)
            assert len(found) == len(seen) == (2 if r in (3, 6) else 3)
            d = np.linalg.norm(planted[:, None] - found[None], axis=2).min(axis=1)
            assert d.max() < 0.1


@pytest.mark.parametrize("text, message", [
    ("frame,hip.x,hip.y\n0,1,2\n", "marker 'hip' has no column hip.z"),
    ("frame,a,b\n0,1,2\n", "no point columns"),
    ("hip.x,hip.y,hip.z\n", "no frames in file"),
    ("hip.x,hip.y,hip.z\n1,2,zz\n", "'zz' is not a number"),
    ("hip.x,hip.y,hip.z\n1,2,inf\n", "not finite"),
])
def test_bad_points_file_is_one_line(tmp_path, capsys, text, message):
    save_cameras(tmp_path / "cams.toml", cameras())
    (tmp_path / "p.csv").write_text(text)
    assert main(["synth", str(tmp_path / "x"), "--points", str(tmp_path / "p.csv"),
                 "--cameras", str(tmp_path / "cams.toml")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "p.csv" in err, err
    assert not (tmp_path / "x" / "truth.csv").exists()


def test_points_take_cameras_and_no_chain(tmp_path, capsys):
    write_points_csv(tmp_path / "p.csv", trajectories())
    assert main(["synth", str(tmp_path / "x"), "--points", str(tmp_path / "p.csv")]) == 1
    assert "--cameras" in capsys.readouterr().err
    save_cameras(tmp_path / "cams.toml", cameras())
    assert main(["synth", str(tmp_path / "x"), "--points", str(tmp_path / "p.csv"),
                 "--cameras", str(tmp_path / "cams.toml"), "--trials", "2"]) == 1
    assert "takes no --trials" in capsys.readouterr().err
