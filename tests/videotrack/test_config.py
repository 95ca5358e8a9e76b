"""Project config: schema validation, defaults, paths, errors that name file and key."""

from pathlib import Path

import pytest

from videotrack.config import (
    FILTER_STEPS,
    MARKERS,
    SECTIONS,
    Key,
    Section,
    describe_section,
    load_config,
    parse_config,
    register_section,
)
from videotrack.detect import default_output, settings_from_config, video_paths
from videotrack.errors import VideoTrackError

MINIMAL = """\
[video]
path = "clips/walk.avi"
[[filters.steps]]
type = "otsu"
"""


def test_defaults_and_relative_paths(tmp_path):
    cfg = parse_config(MINIMAL, tmp_path / "p.toml")
    assert cfg["video"]["path"] == tmp_path / "clips" / "walk.avi"
    assert cfg["video"]["deinterlace"] == "none" and cfg["video"]["fps"] == 0.0
    assert cfg["markers"]["weighting"] == "intensity" and cfg["views"] == []
    assert cfg.given == ("video", "filters") and cfg.folder == tmp_path
    assert video_paths(cfg) == [tmp_path / "clips" / "walk.avi"]
    assert default_output(cfg) == tmp_path / "walk.detections.npz"
    settings = settings_from_config(cfg)
    assert [v.name for v in settings.views] == ["view"] and settings.views[0].roi is None


def test_full_config_builds_settings(tmp_path):
    text = """
[video]
path = ["/data/a.avi", "b"]
deinterlace = "fields"
field_order = "bottom"
line_doubling = "repeat"
frames = "10:20"
fps = 50
[[views]]
name = "side"
roi = [0, 0, 360, 576]
[[views]]
name = "top"
roi = [0, 0, 10, 10]
flip_y = true
camera = "cam2"
video = 1
[[filters.steps]]
type = "threshold"
value = 120
[markers]
min_area = 3
max_aspect = 2.5
[output]
detections = "out/d.npz"
"""
    cfg = parse_config(text, tmp_path / "p.toml")
    assert video_paths(cfg) == [Path("/data/a.avi"), tmp_path / "b"]
    s = settings_from_config(cfg)
    assert s.deinterlace.parities == (1, 0) and s.deinterlace.line_doubling == "repeat"
    assert s.views[1].flip_y and s.views[1].camera == "cam2" and s.views[1].video == 1
    assert s.views[0].camera == "side" and s.markers.max_aspect == 2.5
    assert default_output(cfg) == tmp_path / "out" / "d.npz"


@pytest.mark.parametrize("text, field, message", [
    ("[vidoe]\npath='a'", "vidoe", "unknown section"),
    ("[video]\npath='a'\nspeed=2\n[[filters.steps]]\ntype='otsu'", "video.speed", "unknown key"),
    ("[video]\nfps=3\n[[filters.steps]]\ntype='otsu'", "video.path", "missing"),
    ("[video]\npath=3\n[[filters.steps]]\ntype='otsu'", "video.path", "a path"),
    ("[video]\npath='a'\ndeinterlace='yes'\n[[filters.steps]]\ntype='otsu'",
     "video.deinterlace", "one of 'none', 'fields'"),
    ("[video]\npath='a'\nframes='9:3'\n[[filters.steps]]\ntype='otsu'", "video.frames",
     "empty"),
    ("[video]\npath='a'\n[[filters.steps]]\ntype='otsu'\n[[views]]\nname='a'\nroi=[1,2,3]",
     "views[0].roi", "x, y, width, height"),
    ("[video]\npath='a'\n[[filters.steps]]\ntype='otsu'\n[[views]]\nroi=[1,2,3,4]",
     "views[0].name", "missing"),
    ("[video]\npath='a'\n[[filters.steps]]\ntype='otsu'\n[[views]]\nname='a'\nflip_x=1",
     "views[0].flip_x", "true or false"),
    ("[video]\npath='a'\n[[filters.steps]]\ntype='threshold'\nvalue=999", "filters.steps[0].value",
     "at most 254"),
    ("[video]\npath='a'\n[filters]\nsteps=3", "filters.steps", "a list of tables"),
    ("[video]\npath='a'\n[[filters.steps]]\ntype='otsu'\n[markers]\nmax_area=0",
     "markers.max_area", "at least 1"),
    ("[video]\npath='a'\n[[filters.steps]]\ntype='otsu'\nviews='x'", "filters.steps[0].views",
     "unknown key"),
])
def test_errors_name_file_and_key(tmp_path, text, field, message):
    with pytest.raises(VideoTrackError, match=message) as err:
        parse_config(text, tmp_path / "p.toml")
    assert err.value.field == field and err.value.file == str(tmp_path / "p.toml")
    assert str(err.value).startswith(f"{tmp_path / 'p.toml'}: {field}: ")


def test_toml_syntax_error_gives_the_line(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text("[video]\npath = 'a'\nfps = = 3\n")
    with pytest.raises(VideoTrackError, match="TOML syntax") as err:
        load_config(path)
    assert err.value.line == 3 and str(err.value).startswith(f"{path}:3: ")
    with pytest.raises(VideoTrackError, match="no such config file"):
        load_config(tmp_path / "none.toml")


def test_other_modules_can_add_sections(tmp_path):
    section = Section("demo_anneal", (Key("iterations", "int", 100, "SA steps.", min=1),))
    try:
        assert register_section(section) is section
        cfg = parse_config(MINIMAL + "[demo_anneal]\niterations = 5\n", tmp_path / "p.toml")
        assert cfg["demo_anneal"] == {"iterations": 5}
        with pytest.raises(ValueError, match="twice"):
            register_section(Section("demo_anneal", ()))
    finally:
        SECTIONS.pop("demo_anneal")


def test_describe_is_generated_from_the_schema():
    text = describe_section(MARKERS)
    assert "`[markers]`" in text and "| `min_area` | int | `1` |" in text
    steps = describe_section(FILTER_STEPS)
    for kind, section in FILTER_STEPS.sections.items():
        assert f'`type = "{kind}"`' in steps
        assert all(f"`{k.name}`" in steps for k in section.keys)
