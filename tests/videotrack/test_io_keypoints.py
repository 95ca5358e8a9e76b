"""The keypoint façade and its readers: DeepLabCut, SLEAP, OpenPose, Lightning Pose, Anipose.

Every reader is tested on small files written here in the real formats (DLC's multi-row CSV
headers and pandas h5, SLEAP via sleap-io and the analysis h5 layout, OpenPose JSON) and on
the real files of ../shared/data where present.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.fixtures.keypoint_files import (
    PARTS,
    planted_tracks,
    write_analysis_h5,
    write_dlc_csv,
    write_dlc_h5,
    write_openpose,
)
from videotrack.errors import VideoTrackError
from videotrack.io.keypoints import (
    align_cameras,
    detect_format,
    make_tracks,
    map_to_markers,
    read_keypoints,
    read_npz,
    write_npz,
)

DATA = Path(__file__).parents[2] / ".." / "shared" / "data"
# -- DeepLabCut --------------------------------------------------------------------------------


def test_dlc_csv_single_animal(tmp_path):
    xy, score = planted_tracks()
    t = read_keypoints(write_dlc_csv(tmp_path / "a.csv", xy, score, frames=range(10, 16)))
    assert t.names == PARTS and t.frames.tolist() == list(range(10, 16))
    np.testing.assert_allclose(t.xy, xy)
    np.testing.assert_allclose(t.score, score)
    assert t.missing[2, 1] and t.missing.sum() == 1


def test_dlc_csv_multi_animal_chooses_individual_and_keeps_others_as_candidates(tmp_path):
    xy, score = planted_tracks(k=3)
    xy2 = np.stack([xy, xy + 100.0], axis=1)  # (n, 2 animals, k, 2)
    s2 = np.stack([score, score / 2], axis=1)
    path = write_dlc_csv(tmp_path / "ma.csv", xy2, s2, individuals=["mouse1", "mouse2"])
    first = read_keypoints(path)
    assert first.individual == "mouse1"
    np.testing.assert_allclose(first.xy, xy)
    second = read_keypoints(path, individual="mouse2")
    np.testing.assert_allclose(second.xy, xy + 100.0)
    np.testing.assert_allclose(read_keypoints(path, individual=1).score, score / 2)
    assert first.candidates.shape == (6, 1, 3, 3)
    np.testing.assert_allclose(first.candidates[:, 0, :, :2], xy + 100.0)
    with pytest.raises(VideoTrackError, match=r"no individual 'rat'.*mouse1, mouse2"):
        read_keypoints(path, individual="rat")


def test_dlc_hand_labels_without_likelihood_score_one(tmp_path):
    xy, score = planted_tracks()
    t = read_keypoints(write_dlc_csv(tmp_path / "CollectedData_me.csv", xy, score,
                                     likelihood=False))
    assert np.all(t.score[~t.missing] == 1.0) and np.isnan(t.score[2, 1])


def test_dlc_csv_with_three_index_columns(tmp_path):
    """DeepLabCut >= 2.3 hand labels: labeled-data, video, image name as three index columns."""
    xy, score = planted_tracks(n=3)
    path = write_dlc_csv(tmp_path / "CollectedData_me.csv", xy, score, likelihood=False)
    lines = path.read_text().splitlines()
    lines = [line.replace(",", ",,,", 1) for line in lines[:3]] + [
        f"labeled-data,m4s1,img{10 * i:04d}.png," + line.split(",", 1)[1]
        for i, line in enumerate(lines[3:])]
    path.write_text("\n".join(lines) + "\n")
    t = read_keypoints(path)
    assert t.frames.tolist() == [0, 10, 20]
    np.testing.assert_allclose(t.xy, xy)
    assert t.images  # labelled images, not a video: temporal filters are refused
    from videotrack.markerless.filters import KeypointFilterSettings, apply_filters

    for settings, what in ((KeypointFilterSettings(median=3), "median filter"),
                           (KeypointFilterSettings(viterbi=True), "Viterbi filter")):
        with pytest.raises(VideoTrackError, match=f"the {what} needs a video's consecutive "
                                                  "frames, and these rows are labelled images"):
            apply_filters(t, settings)
    assert apply_filters(t, KeypointFilterSettings(score_threshold=0.5)).n_frames == 3
    assert not read_keypoints(write_dlc_csv(tmp_path / "video.csv", xy, score)).images


def test_dlc_h5_matches_csv(tmp_path):
    xy, score = planted_tracks()
    h5 = read_keypoints(write_dlc_h5(tmp_path / "a.h5", xy, score))
    assert detect_format(tmp_path / "a.h5") == "dlc"
    np.testing.assert_allclose(h5.xy, xy)
    np.testing.assert_allclose(h5.score, score)
    # an Anipose pose-2d file is a DeepLabCut h5
    np.testing.assert_array_equal(read_keypoints(tmp_path / "a.h5", "anipose").xy, h5.xy)


def test_dlc_write_round_trip_csv_and_h5(tmp_path):
    from videotrack.io import dlc

    xy, score = planted_tracks()
    t = make_tracks(PARTS, xy, score, np.arange(3, 9), "mem")
    for name in ("out.csv", "out.h5"):
        dlc.write(tmp_path / name, t)
        back = read_keypoints(tmp_path / name)
        np.testing.assert_array_equal(back.frames, t.frames)
        np.testing.assert_allclose(back.xy, t.xy)
        np.testing.assert_allclose(back.score, t.score)


def test_dlc_bad_files_give_located_errors(tmp_path):
    xy, score = planted_tracks()
    path = write_dlc_csv(tmp_path / "bad.csv", xy, score)
    lines = path.read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[2], "abc", 1)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(VideoTrackError) as err:
        read_keypoints(path)
    assert str(err.value) == f"{path}:6: snout y: not a number: 'abc'"
    (tmp_path / "short.csv").write_text("scorer,a,a\nbodyparts,p,p\ncoords,x,y\n0,1\n")
    with pytest.raises(VideoTrackError, match=r"short\.csv:4: 2 columns, the header has 3"):
        read_keypoints(tmp_path / "short.csv")
    (tmp_path / "other.csv").write_text("a,b\n1,2\n")
    with pytest.raises(VideoTrackError, match=r"other\.csv:1: not a DeepLabCut CSV"):
        read_keypoints(tmp_path / "other.csv")
    (tmp_path / "junk.h5").write_bytes(b"not hdf5 at all")
    with pytest.raises(VideoTrackError, match=r"junk\.h5: not a DeepLabCut h5"):
        read_keypoints(tmp_path / "junk.h5")


def test_lightning_pose_csv(tmp_path):
    xy, score = planted_tracks()
    path = write_dlc_csv(tmp_path / "predictions.csv", xy, score)
    path.write_text(path.read_text().replace("DLC_resnet50", "heatmap_mhcrnn_tracker"))
    assert detect_format(path) == "lightning-pose"
    np.testing.assert_allclose(read_keypoints(path).xy, xy)


# -- SLEAP -------------------------------------------------------------------------------------


def test_sleap_slp_written_with_sleap_io(tmp_path):
    sio = pytest.importorskip("sleap_io")
    xy, score = planted_tracks(n=5, k=3)
    skeleton = sio.Skeleton(list(PARTS))
    video = sio.Video(filename=str(tmp_path / "cam.mp4"))
    tracks = [sio.Track("mouse_a"), sio.Track("mouse_b")]
    frames = []
    for f in range(5):
        insts = [sio.PredictedInstance.from_numpy(
            np.concatenate([xy[f] + 50.0 * j, score[f][:, None]], axis=1)[:, :2],
            skeleton=skeleton, point_scores=np.nan_to_num(score[f]), score=1.0,
            track=tracks[j]) for j in range(2)]
        frames.append(sio.LabeledFrame(video=video, frame_idx=f, instances=insts))
    sio.save_slp(sio.Labels(frames, videos=[video], skeletons=[skeleton], tracks=tracks),
                 str(tmp_path / "cam.slp"))
    t = read_keypoints(tmp_path / "cam.slp", individual="mouse_b")
    assert t.names == PARTS and t.individual == "mouse_b"
    np.testing.assert_allclose(t.xy, xy[:5] + 50.0)
    np.testing.assert_allclose(t.score[~t.missing], score[~t.missing], rtol=1e-6)
    np.testing.assert_allclose(t.candidates[:, 0, :, :2], xy, rtol=1e-6)


def test_sleap_slp_untracked_instances(tmp_path):
    sio = pytest.importorskip("sleap_io")
    xy, _ = planted_tracks(n=3, k=3)
    skeleton = sio.Skeleton(list(PARTS))
    video = sio.Video(filename=str(tmp_path / "cam.mp4"))
    frames = [sio.LabeledFrame(video=video, frame_idx=f, instances=[
        sio.Instance.from_numpy(xy[f], skeleton=skeleton)]) for f in (0, 2)]
    sio.save_slp(sio.Labels(frames, videos=[video], skeletons=[skeleton]),
                 str(tmp_path / "user.slp"))
    t = read_keypoints(tmp_path / "user.slp")
    assert t.individual == "instance0" and t.n_frames == 3
    np.testing.assert_allclose(t.xy[[0, 2]], xy[[0, 2]])
    assert t.missing[1].all()  # frame 1 was not labelled
    assert np.all(t.score[~t.missing] == 1.0)  # hand labels are certain


def test_sleap_analysis_h5(tmp_path):
    xy, score = planted_tracks()
    path = write_analysis_h5(tmp_path / "cam.analysis.h5", xy, score)
    assert detect_format(path) == "sleap"
    t = read_keypoints(path, crop_offset=(100, 20), frame_offset=50)
    np.testing.assert_allclose(t.xy, xy + np.array([100.0, 20.0]))
    np.testing.assert_allclose(t.score, score)
    assert t.frames.tolist() == list(range(50, 56))
    with pytest.raises(VideoTrackError, match="track 3 out of range"):
        read_keypoints(path, individual=3)


# -- OpenPose ----------------------------------------------------------------------------------


def test_openpose_chooses_person(tmp_path):
    rng = np.random.default_rng(2)
    small = np.concatenate([rng.uniform(0, 20, (18, 2)), np.full((18, 1), 0.9)], axis=1)
    big = np.concatenate([rng.uniform(100, 400, (18, 2)), np.full((18, 1), 0.5)], axis=1)
    big[3] = 0  # not detected
    folder = write_openpose(tmp_path / "cam1_json", [[small, big], [big, small], [small]])
    t = read_keypoints(folder)  # default: the largest person
    assert t.names[:2] == ("Nose", "Neck") and len(t.names) == 18  # COCO by count
    np.testing.assert_allclose(t.xy[0], np.where(big[:, 2:] > 0, big[:, :2], np.nan))
    assert t.missing[0, 3] and t.missing[0].sum() == 1
    np.testing.assert_allclose(t.xy[2], small[:, :2])  # the only person
    conf = read_keypoints(folder, individual="confident")
    np.testing.assert_allclose(conf.xy[:2], small[None, :, :2].repeat(2, 0))
    by_index = read_keypoints(folder, individual=1)
    np.testing.assert_allclose(by_index.xy[1], small[:, :2])
    assert by_index.missing[2].all()  # frame 2 has no second person
    assert by_index.candidates is not None


def test_openpose_bad_files(tmp_path):
    folder = write_openpose(tmp_path / "j", [[np.ones((25, 3))]])
    (folder / "cam1.0001.json").write_text('{"people": [\n  {"pose_keypoints_2d": [1, 2]}]}')
    with pytest.raises(VideoTrackError, match=r"cam1\.0001\.json: people\[0\]: "):
        read_keypoints(folder)
    (folder / "cam1.0001.json").write_text('{"people": [\n oops')
    with pytest.raises(VideoTrackError, match=r"cam1\.0001\.json:2: not JSON"):
        read_keypoints(folder)
    (folder / "cam1.0001.json").unlink()
    with pytest.raises(VideoTrackError, match="model COCO has 18 keypoints, the files have 25"):
        read_keypoints(folder, model="coco")


# -- the façade: alignment, markers, offsets, npz ------------------------------------------


def test_align_cameras_on_union_of_frames():
    xy, score = planted_tracks()
    a = make_tracks(PARTS, xy, score, np.arange(0, 6), "a")
    b = make_tracks(PARTS[::-1], xy[:3, ::-1], score[:3, ::-1], [4, 6, 8], "b")
    names, frames, axy, ascore = align_cameras({"left": a, "right": b})
    assert names == PARTS and frames.tolist() == [0, 1, 2, 3, 4, 5, 6, 8]
    assert axy.shape == (2, 8, 3, 2) and ascore.shape == (2, 8, 3)
    np.testing.assert_allclose(axy[0, :6], xy)
    assert np.isnan(axy[0, 6:]).all()
    np.testing.assert_allclose(axy[1, [4, 6, 7]], xy[:3])  # names reordered back
    assert np.isnan(axy[1, :4]).all()
    names, _, sub, _ = align_cameras({"left": a, "right": b}, names=["tail"])
    np.testing.assert_allclose(sub[0, :6, 0], xy[:, 2])
    with pytest.raises(VideoTrackError, match="no camera has keypoint"):
        align_cameras({"left": a}, names=["paw"])


def test_map_to_markers():
    xy, score = planted_tracks()
    t = make_tracks(PARTS, xy, score, np.arange(6), "a.h5")
    mxy, mscore = map_to_markers(t, ["M0", "M1", "M2", "M3"], {"tail": "M0", "snout": "M2"})
    np.testing.assert_allclose(mxy[:, 0], xy[:, 2])
    np.testing.assert_allclose(mxy[:, 2], xy[:, 0])
    assert np.isnan(mxy[:, [1, 3]]).all() and np.isnan(mscore[:, 1]).all()
    same, _ = map_to_markers(t, ["ear", "x"])  # no mapping: same names
    np.testing.assert_allclose(same[:, 0], xy[:, 1])
    with pytest.raises(VideoTrackError, match=r"a\.h5: keypoints\.markers: keypoint 'paw'"):
        map_to_markers(t, ["M0"], {"paw": "M0"})
    with pytest.raises(VideoTrackError, match="marker 'M9'"):
        map_to_markers(t, ["M0"], {"tail": "M9"})
    with pytest.raises(VideoTrackError, match="no keypoint maps"):
        map_to_markers(t, ["M0"])


def test_npz_round_trip(tmp_path):
    xy, score = planted_tracks()
    cams = {"a": make_tracks(PARTS, xy, score, np.arange(6), "a"),
            "b": make_tracks(PARTS, xy + 1, score, np.arange(2, 8), "b")}
    write_npz(tmp_path / "k.npz", cams)
    back = read_npz(tmp_path / "k.npz")
    assert list(back) == ["a", "b"]
    np.testing.assert_allclose(back["b"].xy[2:], xy + 1)
    assert back["a"].frames.tolist() == list(range(8))


def test_unknown_files(tmp_path):
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(VideoTrackError, match=r"x\.txt: unknown keypoint file type"):
        read_keypoints(tmp_path / "x.txt")
    with pytest.raises(VideoTrackError, match="no such keypoint file"):
        read_keypoints(tmp_path / "none.h5")
    with pytest.raises(VideoTrackError, match="format: unknown keypoint format"):
        read_keypoints(tmp_path / "x.txt", "mat")
    with pytest.raises(VideoTrackError, match="crop_offset"):
        read_keypoints(write_dlc_csv(tmp_path / "a.csv", *planted_tracks()), crop_offset=(1,))


# -- real files --------------------------------------------------------------------------------


def need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} not present")
    return path


def test_real_dlc_labels_csv_and_h5_agree():
    folder = need(DATA / "dlc_openfield_labels")
    csv = read_keypoints(folder / "CollectedData_Pranav.csv")
    assert csv.names == ("snout", "leftear", "rightear", "tailbase")
    assert csv.n_frames == 116 and csv.frames[:3].tolist() == [0, 1, 2]  # from img0000.png
    np.testing.assert_allclose(csv.xy[0, 0], [21.521, 265.428])
    pytest.importorskip("tables")
    h5 = read_keypoints(folder / "CollectedData_Pranav.h5")
    np.testing.assert_allclose(h5.xy, csv.xy)
    np.testing.assert_array_equal(h5.frames, csv.frames)
    assert csv.images and h5.images


def test_real_sleap_slp_and_analysis_h5_agree():
    folder = need(DATA / "sleap_anipose_mouse4cam" / "back")
    h5 = read_keypoints(folder / "minimal_back_proofread.analysis.h5")
    assert h5.n_frames == 120 and len(h5.names) == 15 and h5.names[0] == "Nose"
    pytest.importorskip("sleap_io")
    slp = read_keypoints(folder / "minimal_back_proofread.slp")
    assert slp.names == h5.names
    np.testing.assert_allclose(slp.xy, h5.xy, rtol=1e-6)
    np.testing.assert_allclose(slp.score, h5.score, rtol=1e-6)


def test_real_openpose_pose2sim_demo():
    root = need(DATA / "pose2sim_demo" / "balancing_trial" / "pose_openpose_json")
    tracks = {c.name: read_keypoints(c, model="BODY_25B") for c in sorted(root.iterdir())}
    names, _, xy, _ = align_cameras(tracks)
    assert len(tracks) == 4 and xy.shape == (4, 100, 25, 2) and names[17] == "Neck"
    assert 0 < np.isnan(xy[..., 0]).mean() < 0.1
    first = json.loads((root / "cam01_json" / "cam01.0000.json").read_text())
    np.testing.assert_allclose(xy[0, 0, 0], first["people"][0]["pose_keypoints_2d"][:2])


@pytest.mark.parametrize("writer", ["dlc", "sleap"])
def test_damaged_h5_files_give_our_error(tmp_path, writer):
    # a seeded mutator over h5 files: each damaged copy reads or is refused in one line (h5py
    # raised RuntimeError on a damaged heap through the format sniffing: "internal error")
    xy, score = planted_tracks()
    good = (write_dlc_h5(tmp_path / "good.h5", xy, score) if writer == "dlc"
            else write_analysis_h5(tmp_path / "good.h5", xy, score)).read_bytes()
    rng = np.random.default_rng(7)
    for k in range(60):
        data = bytearray(good)
        for pos in rng.integers(0, len(data), rng.integers(1, 8)):
            data[pos] = int(rng.integers(0, 256))
        path = tmp_path / f"m{k}.h5"
        path.write_bytes(bytes(data))
        try:
            read_keypoints(path)
        except VideoTrackError as err:
            assert err.file == str(path) and "\n" not in str(err)
