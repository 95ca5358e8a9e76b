"""Camera calibration: board detection on rendered boards, bundle adjustment recovering
planted cameras, outlier rejection, the command and its errors."""

from __future__ import annotations

import argparse
import re

import numpy as np
import pytest

from kinematics.cameras import PinholeCamera
from kinematics.cameras.calibration_math import project, rodrigues, triangulate
from tests.fixtures.paths import SHARED_DATA
from videotrack.calibration.boards import Board, board_from_table, load_board
from videotrack.calibration.bundle import Options, calibrate
from videotrack.calibration.detect import Corners, Source, detect_all
from videotrack.calibration.report import make_report, save_png
from videotrack.calibration.synthetic import board_image, board_poses_facing, render_view
from videotrack.errors import VideoTrackError

CHARUCO = Board("charuco", (7, 5), 30.0, 22.0, "4X4_50")
CHECKER = Board("checkerboard", (8, 6), 30.0)
GRID_TABLE = {"type": "aruco", "markers": [5, 4], "marker_mm": 30.0, "separation_mm": 6.0,
              "dictionary": "4X4_50"}
GRID = board_from_table(GRID_TABLE)
DIST = (-0.2, 0.1, 0.001, -0.001, 0.0)


def rig(n=3, radius=500.0, dist=DIST, size=(640, 512)):
    """Cameras on an arc around the origin, looking at it, 25° apart."""
    cams = []
    for i in range(n):
        ang = np.deg2rad(-25 + 25 * i)
        c = np.array([radius * np.sin(ang), -80.0, -radius * np.cos(ang)])
        z = -c / np.linalg.norm(c)
        x = np.cross([0, 1, 0], z)
        x /= np.linalg.norm(x)
        R = np.stack([x, np.cross(z, x), z])
        f = 520.0 + 10 * i
        K = [[f, 0, size[0] / 2 + 3 * i], [0, f + 1, size[1] / 2 - 2 * i], [0, 0, 1]]
        cams.append(PinholeCamera(f"cam{i}", K, dist, R=R, t=-R @ c, size=size))
    return cams


def in_reference_frame(cams, ref=0):
    """The planted cameras with camera ``ref`` as the world frame (as calibrate returns)."""
    r0 = cams[ref]
    out = []
    for c in cams:
        R = c.R @ r0.R.T
        out.append(PinholeCamera(c.name, c.K, c.dist, R=R, t=c.t - R @ r0.t, size=c.image_size))
    return out


def projected_corners(board, cams, n_views=24, noise=0.3, outliers=0.0, seed=1):
    """Corners of random board poses projected through ``cams``, with noise and outliers."""
    rng = np.random.default_rng(seed)
    poses = board_poses_facing(board, cams, n_views, seed=seed, full=False)
    obj = board.object_points
    uv = np.full((len(cams), len(poses), len(obj), 2), np.nan)
    for v, (r, t) in enumerate(poses):
        world = obj @ rodrigues(r).T + t
        for c, cam in enumerate(cams):
            p = cam.project(world)
            w, h = cam.image_size
            ok = np.all(np.isfinite(p), 1) & (p[:, 0] > 0) & (p[:, 0] < w) & (p[:, 1] > 0) & \
                (p[:, 1] < h)
            if ok.sum() >= 6:
                uv[c, v, ok] = p[ok] + rng.normal(0, noise, (ok.sum(), 2))
    planted = np.zeros(uv.shape[:3], bool)
    if outliers:
        planted = np.isfinite(uv[..., 0]) & (rng.random(uv.shape[:3]) < outliers)
        uv[planted] += rng.choice([-1, 1], (planted.sum(), 2)) * rng.uniform(8, 40,
                                                                               (planted.sum(), 2))
    frames = np.arange(len(poses))
    return [Corners(c.name, c.image_size, frames, uv[i], [str(f) for f in frames])
            for i, c in enumerate(cams)], planted


# --- math --------------------------------------------------------------------------------


