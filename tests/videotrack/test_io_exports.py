"""Writers of 3D points and joint angles for the field's tools: OpenSim TRC and .mot, C3D,
NWB (ndx-pose, loaded by movement) and DeepLabCut files for movement; round trips and the
real files of ../shared/data where present."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from videotrack.errors import VideoTrackError
from videotrack.io.mot import read_mot, write_mot
from videotrack.io.trc import read_trc, write_trc

DATA = Path(__file__).parents[2] / ".." / "shared" / "data"
MARKERS = ("M0", "M1", "M2")
AXES = ("J0.phi", "J0.psi", "J0.alpha", "J1.beta", "J2.gamma")


def planted(n=7, seed=1):
    rng = np.random.default_rng(seed)
    points = rng.normal(0, 100, (n, len(MARKERS), 3))
    points[3, 1] = np.nan
    angles = rng.uniform(-180, 180, (n, len(AXES)))
    angles[4, 2] = np.nan
    return points, angles, np.arange(20, 20 + n)


def need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} not present")
    return path


def test_trc_round_trip(tmp_path):
    points, _, frames = planted()
    write_trc(tmp_path / "a.trc", MARKERS, points, frames, 100.0)
    back = read_trc(tmp_path / "a.trc")
    assert back.names == MARKERS and back.units == "mm" and back.rate == 100.0
    np.testing.assert_array_equal(back.frames, frames)
    np.testing.assert_allclose(back.points, points, atol=1e-6)
    lines = (tmp_path / "a.trc").read_text().splitlines()
    assert lines[3].split("\t")[:3] == ["Frame#", "Time", "M0"]
    assert lines[6].split("\t")[:2] == ["21", "0.200000"]  # 1-based frame, time in s


def test_mot_round_trip(tmp_path):
    _, angles, frames = planted()
    write_mot(tmp_path / "a.mot", AXES, angles, frames, 50.0)
    back = read_mot(tmp_path / "a.mot")
    assert back.names == AXES and back.in_degrees
    np.testing.assert_allclose(back.time, frames / 50.0, atol=1e-6)
    np.testing.assert_allclose(back.values, angles, atol=1e-6)


def test_writers_refuse_bad_input_and_leave_files_alone(tmp_path):
    points, angles, frames = planted()
    out = tmp_path / "a.trc"
    out.write_text("keep me")
    with pytest.raises(VideoTrackError, match="do not match"):
        write_trc(out, MARKERS[:2], points, frames, 100.0)
    with pytest.raises(VideoTrackError, match="rate: frame rate must be > 0"):
        write_mot(tmp_path / "b.mot", AXES, angles, frames, 0.0)
    with pytest.raises(VideoTrackError, match="column name 'a b'"):
        write_mot(tmp_path / "b.mot", ("a b", *AXES[1:]), angles, frames, 10.0)
    assert out.read_text() == "keep me" and not (tmp_path / "b.mot").exists()
    with pytest.raises(VideoTrackError, match="marker name 'M0' appears twice"):
        write_trc(tmp_path / "c.trc", ("M0", "M0", "M1"), points, frames, 100.0)
    assert [p.name for p in tmp_path.iterdir()] == ["a.trc"]  # no temporary left behind


def test_readers_give_located_errors(tmp_path):
    (tmp_path / "x.trc").write_text("hello\n")
    with pytest.raises(VideoTrackError, match=r"x\.trc:1: not a TRC file"):
        read_trc(tmp_path / "x.trc")
    (tmp_path / "x.mot").write_text("Coordinates\nendheader\ntime\ta\n0.1\tzz\n")
    with pytest.raises(VideoTrackError, match=r"x\.mot:4: not a number"):
        read_mot(tmp_path / "x.mot")


def test_real_trc_and_mot():
    gait = need(DATA / "opensim_gait2354")
    trc = read_trc(gait / "subject01_walk1.trc")
    assert trc.points.shape == (151, 41, 3) and trc.units == "mm" and trc.names[0] == "R.ASIS"
    np.testing.assert_allclose(trc.points[0, 0], [617.24762, 1055.27502, 170.78198])
    mot = read_mot(gait / "subject01_walk1_ik.mot")
    assert mot.values.shape == (73, 23) and mot.names[0] == "pelvis_tilt"
    demo = need(DATA / "pose2sim_demo" / "balancing_trial" / "pose-3d_pose2sim_output")
    p2s = read_trc(demo / "S00_P00_T01_BalancingTrial_0-100.trc")
    assert p2s.points.shape == (100, 21, 3) and p2s.units == "m"


def test_c3d_round_trip_points_and_angles(tmp_path):
    pytest.importorskip("ezc3d")
    from videotrack.io.c3d import read_c3d, write_c3d

    points, angles, frames = planted()
    angles = np.nan_to_num(angles)  # an angle point is missing only as a whole joint
    write_c3d(tmp_path / "a.c3d", MARKERS, points, frames, 200.0, angle_names=AXES,
              angles=angles)
    markers, motion = read_c3d(tmp_path / "a.c3d")
    assert markers.names == MARKERS and markers.units == "mm" and markers.rate == 200.0
    np.testing.assert_array_equal(markers.frames, frames)
    np.testing.assert_allclose(markers.points, points, rtol=1e-6, atol=1e-4)  # float32
    assert np.isnan(markers.points[3, 1]).all()
    assert motion.names == AXES
    np.testing.assert_allclose(motion.values, angles, atol=1e-4)
    with pytest.raises(VideoTrackError, match="'J0_angles' is the name of a marker"):
        write_c3d(tmp_path / "b.c3d", ("J0_angles",), points[:, :1], frames, 200.0,
                  angle_names=AXES, angles=angles)
    assert not (tmp_path / "b.c3d").exists()


def test_real_c3d():
    pytest.importorskip("ezc3d")
    from videotrack.io.c3d import read_c3d

    markers, _ = read_c3d(need(DATA / "ezc3d_c3d" / "Vicon.c3d"))
    assert markers.points.ndim == 3 and markers.points.shape[2] == 3 and markers.rate > 0
    assert np.isfinite(markers.points).any()
    with pytest.raises(VideoTrackError, match="not a readable C3D"):
        read_c3d(Path(__file__))


def test_nwb_round_trip_and_movement_loads_it(tmp_path):
    pytest.importorskip("ndx_pose")
    from videotrack.io.nwb import read_nwb, write_nwb

    points, angles, frames = planted()
    names = ("Mz", "M1", "M2")  # not in sorted order: the order must survive
    axes = AXES
    path = tmp_path / "a.nwb"
    write_nwb(path, names, points, frames, 100.0, angle_names=axes, angles=angles,
              edges=[[0, 1], [1, 2]], subject="locust1")
    markers, conf, motion = read_nwb(path)
    assert markers.names == names and motion.names == axes
    np.testing.assert_array_equal(markers.frames, frames)
    np.testing.assert_allclose(markers.points, points)
    np.testing.assert_allclose(motion.values, angles)
    assert np.isnan(conf[3, 1]) and conf[0, 0] == 1.0
    movement = pytest.importorskip("movement.io.load_poses")
    ds = movement.from_nwb_file(path)
    assert ds.attrs["fps"] == 100.0 and list(ds.individuals.values) == ["locust1"]
    for i, name in enumerate(names):
        np.testing.assert_allclose(ds.position.sel(keypoints=name, individuals="locust1"),
                                   points[:, i])


def test_movement_loads_our_dlc_files(tmp_path):
    movement = pytest.importorskip("movement.io.load_poses")
    from videotrack.io import dlc
    from videotrack.io.keypoints import make_tracks

    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 100, (5, 2, 2))
    xy[1, 0] = np.nan
    t = make_tracks(["nose", "tail"], xy, np.full((5, 2), 0.8), np.arange(5), "mem")
    for name in ("k.csv", "k.h5"):
        dlc.write(tmp_path / name, t)
        ds = movement.from_dlc_file(tmp_path / name, fps=25)
        np.testing.assert_allclose(ds.position.values[:, :, :, 0], xy.transpose(0, 2, 1))


def fitted_results(n=6):
    """A Results table as a fit leaves it: 2 markers, 1 joint, 2 axes, one failed row."""
    from videotrack.results.files import Results

    rng = np.random.default_rng(4)
    return Results(
        axis_labels=("J0.phi", "J1.beta"), view_names=("side",), chain_names=("leg",),
        marker_names=("M0", "M1"), joint_names=("J1",), frames=np.arange(n),
        video_frames=np.arange(n), fields=np.full(n, -1), times=np.arange(n) / 25.0,
        angles_deg=rng.uniform(-90, 90, (n, 2)), error=np.zeros(n),
        error_per_view=np.zeros((n, 1)), runs=np.ones(n, int), iterations=np.ones(n, int),
        status=("ok",) * (n - 1) + ("failed",), roots=np.zeros((n, 1, 3)),
        markers=rng.normal(0, 50, (n, 2, 3)), joints=rng.normal(0, 50, (n, 1, 3)))


@pytest.mark.parametrize("suffix", [".trc", ".mot", ".c3d", ".nwb"])
def test_export_results(tmp_path, suffix):
    from videotrack.io.export import export_results

    if suffix == ".c3d":
        pytest.importorskip("ezc3d")
    if suffix == ".nwb":
        pytest.importorskip("ndx_pose")
    res = fitted_results()
    path = export_results(res, tmp_path / f"walk{suffix}")
    points = np.concatenate([res.markers, res.joints], axis=1)
    if suffix == ".trc":
        got = read_trc(path)
        assert got.names == ("M0", "M1", "J1") and got.rate == 25.0
        np.testing.assert_allclose(got.points[:5], points[:5], atol=1e-6)
        assert np.isnan(got.points[5]).all()  # the failed row
    elif suffix == ".mot":
        got = read_mot(path)
        np.testing.assert_allclose(got.values[:5], res.angles_deg[:5], atol=1e-6)
        assert np.isnan(got.values[5]).all()
    elif suffix == ".c3d":
        from videotrack.io.c3d import read_c3d

        markers, motion = read_c3d(path)
        np.testing.assert_allclose(markers.points[:5], points[:5], atol=1e-4)
        np.testing.assert_allclose(motion.values[:5], res.angles_deg[:5], atol=1e-4)
        assert np.isnan(motion.values[5]).all() and np.isnan(markers.points[5]).all()
    else:
        from videotrack.io.nwb import read_nwb

        markers, _, motion = read_nwb(path)
        np.testing.assert_allclose(markers.points[:5], points[:5])
        np.testing.assert_allclose(motion.values[:5], res.angles_deg[:5])


def test_results_keep_their_sd_through_the_csv_and_into_mot_and_nwb(tmp_path):
    """The ``.sd`` columns round-trip through the results CSV; a ``.mot`` export carries them
    as columns ``<axis>.sd``, an NWB export as ``JointAngleSD`` (a failed row's empty, as
    its angles)."""
    from dataclasses import replace

    from videotrack.io.export import export_results
    from videotrack.results.files import frame_results, read_results, write_results

    res = fitted_results()
    res = replace(res, sd=np.abs(res.angles_deg) / 100.0)
    path = write_results(tmp_path / "walk.results.csv", res, {"seed": 0})
    header = path.read_text().splitlines()[0].split(",")
    assert header[header.index("status") - 2:header.index("status")] == ["J0.phi.sd",
                                                                         "J1.beta.sd"]
    back = read_results(path)
    np.testing.assert_array_equal(back.sd, res.sd)
    np.testing.assert_array_equal(frame_results(back, 0)[2].sd_deg, res.sd[2])
    older = replace(res, sd=None)  # a file without the columns reads as before
    assert read_results(write_results(tmp_path / "old.results.csv", older, {})).sd is None
    from videotrack.io.mot import read_mot

    motion = read_mot(export_results(res, tmp_path / "walk.mot"))  # .mot: columns of their own
    assert motion.names == ("J0.phi", "J1.beta", "J0.phi.sd", "J1.beta.sd")
    np.testing.assert_allclose(motion.values[:5, 3], res.sd[:5, 1], atol=1e-6)
    assert np.isnan(motion.values[5, 3])  # a failed row's, as its angles
    pytest.importorskip("ndx_pose")
    import pynwb

    nwb = export_results(res, tmp_path / "walk.nwb")
    with pynwb.NWBHDF5IO(str(nwb), mode="r") as io:
        group = io.read().processing["behavior"]["JointAngleSD"]
        got = np.asarray(group["J1.beta"].data[:])
    np.testing.assert_allclose(got[:5], res.sd[:5, 1])
    assert np.isnan(got[5])


def test_export_refuses_unknown_suffix(tmp_path):
    from videotrack.io.export import export_results

    with pytest.raises(VideoTrackError, match=r"walk\.xyz: unknown export type '\.xyz'"):
        export_results(fitted_results(), tmp_path / "walk.xyz")
