"""Markers of several colours: ``synth --colour`` end to end, one view per camera and colour
(its own HSV range, its own ``model_markers``), config errors and staleness."""

import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from kinematics.fit import SetupError
from videotrack.cli import main
from videotrack.detect.detections import DetectSettings, load_detections
from videotrack.detect.filters import FilterChain
from videotrack.detect.marker_colours import bgr, colour_of_markers, hsv_range, parse_colour
from videotrack.detect.markers import MarkerSettings
from videotrack.detect.run import detect_video, settings_from_config
from videotrack.detect.video import VideoSource
from videotrack.detect.views import View
from videotrack.errors import VideoTrackError, VideoTrackWarning
from videotrack.project.config import load_config
from videotrack.results.evaluate import evaluate_files
from videotrack.results.files import read_results, read_sidecar
from videotrack.synth.render import render_markers
from videotrack.workflow import load_model, plan_project, run_project

COLOURS = ["--colour", "red=M0,M1,M2", "--colour", "green=M3"]
VIEWS = ["side_red", "side_green", "top_red", "top_green"]
RED, GREEN = ["M0", "M1", "M2"], ["M3"]


def synth(out: Path, *options: str) -> Path:
    """A coloured synthetic project of the bundled locust chain; returns its project file."""
    assert main(["synth", str(out), "--frames", "30", *COLOURS, *options]) == 0
    return out / "project.toml"


def max_angle_error(project: Path) -> float:
    ev = evaluate_files(project.parent / "detections.results.csv", project.parent / "truth.csv")
    assert ev.n_scored == ev.n_frames == 30
    return max(r.max for r in ev.rows if r.kind == "angle")


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A coloured project, rendered, detected and fitted by ``videotrack run``."""
    project = synth(tmp_path_factory.mktemp("colours") / "project")
    assert main(["run", str(project)]) == 0
    return project


def test_synth_writes_one_view_per_camera_and_colour(fitted):
    """project.toml: a view per camera and colour sharing the camera's ROI, each with its
    markers and HSV range, in place of the chain's one hsv_range step."""
    config = load_config(fitted)
    views = config["views"]
    assert [v["name"] for v in views] == VIEWS
    assert [v["camera"] for v in views] == ["side", "side", "top", "top"]
    assert views[0]["roi"] == views[1]["roi"] != views[2]["roi"] == views[3]["roi"]
    assert [list(v["model_markers"]) for v in views] == [RED, GREEN, RED, GREEN]
    red, green = hsv_range("red", 0), hsv_range("green", 0)
    assert [v["hsv_lower"][:2] for v in views] == [red[0][:2], green[0][:2]] * 2
    assert [v["hsv_upper"] for v in views] == [red[1], green[1]] * 2
    settings = settings_from_config(config)
    assert [s["type"] for s in settings.filters.steps] == ["hsv_range"]
    assert [v.hsv is not None for v in settings.views] == [True] * 4
    assert load_model(config).view_markers == {"side_red": RED, "side_green": GREEN,
                                               "top_red": RED, "top_green": GREEN}


def test_colour_views_detect_their_markers_and_fit_the_truth(fitted):
    """Red views see (up to) the three red markers, green views the one green; the fit
    matched per colour recovers every free axis."""
    det = load_detections(fitted.parent / "detections.npz")
    assert det.view_names == VIEWS and det.n_records == 30
    counts = det.counts()
    red, green = counts[:, [0, 2]], counts[:, [1, 3]]
    assert red.max() <= 3 and np.mean(red == 3) > 0.9  # red discs may merge
    assert green.max() <= 1 and np.mean(green == 1) > 0.9
    results = read_results(fitted.parent / "detections.results.csv")
    assert list(results.view_names) == VIEWS and results.ok_mask().all()
    assert np.median(results.error) < 0.5  # px: every detection explained
    assert read_sidecar(fitted.parent / "detections.results.csv")["view_markers"] == {
        "side_red": RED, "side_green": GREEN, "top_red": RED, "top_green": GREEN}
    assert max_angle_error(fitted) < 3.0