def test_projection_and_rodrigues_match_opencv():
    import cv2

    rng = np.random.default_rng(0)
    r = rng.normal(size=(6, 3))
    for i in range(6):
        assert np.allclose(rodrigues(r[i]), cv2.Rodrigues(r[i])[0], atol=1e-12)
    cam = rig(1)[0]
    X = rng.normal(0, 50, (20, 3))
    intr = np.array([*np.diag(cam.K)[:2], *cam.K[:2, 2], *cam.dist[:5]])
    assert np.allclose(project(X @ cam.R.T + cam.t, intr), cam.project(X), atol=1e-9)


def test_triangulation_inverts_projection():
    cams = rig(3)
    X = np.random.default_rng(1).normal(0, 40, (10, 3))
    uv = np.array([c.project(X) for c in cams])
    uv[2, :3] = np.nan  # seen by two cameras only
    uv[1:, 9] = np.nan  # seen by one: not triangulated
    got = triangulate(cams, uv)
    assert np.allclose(got[:9], X[:9], atol=1e-6)
    assert np.all(np.isnan(got[9]))


# --- board config and detection -------------------------------------------------------------


@pytest.mark.parametrize("board", [CHARUCO, CHECKER, GRID], ids=["charuco", "checkerboard",
                                                                  "aruco"])
def test_detection_finds_known_corners_on_rendered_boards(board):
    cams = rig(2)
    image, S = board_image(board, 40)
    errors = []
    for r, t in board_poses_facing(board, cams, 3, seed=2):
        world = board.object_points @ rodrigues(r).T + t
        for cam in cams:
            ids, uv = board.detect(render_view(image, S, cam, r, t))
            assert len(ids) >= 0.75 * board.n_corners  # a marker may be missed at a slant
            errors.append(np.linalg.norm(uv - cam.project(world)[ids], axis=1))
    errors = np.concatenate(errors)
    assert np.median(errors) < 0.2 and errors.max() < 0.6  # sub-pixel, through distortion


def test_charuco_partial_view_keeps_corner_identities():
    cam = rig(1, dist=())[0]
    image, S = board_image(CHARUCO, 40)
    (r, t), = board_poses_facing(CHARUCO, [cam], 1, seed=3, min_cameras=1)
    view = render_view(image, S, cam, r, t)
    world = CHARUCO.object_points @ rodrigues(r).T + t
    truth = cam.project(world)
    cut = int(np.median(truth[:, 0]))
    view[:, cut:] = 128  # hide the right half of the board
    ids, uv = CHARUCO.detect(view)
    assert 6 <= len(ids) < CHARUCO.n_corners
    assert np.all(truth[ids, 0] < cut)
    assert np.max(np.linalg.norm(uv - truth[ids], axis=1)) < 0.6


def test_rendered_grid_is_the_board_opencv_prints():
    image, S = board_image(GRID, 40)
    printed = GRID._cv.generateImage((image.shape[1], image.shape[0]), marginSize=40)
    assert np.array_equal(image, printed)
    # marker 6 (row 1, column 1) begins one pitch (36 mm = 48 px) in from the first
    x, y, _ = S @ [*GRID.object_points[4 * 6, :2], 1]
    assert (x, y) == (40 - 0.5 + 48, 40 - 0.5 + 48) and image[88, 88] == 0 == image[88, 127]
    assert image[87, 88] == 255 == image[88, 128]
    with pytest.raises(ValueError, match="whole number of pixels"):
        board_image(GRID, 44)  # 6 mm would be 8.8 px


