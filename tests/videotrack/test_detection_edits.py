"""Hand edits of the detections (GUI, issue 15 item 3): applying, snapping, the sidecar."""

from __future__ import annotations

import json

import numpy as np
import pytest

from videotrack.detect.detections import build_detections
from videotrack.detect.edits import (
    ViewEdit,
    add_point,
    apply_edit,
    edited_detections,
    edits_path,
    hidden_marks,
    is_hidden,
    load_edits,
    move_point,
    remove_point,
    save_edits,
    snap_to_centroid,
    toggle_hidden,
)
from videotrack.errors import VideoTrackError

VIEWS = ["side", "top"]


def _detections():
    per_record = [[(np.array([[1.0, 2.0], [5.5, 6.25]]), np.array([3, 4])),
                   (np.array([[9.0, 9.0]]), np.array([5]))],
                  [(np.empty((0, 2)), np.empty(0, np.int64)),
                   (np.array([[7.0, 8.0]]), np.array([6]))]]
    return build_detections(per_record, [0, 1], [-1, -1], {"view_names": VIEWS})


def test_edits_remove_add_and_move_points():
    det = _detections()
    edits = remove_point({}, 0, 0, (5.5, 6.25))  # a ghost
    edits = add_point(edits, 1, 0, (3.0, 4.0))  # a missed marker
    edits = move_point(edits, 1, 1, (7.0, 8.0), (7.5, 8.5))
    out = edited_detections(det, edits)
    np.testing.assert_array_equal(out.points_of(0, 0), [[1.0, 2.0]])
    np.testing.assert_array_equal(out.points_of(0, 1), [[9.0, 9.0]])
    np.testing.assert_array_equal(out.points_of(1, 0), [[3.0, 4.0]])
    np.testing.assert_array_equal(out.points_of(1, 1), [[7.5, 8.5]])
    assert out.areas.tolist() == [3, 5, 0, 0]
    np.testing.assert_array_equal(apply_edit(det.points_of(1, 1), edits[(1, 1)]), [[7.5, 8.5]])
    assert det.points.shape == (4, 2)  # the detections themselves are untouched
    # removing an added point drops it; undoing the ghost removal is removing the edit
    again = remove_point(edits, 1, 0, (3.0, 4.0))
    assert (1, 0) not in again
    assert edited_detections(det, {}) is det
    # a removed point that matches nothing (detected again since) changes nothing
    void = {(0, 1): ViewEdit(removed=((0.0, 0.0),))}
    np.testing.assert_array_equal(edited_detections(det, void).points, det.points)


def test_sidecar_round_trip_and_bad_files(tmp_path):
    results = tmp_path / "results.csv"
    path = edits_path(results)
    assert path == tmp_path / "results.detection-edits.json"
    assert load_edits(path, VIEWS) == {}  # no file: no edits
    edits = move_point(remove_point({}, 3, 1, (1 / 3, 2.0)), 0, 0, (4.0, 5.0), (4.25, 5.5))
    save_edits(path, edits, VIEWS)
    assert load_edits(path, VIEWS) == edits  # floats round-trip exactly
    with pytest.raises(VideoTrackError, match="views"):
        load_edits(path, ["front"])
    for text, message in (("{", "cannot read"), ('{"format": "x"}', "not a detection edits"),
                          (json.dumps({"format": "videotrack-detection-edits", "version": 1,
                                       "views": VIEWS, "edits": [{"record": 0}]}),
                           "each edit needs")):
        path.write_text(text)
        with pytest.raises(VideoTrackError, match=message) as err:
            load_edits(path, VIEWS)
        assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_snap_to_centroid_finds_a_bright_or_dark_blob():
    yy, xx = np.mgrid[0:40, 0:50]
    blob = np.exp(-((xx - 20.3) ** 2 + (yy - 15.7) ** 2) / 4.0)
    bright = (40 + 200 * blob).astype(np.uint8)
    x, y = snap_to_centroid(np.dstack([bright] * 3), (23.0, 13.0))
    assert abs(x - 20.3) < 0.15 and abs(y - 15.7) < 0.15
    dark = (220 - 200 * blob).astype(np.uint8)
    x, y = snap_to_centroid(dark, (18.0, 17.0))
    assert abs(x - 20.3) < 0.15 and abs(y - 15.7) < 0.15
    assert snap_to_centroid(np.full((10, 10), 7, np.uint8), (4.5, 3.0)) == (4.5, 3.0)


def test_hidden_marks_toggle_round_trip_and_read_version_1(tmp_path):
    edits = toggle_hidden(toggle_hidden({}, 2, 1, "M3"), 4, 0, "M1")
    assert is_hidden(edits, 2, 1, "M3") and not is_hidden(edits, 2, 0, "M3")
    assert toggle_hidden(edits, 4, 0, "M1") == {(2, 1): ViewEdit(hidden=("M3",))}
    marks = hidden_marks(edits, 5, 2, ["M0", "M1", "M2", "M3"])
    assert marks.shape == (5, 2, 4) and marks.sum() == 2 and marks[2, 1, 3] and marks[4, 0, 1]
    assert hidden_marks(edits, 5, 2, ["M0", "M2"]) is None  # names the chain lost: void
    assert hidden_marks(edits, 3, 2, ["M3"]).sum() == 1  # records beyond the video: void
    det = _detections()
    assert edited_detections(det, edits) is det  # hidden marks move no detection
    path = tmp_path / "r.detection-edits.json"
    both = add_point(edits, 2, 1, (7.0, 8.0))
    save_edits(path, both, VIEWS)
    assert json.loads(path.read_text())["version"] == 2
    assert load_edits(path, VIEWS) == both
    old = {"format": "videotrack-detection-edits", "version": 1, "views": VIEWS,
           "edits": [{"record": 0, "view": "top", "removed": [], "added": [[1.0, 2.0]]}]}
    path.write_text(json.dumps(old))
    assert load_edits(path, VIEWS) == {(0, 1): ViewEdit(added=((1.0, 2.0),))}
    save_edits(path, load_edits(path, VIEWS), VIEWS)  # no marks: still version 1
    assert json.loads(path.read_text()) == old
    for bad in ("M3", [3], None):
        old["edits"][0]["hidden"] = bad
        path.write_text(json.dumps(old))
        with pytest.raises(VideoTrackError, match="hidden marker names") as err:
            load_edits(path, VIEWS)
        assert "\n" not in str(err.value)