def test_colour_decoys_are_harmless_only_when_views_know_their_markers(tmp_path):
    """Ghosts take the colours in turn: each view sees one decoy of its colour. Matched to
    their colour's markers the views fit the truth; matched to every marker they do not."""
    project = synth(tmp_path / "p", "--ghosts", "2")
    config = load_config(project)
    run = run_project(config)
    assert run.steps == ("detect", "fit")
    counts = run.detections.counts()
    assert counts[:, [1, 3]].max() == 2 and counts[:, [0, 2]].max() == 4  # one decoy each
    assert max_angle_error(project) < 5.0
    project.write_text(re.sub(r"model_markers = .*\n", "", project.read_text()))
    config = load_config(project)
    assert plan_project(config) == ("fit", "changed: the markers views show")
    with pytest.raises(SetupError, match="the chain does not fit the detections"):
        run_project(config)  # the set-up checks see it
    assert run_project(config, anneal={"accept_setup": True}).steps == ("fit",)  # same detections
    assert max_angle_error(project) > 20.0


def test_editing_model_markers_makes_results_stale(fitted, tmp_path):
    """The markers a view shows are an input of the fit: changing them calls for a refit
    (and keeps the detections)."""
    project = Path(shutil.copytree(fitted.parent, tmp_path / "copy")) / "project.toml"
    assert plan_project(load_config(project)) == ("up to date", "")
    text = project.read_text()
    edited = text.replace('model_markers = ["M0", "M1", "M2"]', 'model_markers = ["M0", "M1"]',
                          1)
    assert edited != text
    project.write_text(edited)
    assert plan_project(load_config(project)) == ("fit", "changed: the markers views show")
    # what counts is the markers picked, not how the patterns are written
    project.write_text(text.replace('model_markers = ["M0", "M1", "M2"]',
                                    'model_markers = ["M[0-2]"]'))
    assert plan_project(load_config(project)) == ("up to date", "")


# -- config errors -------------------------------------------------------------------------

VIEW_ERRORS = [
    ('hsv_lower = [0, 80, 90]', '[0, 80, 90]', "views[1].hsv_upper", "hsv_upper is missing"),
    ('hsv_upper = [10, 255, 255]', '[0, 80, 90]', "views[1].hsv_lower", "hsv_lower is missing"),
    ('hsv_lower = [0, 80]\nhsv_upper = [10, 255, 255]', '[0, 80, 90]', "views[1].hsv_lower",
     "got 2 entries"),
    ('hsv_lower = [0, 80, 90]\nhsv_upper = [10, 255, 255]', None, "views[1].hsv_lower",
     "the chain has 0"),
]


@pytest.mark.parametrize(("view", "chain_lower", "field", "message"), VIEW_ERRORS)
def test_view_colour_errors_name_the_field(tmp_path, view, chain_lower, field, message):
    """A view's colour needs both bounds, three entries each, and a chain whose one
    hsv_range step it replaces."""
    step = (f'type = "hsv_range"\nlower = {chain_lower}\nupper = [10, 255, 255]'
            if chain_lower else 'type = "threshold"\nvalue = 90')
    path = tmp_path / "project.toml"
    path.write_text(f'[video]\npath = "v.avi"\n\n[[views]]\nname = "a"\n\n[[views]]\n'
                    f'name = "b"\n{view}\n\n[[filters.steps]]\n{step}\n')
    with pytest.raises(VideoTrackError) as err:
        settings_from_config(load_config(path))
    assert err.value.field == field and message in err.value.message
    assert "\n" not in str(err.value) and str(err.value).startswith(str(path))


def test_model_markers_naming_no_marker_is_an_error(fitted, tmp_path):
    """A ``model_markers`` pattern that picks none of the chain's markers names its entry."""
    text = fitted.read_text().replace('model_markers = ["M3"]', 'model_markers = ["M3", "L*"]',
                                      1)
    for key in ("chain", "cameras"):  # the copy lies elsewhere: absolute paths
        text = text.replace(f'path = "{key}.', f'path = "{fitted.parent.as_posix()}/{key}.')
    path = tmp_path / "project.toml"
    path.write_text(text)
    config = load_config(path)
    settings_from_config(config)  # detection does not mind
    with pytest.raises(VideoTrackError) as err:
        load_model(config)
    assert err.value.field == "views[1].model_markers[1]"
    assert "'L*' names no marker" in err.value.message and "M0, M1, M2, M3" in err.value.message
    assert "\n" not in str(err.value)