def test_grid_partial_views_keep_marker_identities_and_few_markers_are_skipped():
    cam = rig(1, dist=())[0]
    image, S = board_image(GRID, 40)
    (r, t), = board_poses_facing(GRID, [cam], 1, seed=3, min_cameras=1)
    view = render_view(image, S, cam, r, t)
    truth = cam.project(GRID.object_points @ rodrigues(r).T + t)
    cut = np.median(truth[:, 0])
    hidden = view.copy()
    hidden[:, int(cut):] = 128  # hide the right half of the board
    ids, uv = GRID.detect(hidden)
    assert 12 <= len(ids) < GRID.n_corners and len(ids) % 4 == 0
    assert np.all(truth[ids, 0] < cut)
    assert np.max(np.linalg.norm(uv - truth[ids], axis=1)) < 0.4
    # three markers make a view; two (8 corners) are too few to trust: the view is skipped
    import cv2

    quads = truth.reshape(-1, 4, 2)
    for shown, expected in ((3, 12), (2, 0)):
        painted = view.copy()
        for quad in quads[shown:]:  # paint over the other markers (white, as the paper)
            centre = quad.mean(axis=0)
            cv2.fillConvexPoly(painted, np.rint(centre + 1.3 * (quad - centre)).astype(np.int32),
                               255)
        ids, _ = GRID.detect(painted)
        assert len(ids) == expected and set(ids // 4) <= set(range(shown))


def test_board_config_errors(tmp_path):
    path = tmp_path / "board.toml"
    path.write_text('[board]\ntype = "charuco"\nsquares = [7, 5]\nsquare_mm = 30\n'
                    'marker_mm = 40\ndictionary = "4X4_50"\n')
    with pytest.raises(VideoTrackError, match=r"board.toml: board.marker_mm: .*smaller"):
        load_board(path)
    for table, field in [({"type": "circles", "squares": [5, 5], "square_mm": 1}, "type"),
                         ({"type": "checkerboard", "squares": [5], "square_mm": 1}, "squares"),
                         ({"type": "checkerboard", "squares": [8, 8], "square_mm": 1},
                          "squares"),
                         ({"type": "checkerboard", "squares": [6, 5], "square_mm": -1},
                          "square_mm"),
                         ({"type": "charuco", "squares": [5, 5], "square_mm": 2,
                           "marker_mm": 1, "dictionary": "9X9_1"}, "dictionary"),
                         ({"type": "charuco", "squares": [20, 20], "square_mm": 2,
                           "marker_mm": 1, "dictionary": "4X4_50"}, "dictionary"),
                         ({**GRID_TABLE, "markers": [5]}, "markers"),
                         ({**GRID_TABLE, "markers": [1, 4]}, "markers"),
                         ({**GRID_TABLE, "separation_mm": 0}, "separation_mm"),
                         ({**GRID_TABLE, "marker_mm": None}, "marker_mm"),
                         ({**GRID_TABLE, "markers": [10, 6]}, "dictionary"),  # 60 > 50
                         ({**GRID_TABLE, "dictionary": None}, "dictionary")]:
        with pytest.raises(VideoTrackError, match=f"board.{field}"):
            board_from_table(table)
    with pytest.raises(VideoTrackError, match=r"board: unknown key.*squares for type 'aruco'"):
        board_from_table({**GRID_TABLE, "squares": [5, 4]})
    path.write_text("board_x = 8\nboard_y = 11\nsquare_length = 24.0\nmarker_length = 18.75\n"
                    "marker_bits = 4\ndict_size = 1000\n")  # an Anipose board file
    assert load_board(path) == Board("charuco", (8, 11), 24.0, 18.75, "4X4_1000")
    path.write_text("[board\n")
    with pytest.raises(VideoTrackError, match="not valid TOML"):
        load_board(path)
    path.write_text('[board]\ntype = "aruco"\nmarkers = [5, 4]\nmarker_mm = 30\n'
                    'separation_mm = 6\ndictionary = "4X4_50"\n')
    assert load_board(path) == GRID and GRID.separation_mm == 6.0
    assert GRID.describe() == "aruco grid 5x4 markers of 30 mm, 6 mm apart, dictionary 4X4_50"


def _render_folder(folder, board, cams, n_views, seed=4):
    import cv2

    image, S = board_image(board, 40)
    poses = board_poses_facing(board, cams, n_views, seed=seed, min_cameras=min(2, len(cams)))
    for cam in cams:
        (folder / cam.name).mkdir(parents=True, exist_ok=True)
        for i, (r, t) in enumerate(poses):
            cv2.imwrite(str(folder / cam.name / f"v{i:02d}.png"), render_view(image, S, cam, r, t))
    return poses


def test_detect_all_caches_and_reports_a_mismatched_board(tmp_path):
    cams = rig(2)
    _render_folder(tmp_path, CHECKER, cams, 3)
    sources = [Source(c.name, tmp_path / c.name) for c in cams]
    cache = tmp_path / "c.npz"
    first = detect_all(CHECKER, sources, cache=cache, progress=False)
    assert [c.views_found for c in first] == [3, 3]
    again = detect_all(CHECKER, sources, cache=cache, progress=False)
    assert np.array_equal(first[0].uv, again[0].uv, equal_nan=True)
    wrong = Board("checkerboard", (9, 6), 30.0)  # squares miscounted
    with pytest.raises(VideoTrackError, match=r"cam0: --camera cam0: no checkerboard 9x6"):
        detect_all(wrong, sources, cache=cache, progress=False)
    with pytest.raises(VideoTrackError, match="no image matches"):
        Source("x", str(tmp_path / "nothing*.png"))


# --- bundle adjustment -----------------------------------------------------------------------


def _check_recovered(cal, cams, centre_mm, focal_rel):
    truth = in_reference_frame(cams)
    for got, want in zip(cal.cameras, truth, strict=True):
        assert np.linalg.norm(got.centre - want.centre) < centre_mm, got.name
        assert np.allclose(np.diag(got.K)[:2], np.diag(want.K)[:2], rtol=focal_rel), got.name


def test_bundle_adjustment_recovers_planted_cameras():
    cams = rig(3)
    corners, _ = projected_corners(CHARUCO, cams, noise=0.0)
    cal = calibrate(corners, CHARUCO.object_points, Options(restarts=2, n_dist=4))
    _check_recovered(cal, cams, 1e-3, 1e-6)  # exact data: exact cameras
    corners, _ = projected_corners(CHARUCO, cams, noise=0.3)
    cal = calibrate(corners, CHARUCO.object_points, Options(restarts=2, n_dist=4))
    _check_recovered(cal, cams, 5.0, 0.01)
    assert 0.2 < np.nanmedian(cal.errors) < 0.45  # the noise level (Rayleigh median 0.35)
    report = make_report(cal, corners, CHARUCO)
    assert abs(report.square["error"]) < 0.1
    assert report.repeat["diverged"] == 0 and report.repeat["starts"] == 2


def test_outliers_are_rejected():
    cams = rig(3)
    corners, planted = projected_corners(CHARUCO, cams, noise=0.3, outliers=0.05, seed=5)
    cal = calibrate(corners, CHARUCO.object_points, Options(restarts=1, n_dist=4))
    _check_recovered(cal, cams, 5.0, 0.01)
    flagged = np.isfinite(cal.errors) & ~cal.inlier
    assert flagged[planted].mean() > 0.95  # nearly every planted outlier found ...
    assert flagged[~planted].mean() < 0.02  # ... and few good corners lost
    assert np.median(cal.errors[cal.inlier]) < 0.45


def test_camera_never_sharing_a_view_is_named():
    cams = rig(3)
    corners, _ = projected_corners(CHARUCO, cams, noise=0.1)
    corners[2].uv[:12] = np.nan  # cam2 sees only views 12..
    corners[0].uv[12:] = np.nan  # cam0 and cam1 only views ..11
    corners[1].uv[12:] = np.nan
    with pytest.raises(VideoTrackError, match=r"camera\(s\) cam2 never see the board in the "
                                              r"same frame as cam0, cam1"):
        calibrate(corners, CHARUCO.object_points, Options(restarts=1))


def test_fixed_intrinsics_stay_and_world_frame_follows_the_reference():
    cams = rig(3)
    corners, _ = projected_corners(CHARUCO, cams, noise=0.2)
    known = {i: c for i, c in enumerate(cams)}
    cal = calibrate(corners, CHARUCO.object_points,
                    Options(restarts=1, fix_intrinsics=True, known=known, reference=1))
    for got, want in zip(cal.cameras, cams, strict=True):
        assert np.array_equal(got.K, want.K) and np.allclose(got.dist, want.dist)
    assert np.allclose(cal.cameras[1].t, 0) and np.allclose(cal.cameras[1].R, np.eye(3))
    truth = in_reference_frame(cams, ref=1)
    assert np.linalg.norm(cal.cameras[0].centre - truth[0].centre) < 3.0


def test_report_and_png(tmp_path):
    cams = rig(2)
    corners, _ = projected_corners(CHARUCO, cams, n_views=6, noise=0.3)
    cal = calibrate(corners, CHARUCO.object_points, Options(restarts=2, n_dist=4))
    report = make_report(cal, corners, CHARUCO)
    text = "\n".join(report.lines())
    assert "median px" in text and "square size" in text and "repeatability over 2" in text
    assert any("poorly constrained" in w for w in report.warnings)  # 6 views < 8
    save_png(tmp_path / "r.png", cal, corners)
    assert (tmp_path / "r.png").read_bytes().startswith(b"\x89PNG")


# --- the command ---------------------------------------------------------------------------


def cli(*argv):
    """``videotrack calibrate ...`` through the CLI's error handling (not yet registered)."""
    import videotrack.cli as vcli
    from videotrack.commands import calibrate as command

    parser = argparse.ArgumentParser(prog="videotrack")
    command.add_parser(parser.add_subparsers())
    original = vcli.build_parser
    vcli.build_parser = lambda: parser
    try:
        return vcli.main([str(a) for a in argv])
    finally:
        vcli.build_parser = original


def test_command_calibrates_rendered_views(tmp_path, capsys, monkeypatch):
    import videotrack.cli as vcli

    stray = []
    monkeypatch.setattr(vcli, "_stray_warning", lambda *a: stray.append(a))
    cams = rig(3)
    _render_folder(tmp_path, CHARUCO, cams, 8)
    board = tmp_path / "board.toml"
    board.write_text('[board]\ntype = "charuco"\nsquares = [7, 5]\nsquare_mm = 30.0\n'
                     'marker_mm = 22.0\ndictionary = "4X4_50"\n')
    out = tmp_path / "cameras.toml"
    args = ["calibrate", board, *[f"--camera={c.name}={tmp_path / c.name}" for c in cams],
            "-o", out, "--anipose-out", tmp_path / "calibration.toml", "--report-png",
            tmp_path / "r.png", "--restarts", "2", "--distortion", "4"]
    assert cli(*args) == 0
    text = capsys.readouterr().out
    assert "square size" in text and "spanning tree" in text
    from kinematics.cameras.files import import_anipose_toml, load_camera_file

    got = load_camera_file(out)
    assert got.units == "mm"
    _check_recovered(argparse.Namespace(cameras=list(got.cameras.values())), cams, 5.0, 0.01)
    assert list(import_anipose_toml(tmp_path / "calibration.toml")) == ["cam0", "cam1", "cam2"]
    assert (tmp_path / "cameras.toml.corners.npz").is_file()
    # the same again: from the cache, outputs replaced
    assert cli(*args) == 0
    assert not stray  # no library warning reaches the user
    # a board view as the world frame, then the poses refined from points: the refinement
    # keeps the reference camera, not the board's name, fixed
    rng = np.random.default_rng(5)
    X = rng.normal(0, 80, (120, 3)) + np.array([0, 80, 500.0])
    p2d = np.array([c.project(X) for c in in_reference_frame(cams)])
    np.savez(tmp_path / "points.npz", p2d=p2d + rng.normal(0, 0.2, p2d.shape))
    capsys.readouterr()
    assert cli(*args, "--world-view", "0", "--refine-points", tmp_path / "points.npz") == 0
    assert "world frame: the board in view 0" in capsys.readouterr().out


def test_command_calibrates_an_aruco_grid_and_names_a_mismatched_one(tmp_path, capsys):
    from kinematics.cameras.files import load_camera_file

    cams = rig(3)
    _render_folder(tmp_path, GRID, cams, 8)
    board = tmp_path / "grid.toml"

    def write(**change):
        table = {**GRID_TABLE, **change}
        board.write_text("[board]\n" + "".join(
            f"{k} = {v!r}\n".replace("'", '"') for k, v in table.items()))

    write()
    out = tmp_path / "cameras.toml"
    args = ["calibrate", board, *[f"--camera={c.name}={tmp_path / c.name}" for c in cams],
            "-o", out, "--restarts", "2", "--distortion", "4"]
    assert cli(*args) == 0
    text = capsys.readouterr().out
    assert "board: aruco grid 5x4 markers of 30 mm, 6 mm apart" in text
    assert abs(float(re.search(r"marker size: ([\d.]+) mm measured", text)[1]) - 30) < 0.05
    median = float(re.search(r"^all +\d+ +([\d.]+)", text, re.M)[1])
    assert median < 0.1  # sub-pixel corners, through lens distortion
    got = load_camera_file(out)
    _check_recovered(argparse.Namespace(cameras=list(got.cameras.values())), cams, 5.0, 0.01)
    for change, described in (({"markers": [4, 3]}, "aruco grid 4x3 markers"),
                              ({"markers": [4, 5]}, "aruco grid 4x5 markers"),
                              ({"dictionary": "5X5_50"}, "dictionary 5X5_50")):
        write(**change)
        assert cli(*args) == 1
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1, err
        assert f"{tmp_path / 'cam0'}: --camera cam0: no aruco grid " in err and described in err
        assert "check the board config (markers along x and y, dictionary)" in err


def test_command_errors_are_one_line(tmp_path, capsys):
    board = tmp_path / "board.toml"
    board.write_text('[board]\ntype = "checkerboard"\nsquares = [8, 6]\nsquare_mm = 30\n')
    cases = [
        (["--camera", "a"], "expected NAME=PATH"),
        (["--camera", f"a={tmp_path}/x*.png", "--camera", f"a={tmp_path}"], "given twice"),
        (["--camera", f"a={board}", "--camera", f"b={board}", "-o", board],
         "an output never replaces an input"),
        (["--camera", f"a={tmp_path}/none", "--camera", f"b={tmp_path}/none"],
         "no such file"),
        (["--camera", f"a={tmp_path}/none"], "give two or more"),
    ]
    for extra, message in cases:
        argv = ["calibrate", board, *extra]
        if "-o" not in extra:
            argv += ["-o", tmp_path / "out.toml"]
        assert cli(*argv) == 1
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "out.toml").exists()


