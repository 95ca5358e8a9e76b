"""Synthetic marker videos: projections, occlusions, ghosts, interlacing, lossless output."""

import cv2
import numpy as np
import pytest

from kinematics.model.fk import forward_kinematics
from videotrack.errors import VideoTrackError
from videotrack.results.tables import read_table, write_table
from videotrack.synth.motion import smooth_random_motion
from videotrack.synth.paper_setup import VIEW_SIZE, locust_cameras
from videotrack.synth.project import (
    SynthOptions,
    VideoSink,
    iter_frames,
    simulate,
    truth_columns,
    truth_table,
    view_rois,
)


@pytest.fixture
def scene_inputs(locust):
    return locust, locust_cameras(), smooth_random_motion(locust, 40, 2, seed=5)


def test_projections_are_the_cameras_view_of_fk(scene_inputs):
    body, cams, angles = scene_inputs
    scene = simulate(body, cams, angles, SynthOptions())
    markers = forward_kinematics(body, angles).markers
    for v, cam in enumerate(cams.values()):
        np.testing.assert_allclose(scene.projections[:, v], cam.project(markers))
    assert scene.visible.all() and scene.ghosts.shape[2] == 0


def test_motion_stays_in_ranges_and_is_smooth(locust):
    a = smooth_random_motion(locust, 668, 10, seed=1)
    lo, hi = locust.ranges_deg().T
    assert a.shape == (668, 9) and np.all(a >= lo) and np.all(a <= hi)
    steps = np.abs(np.diff(a, axis=0))
    cuts = np.linspace(0, 668, 11).round().astype(int)[1:-1] - 1
    within = np.delete(steps, cuts, axis=0)
    assert within.max() < 15.0  # smooth inside a sequence
    np.testing.assert_array_equal(a, smooth_random_motion(locust, 668, 10, seed=1))


def test_occlusion_fraction_and_ghosts(scene_inputs):
    body, cams, _ = scene_inputs
    angles = smooth_random_motion(body, 2000, 4, seed=2)
    opts = SynthOptions(occlusion_fraction=0.02, occlusion_length=3, static_ghosts=2,
                        flicker_ghosts=3, flicker_probability=0.5, seed=9)
    scene = simulate(body, cams, angles, opts)
    hidden = 1 - scene.visible.mean()
    assert 0.01 < hidden < 0.03
    # static ghosts never move or vanish; flickering ones are on about half the time
    assert np.all(scene.ghosts[:, :, :2] == scene.ghosts[:1, :, :2])
    on = np.isfinite(scene.ghosts[:, :, 2:, 0]).mean()
    assert 0.45 < on < 0.55


def test_rendered_markers_sit_at_their_projections(scene_inputs):
    body, cams, angles = scene_inputs
    opts = SynthOptions(marker_diameter=4.0)
    scene = simulate(body, cams, angles[:3], opts)
    sizes = [VIEW_SIZE, VIEW_SIZE]
    frames = list(iter_frames(scene, sizes, opts))
    assert len(frames) == 3 and frames[0][0].shape == (288, 720)
    rois = view_rois(sizes, "side-by-side")
    img = frames[0][0].astype(float) - opts.background
    for v, (x0, y0, _, _) in enumerate(rois):
        for p in scene.projections[0, v]:
            cx, cy = round(p[0]) + x0, round(p[1]) + y0
            win = img[cy - 4:cy + 5, cx - 4:cx + 5]
            ys, xs = np.mgrid[cy - 4:cy + 5, cx - 4:cx + 5]
            centroid = np.array([(win * xs).sum(), (win * ys).sum()]) / win.sum()
            np.testing.assert_allclose(centroid, p + np.array([x0, y0]), atol=0.1)


def test_interlaced_fields_hold_consecutive_postures(scene_inputs):
    body, cams, angles = scene_inputs
    opts = SynthOptions(interlaced=True)
    scene = simulate(body, cams, angles[:4], opts)
    sizes = [VIEW_SIZE, VIEW_SIZE]
    inter = list(iter_frames(scene, sizes, opts))
    full = list(iter_frames(scene, sizes, SynthOptions()))
    assert len(inter) == 2
    np.testing.assert_array_equal(inter[1][0][0::2], full[2][0][0::2])  # top field: t = 2
    np.testing.assert_array_equal(inter[1][0][1::2], full[3][0][1::2])  # bottom field: t = 3
    with pytest.raises(VideoTrackError, match="even number"):
        simulate(body, cams, angles[:3], opts)


@pytest.mark.parametrize("codec", ["ffv1", "png"])
def test_video_sink_is_lossless_and_atomic(tmp_path, codec):
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (48, 64), dtype=np.uint8) for _ in range(5)]
    target = tmp_path / ("v.avi" if codec == "ffv1" else "v_png")
    with VideoSink(target, 25, codec) as sink:
        for f in frames:
            sink.write(f)
        sink.commit()
    assert [p.name for p in tmp_path.iterdir()] == [target.name]
    if codec == "ffv1":
        cap = cv2.VideoCapture(str(target))
        back = []
        ok, f = cap.read()
        while ok:
            back.append(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) if f.ndim == 3 else f)
            ok, f = cap.read()
    else:
        back = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted(target.iterdir())]
    assert len(back) == 5
    for a, b in zip(frames, back, strict=True):
        np.testing.assert_array_equal(a, b)


def test_interrupted_sink_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError), VideoSink(tmp_path / "v.avi", 25) as sink:
        sink.write(np.zeros((16, 16), np.uint8))
        raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []


def test_truth_table_round_trips(tmp_path, scene_inputs):
    body, cams, angles = scene_inputs
    scene = simulate(body, cams, angles, SynthOptions(occlusion_fraction=0.1, seed=1))
    cols = truth_columns(body, scene.view_names)
    table = truth_table(scene)
    assert table.shape == (40, len(cols)) and "side.M3.u" in cols and "J0.phi" in cols
    write_table(tmp_path / "truth.csv", cols, table)
    cols2, table2 = read_table(tmp_path / "truth.csv")
    assert cols2 == cols
    np.testing.assert_array_equal(table2, table)


def test_bad_options_name_the_field(scene_inputs):
    body, cams, angles = scene_inputs
    with pytest.raises(VideoTrackError, match="occlusion_fraction"):
        simulate(body, cams, angles, SynthOptions(occlusion_fraction=1.5))
    with pytest.raises(VideoTrackError, match="layout"):
        simulate(body, cams, angles, SynthOptions(layout="diagonal"))
