"""Content identity (issue 16, item 1): inputs are known by their content, not by size, name
or place. A different video of the same byte size is a changed input; a project copied or
moved elsewhere stays up to date; digests are cached by file identity and never trusted for
a file that changed."""

import csv
import os
import re
import shutil
import time
from pathlib import Path

import cv2
import pytest

from videotrack.batch import plan_trial
from videotrack.cli import main
from videotrack.detect.video import VideoSource
from videotrack.project import identity
from videotrack.project.folders import open_project
from videotrack.synth.paper_setup import write_example_project

ANNEAL = {"n_end": 2000, "n_l": 200, "n_tau": 86}
# a trial's state, with or without warnings (the short schedule misfits a frame or two,
# which the status flags): these tests are about what is up to date
DONE, UP_TO_DATE = "done(-with-warnings)?", "(up to date|up-to-date-with-warnings)"
TRIALS = ["s1/t1", "s1/t2"]


@pytest.fixture(autouse=True)
def own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv(identity.CACHE_ENV, str(tmp_path / "cache"))
    identity._MEMO.clear()
    yield
    identity._MEMO.clear()


def raw_video(source: Path, target: Path) -> Path:
    """``source`` re-encoded uncompressed (Y800): every such video of the same frame size and
    count has the same byte size, as the raw files of lab cameras do."""
    with VideoSource(source) as video:
        frames = [frame.copy() for _, frame in video.frames()]
    h, w = frames[0].shape
    writer = cv2.VideoWriter(str(target), cv2.VideoWriter_fourcc(*"Y800"), 50.0, (w, h),
                             isColor=False)
    for frame in frames:
        writer.write(frame)
    writer.release()
    return target


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A project of two trials whose videos are raw (uncompressed), plus the raw video of
    each trial under ``raw/`` (A = trial 1's, B = trial 2's: same size, other content)."""
    base = tmp_path_factory.mktemp("identity")
    root = base / "project"
    write_example_project(root, TRIALS, frames=12, anneal=ANNEAL)
    raw = base / "raw"
    raw.mkdir()
    for name, tag in zip(TRIALS, "AB", strict=True):
        video = root / name / "video.avi"
        raw_video(video, raw / f"{tag}.avi")
        shutil.copyfile(raw / f"{tag}.avi", video)
    assert (raw / "A.avi").stat().st_size == (raw / "B.avi").stat().st_size
    assert (raw / "A.avi").read_bytes() != (raw / "B.avi").read_bytes()
    return base


@pytest.fixture
def project(rendered, tmp_path):
    shutil.copytree(rendered, tmp_path / "work")
    return tmp_path / "work" / "project"


def batch(capsys, root, *args):
    code = main(["batch", str(root), "--jobs", "1", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def rows(root: Path) -> dict[str, dict]:
    return {r["trial"]: r for r in csv.DictReader((root / "summary.csv").open())}


def test_a_different_video_of_the_same_size_is_not_up_to_date(project, capsys):
    # issue 16: cp A_raw.avi R/s1/t1/walk.avi && batch; cp B_raw.avi ... && batch --dry-run
    video = project / "s1" / "t1" / "video.avi"
    results = project / "s1" / "t1" / "video.results.csv"
    assert batch(capsys, project)[0] == 0
    before = results.read_bytes()
    video.write_bytes((project.parent / "raw" / "B.avi").read_bytes())  # same size and inode
    code, out, _ = batch(capsys, project, "--dry-run")
    line = next(line for line in out.splitlines() if line.startswith("s1/t1"))
    assert "detect + fit" in line and "another video of the same size" in line
    assert plan_trial(open_project(project).trials[1]) == ("up to date", "")
    code, out, _ = batch(capsys, project)
    assert code == 0 and re.search(f"1 {DONE}, 1 {UP_TO_DATE}", out), out
    assert results.read_bytes() != before
    # and back: the content, not the dates, decides
    video.write_bytes((project.parent / "raw" / "A.avi").read_bytes())
    assert plan_trial(open_project(project).trials[0])[0] == "detect + fit"
    assert batch(capsys, project)[0] == 0
    assert results.read_bytes() == before


@pytest.mark.parametrize("how", ["copy", "move"])
def test_a_copied_or_moved_project_stays_up_to_date(project, tmp_path, capsys, how):
    # issue 16: cp -a myproject myproject2 && batch myproject2 --dry-run
    assert batch(capsys, project)[0] == 0
    before = {p.relative_to(project): p.read_bytes() for p in project.rglob("*.results.csv*")}
    other = tmp_path / "elsewhere" / "project2"
    other.parent.mkdir()
    if how == "copy":
        shutil.copytree(project, other)  # new inodes, same dates (cp -a)
    else:
        os.rename(project, other)
    code, out, _ = batch(capsys, other, "--dry-run")
    assert code == 0 and "2 trials: 0 to process, 2 up to date" in out, out
    code, out, _ = batch(capsys, other)
    assert code == 0 and re.search(f"2 {UP_TO_DATE}", out) and "no log (nothing to do)" in out
    assert {p.relative_to(other): p.read_bytes()
            for p in other.rglob("*.results.csv*")} == before
    sidecar = (other / "s1" / "t1" / "video.results.csv.json").read_text()
    assert '"chain": "../../chain.xml"' in sidecar and str(tmp_path) not in sidecar
    if how == "copy":  # computed anywhere, the outputs are the same bytes
        assert batch(capsys, other, "--force")[0] == 0
        for name in ("video.detections.npz", "video.results.csv", "video.results.csv.json"):
            for trial in TRIALS:
                assert (other / trial / name).read_bytes() == (project / trial / name
                                                               ).read_bytes(), name


def test_the_camera_a_view_uses_is_part_of_the_identity(project, capsys):
    assert batch(capsys, project)[0] == 0
    config = project / "config.toml"
    text = config.read_text()
    assert 'camera = "side"' in text and 'camera = "top"' in text
    config.write_text(text.replace('camera = "side"', 'camera = "@"').replace(
        'camera = "top"', 'camera = "side"').replace('camera = "@"', 'camera = "top"'))
    trial = open_project(project).trials[0]
    assert plan_trial(trial) == ("detect + fit", "stale detections: made with other views "
                                 "settings; run 'videotrack detect --force' to redo them")


def test_digests_are_cached_by_file_identity(tmp_path, monkeypatch):
    reads = []
    real = identity.sha256_of
    monkeypatch.setattr(identity, "sha256_of", lambda p: reads.append(Path(p).name) or real(p))
    old = tmp_path / "old.bin"
    old.write_bytes(b"a" * 1000)
    past = time.time() - 60
    os.utime(old, (past, past))
    time.sleep(0.01)
    # (ctime cannot be set back: the entry waits until the file is RACY_SECONDS old)
    monkeypatch.setattr(identity, "RACY_SECONDS", 0.0)
    first = identity.content_hash(old)
    assert identity.content_hash(old) == first and reads == ["old.bin"]
    identity._MEMO.clear()  # another process: the cache file answers
    assert identity.content_hash(old) == first and reads == ["old.bin"]
    assert len(list((tmp_path / "cache" / "hashes").iterdir())) == 1
    # rewritten with the same size, and even the same mtime: hashed again
    old.write_bytes(b"b" * 1000)
    os.utime(old, (past, past))
    assert identity.content_hash(old) != first and reads == ["old.bin"] * 2
    # a broken cache entry is a miss, never an error
    identity._MEMO.clear()
    for entry in (tmp_path / "cache" / "hashes").iterdir():
        entry.write_text("garbage")
    assert identity.content_hash(old) == identity.sha256_of(old)


def test_recent_files_are_not_cached(tmp_path, monkeypatch):
    # a file written within the timestamp granularity could be rewritten unnoticed
    fresh = tmp_path / "fresh.bin"
    fresh.write_bytes(b"x" * 10)
    identity.content_hash(fresh)
    assert not (tmp_path / "cache" / "hashes").exists()
    monkeypatch.setenv(identity.CACHE_ENV, str(tmp_path / "file-not-folder"))
    (tmp_path / "file-not-folder").write_text("")  # an unusable cache folder: no cache
    monkeypatch.setattr(identity, "RACY_SECONDS", -1e9)
    assert identity.content_hash(fresh) == identity.sha256_of(fresh)


def test_image_folders_are_known_by_their_images(tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    for k in range(3):
        (folder / f"{k}.png").write_bytes(bytes([k]) * 10)
    (folder / "notes.txt").write_text("not a frame")
    first = identity.video_hash(folder)
    (folder / "notes.txt").write_text("still not a frame")
    assert identity.video_hash(folder) == first
    (folder / "1.png").write_bytes(b"\x09" * 10)
    assert identity.video_hash(folder) != first