def test_intrinsics_only_needs_no_shared_views():
    cams = rig(2)
    corners, _ = projected_corners(CHARUCO, cams, noise=0.2)
    corners[1] = Corners("cam1", corners[1].size, corners[1].frames[:15],
                         corners[1].uv[:15].copy(), corners[1].labels[:15])  # fewer views
    cal = calibrate(corners, CHARUCO.object_points, Options(intrinsics_only=True, n_dist=4))
    for got, want in zip(cal.cameras, cams, strict=True):
        assert np.allclose(np.diag(got.K)[:2], np.diag(want.K)[:2], rtol=0.01)
        assert np.allclose(got.t, 0) and np.allclose(got.R, np.eye(3))
    assert np.nanmedian(cal.errors) < 0.4


def test_checkerboard_views_turned_between_cameras_are_matched():
    cams = rig(3)
    corners, _ = projected_corners(CHECKER, cams, noise=0.2, seed=7)
    seen = np.all(np.isfinite(corners[2].uv[..., 0]), axis=1)
    turned = np.flatnonzero(seen)[::3]
    corners[2].uv[turned] = corners[2].uv[turned, ::-1]  # as OpenCV may order a half-turn
    cal = calibrate(corners, CHECKER.object_points, Options(restarts=1, n_dist=4,
                                                            symmetric=True))
    _check_recovered(cal, cams, 5.0, 0.01)
    assert np.nanpercentile(cal.errors, 99) < 1.5