def test_parse_colour():
    """``--colour COLOUR=MARKERS``: known colours only, markers required."""
    assert parse_colour("Red= LF_*, LM_* ,") == ("red", ("LF_*", "LM_*"))
    for text, message in [("purple=M0", "unknown colour 'purple'"), ("red", "COLOUR=MARKERS"),
                          ("red=", "COLOUR=MARKERS"), ("=M0", "unknown colour ''")]:
        with pytest.raises(VideoTrackError, match=re.escape(message)) as err:
            parse_colour(text)
        assert err.value.field == "--colour"


def test_colour_of_markers():
    """Every marker gets exactly one colour; every pattern names a marker."""
    names = ["L1", "L2", "R1", "R2"]
    colours = (("red", ("L*",)), ("green", ("R1", "R2")))
    np.testing.assert_array_equal(colour_of_markers(colours, names), [0, 0, 1, 1])
    for bad, message in [
        ((("red", ("L*", "R1")), ("green", ("R*",))), "'R1' is both red and green"),
        ((("red", ("L*",)), ("green", ("R1",))), "'R2' has no colour"),
        ((("red", ("L*", "X*")), ("green", ("R*",))), "'X*' names no marker"),
        ((("red", ("L*",)), ("red", ("R*",))), "'red' is given twice"),
        ((("red", ("L*",)), ("pink", ("R*",))), "unknown colour 'pink'"),
    ]:
        with pytest.raises(VideoTrackError, match=re.escape(message)) as err:
            colour_of_markers(bad, names)
        assert err.value.field == ("colours.red[1]" if "X*" in message else "colours")


# -- detection -----------------------------------------------------------------------------


def test_each_view_keeps_only_its_colour(tmp_path, video_writer):
    """Views sharing one region with their own HSV ranges each find only their colour's
    disc; a view without a range keeps the chain's (red)."""
    red_xy, green_xy = np.array([20.3, 30.6]), np.array([57.8, 24.2])
    gains = np.array([bgr("red", 200.0), bgr("green", 200.0)])
    frame = render_markers((60, 80, 3), np.array([red_xy, green_xy]), 6.0, gains, 20.0, 1.0,
                           np.random.default_rng(0))
    assert frame.shape == (60, 80, 3)
    path = video_writer(tmp_path / "colour.avi", [frame] * 3)
    red, green = hsv_range("red", 86), hsv_range("green", 86)
    chain = FilterChain([{"type": "hsv_range", "lower": red[0], "upper": red[1]}])
    region = (0, 0, 80, 60)
    views = (View("red", region, hsv=red), View("green", region, hsv=green),
             View("plain", region))
    det = detect_video(VideoSource(path, colour=True),
                       DetectSettings(views, chain, MarkerSettings(min_area=3)))
    for r in range(det.n_records):
        for view, truth in (("red", red_xy), ("green", green_xy), ("plain", red_xy)):
            found = det.points_of(r, view)
            assert found.shape == (1, 2), view
            assert np.linalg.norm(found[0] - truth) < 0.2, view


def test_a_views_colour_survives_its_dict():
    from videotrack.detect.views import View

    view = View("a", (0, 0, 10, 10), camera="cam", hsv=((1, 2, 3), (4, 5, 6)))
    assert View.from_dict(view.to_dict()) == view
    plain = View("b", (0, 0, 10, 10))
    assert "hsv" not in plain.to_dict() and View.from_dict(plain.to_dict()) == plain


def test_a_marker_no_view_shows_is_warned_about(fitted, tmp_path):
    """Every view lists its markers and none lists M3: loading says so, once, and still
    loads."""
    text = fitted.read_text().replace('model_markers = ["M3"]', 'model_markers = ["M0"]')
    for key in ("chain", "cameras"):  # the copy lies elsewhere: absolute paths
        text = text.replace(f'path = "{key}.', f'path = "{fitted.parent.as_posix()}/{key}.')
    path = tmp_path / "project.toml"
    path.write_text(text)
    with pytest.warns(VideoTrackWarning, match="no view shows M3; the fit never places"):
        model = load_model(load_config(path))
    assert model.view_markers["side_green"] == ["M0"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_model(load_config(fitted))  # the tip is green: every marker is shown