def test_world_frame_on_a_board_view():
    from videotrack.calibration.bundle import reframe

    cams = rig(2)
    corners, _ = projected_corners(CHARUCO, cams, noise=0.0)
    cal = calibrate(corners, CHARUCO.object_points, Options(restarts=1, n_dist=4))
    view = int(np.flatnonzero(np.all(np.isfinite(cal.board_poses), axis=1))[0])
    moved = reframe(cal, view)
    # the board's corners, in the new world, are the board's own coordinates
    for cam, c in zip(moved, corners, strict=True):
        seen = np.isfinite(c.uv[view, :, 0])
        assert np.allclose(cam.project(CHARUCO.object_points[seen]), c.uv[view, seen],
                           atol=1e-5)
    with pytest.raises(VideoTrackError, match="--world-view: view 999 has no board pose"):
        reframe(cal, 999)


def test_refinement_from_animal_points_recovers_poses():
    from videotrack.calibration.refine import refine_extrinsics

    def angle(a, b):
        return np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1, 1)))

    cams = in_reference_frame(rig(3))
    rng = np.random.default_rng(3)
    X = rng.normal(0, 80, (200, 3)) + np.array([0, 80, 500.0])  # markers where cameras look
    uv = np.array([c.project(X) for c in cams])
    def bumped(c, turn, shift):  # turned about its centre, the centre moved by ``shift``
        R = rodrigues(turn) @ c.R
        return PinholeCamera(c.name, c.K, c.dist, R=R, t=-R @ (c.centre + shift),
                             size=c.image_size)

    # bumped mounts: turned by about 1°, moved by about 1 mm
    nudged = [cams[0]] + [bumped(c, rng.normal(0, 0.02, 3), rng.normal(0, 0.7, 3))
                          for c in cams[1:]]
    got, errors, change = refine_extrinsics(nudged, uv)  # exact points
    for g, n, w in zip(got[1:], nudged[1:], cams[1:], strict=True):
        assert angle(g, w) < angle(n, w) / 10, g.name
    assert np.nanmedian(errors) < 0.05
    assert set(change.moved) == {c.name for c in cams} and change.moved[cams[0].name] < 1e-9
    uv = uv + rng.normal(0, 0.3, uv.shape)
    uv[rng.random((3, 200)) < 0.15] = np.nan  # occlusions
    uv[:, :10] += rng.uniform(-40, 40, (3, 10, 2))  # mistracked points
    got, errors, _ = refine_extrinsics(nudged, uv)
    for g, n, w in zip(got[1:], nudged[1:], cams[1:], strict=True):
        assert angle(g, w) < min(0.3, angle(n, w) / 3), g.name
    assert np.nanmedian(errors[:, 10:]) < 0.4 and np.nanmedian(errors[:, :10]) > 5
    # a camera moved far (not a bump): only a freed rig follows it
    moved = [cams[0], bumped(cams[1], rng.normal(0, 0.02, 3), np.array([40.0, 0, 0])),
             cams[2]]
    exact = np.array([c.project(X) for c in cams])
    got, _, change = refine_extrinsics(moved, exact, free_rig=True)
    assert angle(got[1], cams[1]) < 0.05
    assert any(abs(after / before - 1) > 0.01 for *_, before, after in change.baselines)


def test_refinement_keeps_the_mouse_rig_or_refuses():
    """The sleap-anipose mouse rig (shared data) refined from its SLEAP keypoints: the
    freed rig's baselines move by up to 66 % (mid-top 209.5 -> 72.1 mm) for a lower
    reprojection error; held, the change is refused with the camera named."""
    import h5py

    from videotrack.calibration.formats import read_cameras
    from videotrack.calibration.refine import refine_extrinsics

    folder = SHARED_DATA / "sleap_anipose_mouse4cam"
    if not folder.is_dir():
        pytest.skip("shared data absent")
    cams = [c for c in read_cameras(folder / "calibration.toml").values()
            if c.name in ("back", "mid", "top")]  # 'side' is wrong in the file
    p2d = np.array([np.transpose(h5py.File(folder / c.name /
                                           f"minimal_{c.name}_proofread.analysis.h5")
                                 ["tracks"][0], (2, 1, 0)).reshape(-1, 2) for c in cams])
    with pytest.raises(VideoTrackError, match=r"refinement refused: camera (mid|top) would "
                                              r"turn by [\d.]+°.*--free-rig"):
        refine_extrinsics(cams, p2d)
    _, _, change = refine_extrinsics(cams, p2d, free_rig=True)
    *_, rel = change.worst_baseline()
    assert abs(rel) > 0.3 and "mid-top" in "\n".join(change.lines())


def test_schur_step_gives_the_dense_solution(monkeypatch):
    from videotrack.calibration import bundle_adjust

    cams = rig(2)
    corners, _ = projected_corners(CHARUCO, cams, n_views=8, noise=0.3)
    dense = calibrate(corners, CHARUCO.object_points, Options(restarts=1, n_dist=4))
    monkeypatch.setattr(bundle_adjust, "_DENSE_MAX", 0)  # as for hundreds of views
    schur = calibrate(corners, CHARUCO.object_points, Options(restarts=1, n_dist=4))
    for a, b in zip(dense.cameras, schur.cameras, strict=True):
        assert np.allclose(a.K, b.K, rtol=1e-6) and np.allclose(a.t, b.t, atol=1e-4)


def test_command_refines_an_imported_calibration(tmp_path, capsys):
    from kinematics.cameras.files import load_cameras, save_cameras

    cams = in_reference_frame(rig(3))
    rng = np.random.default_rng(4)
    X = rng.normal(0, 80, (150, 3)) + np.array([0, 80, 500.0])
    p2d = np.array([c.project(X) for c in cams]) + rng.normal(0, 0.2, (3, 150, 2))
    np.savez(tmp_path / "points.npz", p2d=p2d)
    nudged = [cams[0]] + [PinholeCamera(c.name, c.K, c.dist, R=rodrigues(rng.normal(0, 0.02, 3))
                                        @ c.R, t=c.t, size=c.image_size) for c in cams[1:]]
    save_cameras(tmp_path / "rough.toml", nudged, units="mm")
    assert cli("calibrate", "--import", tmp_path / "rough.toml", "--refine-points",
               tmp_path / "points.npz", "-o", tmp_path / "fine.toml") == 0
    before, after = (float(x) for x in re.findall(r"([\d.]+) px (?:before|after)",
                                                  capsys.readouterr().out))
    assert before > 2 and after < 0.4
    assert set(load_cameras(tmp_path / "fine.toml")) == {"cam0", "cam1", "cam2"}
    np.savez(tmp_path / "bad.npz", xy=p2d)
    assert cli("calibrate", "--import", tmp_path / "rough.toml", "--refine-points",
               tmp_path / "bad.npz", "-o", tmp_path / "fine.toml") == 1
    assert "bad.npz: no array 'p2d'" in capsys.readouterr().err


def test_command_intrinsics_only_from_unsynchronised_images(tmp_path, capsys):
    cams = rig(2, dist=(-0.1, 0.05, 0, 0))
    _render_folder(tmp_path / "a", CHECKER, cams[:1], 5, seed=1)
    _render_folder(tmp_path / "b", CHECKER, cams[1:], 4, seed=2)
    board = tmp_path / "board.toml"
    board.write_text('[board]\ntype = "checkerboard"\nsquares = [8, 6]\nsquare_mm = 30\n')
    assert cli("calibrate", board, f"--camera=cam0={tmp_path}/a/cam0/*.png",
               f"--camera=cam1={tmp_path / 'b' / 'cam1'}", "--intrinsics-only",
               "--distortion", "4", "-o", tmp_path / "k.toml", "--report-png",
               tmp_path / "k.png") == 0
    from kinematics.cameras.files import load_cameras

    got = load_cameras(tmp_path / "k.toml")
    for cam in cams:
        assert np.allclose(got[cam.name].K, cam.K, rtol=0.02, atol=3)
    assert "cam1" in capsys.readouterr().out


def test_import_names_identical_cameras(tmp_path, capsys):
    from kinematics.cameras.files import save_cameras

    cams = rig(3)
    copy = PinholeCamera("cam3", cams[2].K, cams[2].dist, R=cams[2].R, t=cams[2].t,
                         size=cams[2].image_size)
    save_cameras(tmp_path / "four.toml", [*cams, copy])
    assert cli("calibrate", "--import", tmp_path / "four.toml", "-o", tmp_path / "out.toml") == 0
    err = capsys.readouterr().err
    assert "warning: cameras cam2 and cam3 are identical" in err


def test_triangulate_names_the_wrong_camera_of_the_mouse_rig(tmp_path, capsys):
    """The shipped calibration of the sleap-anipose rig has 'side' a copy of 'top' (shared
    data): triangulation names both, and 'side' by its errors."""
    from videotrack.cli import main

    folder = SHARED_DATA / "sleap_anipose_mouse4cam"
    if not folder.is_dir():
        pytest.skip("shared data absent")
    views = [f"{v}={folder / v / f'minimal_{v}_proofread.analysis.h5'}"
             for v in ("back", "mid", "side", "top")]
    assert main(["triangulate", str(folder / "calibration.toml"), *views, "-o",
                 str(tmp_path / "p3d.csv")]) == 0
    out, err = capsys.readouterr()
    assert re.search(r"per camera: back [\d.]+ px, mid [\d.]+ px, side [\d.]+ px", out)
    assert "cameras side and top are identical" in err
    assert "warning: camera side reprojects with a median error of" in err
