"""Project config: schema validation, defaults, paths, errors that name file and key."""

import dataclasses
from pathlib import Path

import pytest

from kinematics.errors import KinematicsError, LocatedError
from kinematics.fit.settings import AnnealParams, ErrorOptions, setting
from videotrack.detect.run import default_output, settings_from_config, video_paths
from videotrack.errors import VideoTrackError
from videotrack.project.config import (
    ANNEAL,
    FILTER_STEPS,
    MARKERS,
    SECTIONS,
    Key,
    Section,
    describe_section,
    load_config,
    parse_config,
    record_from_table,
    record_section,
    register_section,
)
from videotrack.workflow import anneal_params, load_model

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
    ("[video]\npath='a'\n[[filters.steps]]\ntype=[1]", "filters.steps[0].type",
     r"unknown type \[1\]"),
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
    # nested past the parser's recursion: a syntax error at its line, no RecursionError
    path.write_text("[video]\npath = 'a'\n\nx = " + "[" * 1000 + "]" * 1000 + "\n")
    with pytest.raises(VideoTrackError, match="nested too deep") as err:
        load_config(path)
    assert err.value.line == 4


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


# -- [anneal]: derived from kinematics.fit.settings (AnnealParams, ErrorOptions) -------------------

def _anneal_config(tmp_path, body: str):
    return parse_config(MINIMAL + "[anneal]\n" + body, tmp_path / "p.toml")


def test_every_anneal_field_is_a_key(tmp_path):
    names = [k.name for k in ANNEAL.keys]
    flat = {"mode": "error"}  # ErrorOptions' fields are flattened; its mode is `error`
    expected = [f.name for f in dataclasses.fields(AnnealParams) if f.name != "error"]
    expected += [flat.get(f.name, f.name) for f in dataclasses.fields(ErrorOptions)]
    expected += ["profile"]  # which settings the others start from
    assert sorted(names) == sorted(expected) and len(names) == len(set(names))
    defaults = AnnealParams()
    for key in ANNEAL.keys:
        assert key.doc, key.name  # every key is documented (the field's metadata)
        if key.choices is None and key.type != "bool":
            assert key.min is not None and key.max is not None, key.name  # GUI spin boxes
        if key.type in ("int", "float"):
            assert key.min <= key.default <= key.max, key.name
    # None-able fields are written 0 in a project file, and their docs say so
    for name in ("plausibility_threshold", "root_gate_px", "cap_px"):
        key = ANNEAL.key(name)
        assert "written 0 in a project file" in key.doc, name
        assert key.default == (10.0 if name == "cap_px" else 0.0), name  # cap: the defaults
    assert anneal_params(parse_config(MINIMAL, tmp_path / "p.toml")) == defaults


def test_the_paper_profile_gives_the_papers_settings_under_the_keys_set(tmp_path):
    p = anneal_params(_anneal_config(tmp_path, 'profile = "paper"\n'))
    assert p == AnnealParams.paper()
    p = anneal_params(_anneal_config(tmp_path, 'profile = "paper"\nseed = 4\nrefine = true\n'))
    assert p == AnnealParams.paper(seed=4, refine=True)
    # the command line's --paper
    assert anneal_params(_anneal_config(tmp_path, "seed = 4\n"), profile="paper") == (
        AnnealParams.paper(seed=4))
    assert anneal_params(_anneal_config(tmp_path, "")) == AnnealParams()
    with pytest.raises(LocatedError, match="profile"):
        anneal_params(_anneal_config(tmp_path, 'profile = "fast"\n'))


def test_new_anneal_keys_reach_the_params(tmp_path):
    cfg = _anneal_config(tmp_path, "root_gate_px = 12\nrefine_gate_px = 3.5\n"
                         "refine_steps = 4\nsegment_length = 8\nmax_redraws = 2\n")
    p = anneal_params(cfg)
    assert (p.root_gate_px, p.refine_gate_px, p.refine_steps, p.segment_length,
            p.max_redraws) == (12.0, 3.5, 4, 8, 2)
    assert p.error == AnnealParams().error and p.n_end == AnnealParams().n_end
    assert anneal_params(_anneal_config(tmp_path, "root_gate_px = 0\n")).root_gate_px is None
    # overrides (the command line) still apply on top
    q = anneal_params(cfg, n_end=3500, seed=9)
    assert (q.n_end, q.n_l, q.n_tau, q.seed, q.root_gate_px) == (3500, 350, 150, 9, 12.0)


@pytest.mark.parametrize("body, field, message", [
    ("root_gate_px = -1", "anneal.root_gate_px", "at least 0"),
    ("refine_steps = 1.5", "anneal.refine_steps", "an integer"),
    ("segment_length = 0", "anneal.segment_length", "at least 1"),
    ("error = 'median'", "anneal.error", "one of 'paper', 'bidirectional'"),
    ("cap_px = 'none'", "anneal.cap_px", "a number"),
    ("root_gate = 3", "anneal.root_gate", "unknown key"),
])
def test_bad_anneal_value_names_the_key(tmp_path, body, field, message):
    with pytest.raises(VideoTrackError, match=message) as err:
        _anneal_config(tmp_path, body + "\n")
    assert err.value.field == field and "\n" not in str(err.value)
    assert str(err.value).startswith(f"{tmp_path / 'p.toml'}: {field}: ")


@pytest.mark.parametrize("body, field", [
    ("refine_gate_px = 0", "anneal.refine_gate_px"),  # the record's own rule: > 0
    ("tau0 = 0", "anneal.tau0"),
])
def test_record_rules_name_the_key(tmp_path, body, field):
    cfg = _anneal_config(tmp_path, body + "\n")
    with pytest.raises(VideoTrackError, match="> 0") as err:
        anneal_params(cfg)
    assert err.value.field == field and "\n" not in str(err.value)
    assert str(err.value).startswith(f"{tmp_path / 'p.toml'}: {field}: ")


OLD_ANNEAL = """
[anneal]
n_end = 20000
n_l = 2000
n_tau = 857
tau0 = 150
l0 = 0.5
c_l = 0.7
c_tau = 0.8
epsilon = 0.5
plausibility_threshold = 0
reanalysis_threshold = 3.0
max_runs = 3
start = "previous"
refine = true
error = "bidirectional"
penalty_weight = 2.0
cap_px = 0
seed = 1
"""


def test_old_style_project_loads_unchanged(tmp_path):
    from videotrack.synth.paper_setup import write_paper_project

    project = write_paper_project(tmp_path / "demo", frames=2, sequences=1)
    assert load_model(load_config(project.config)).params == AnnealParams.paper()  # the demo's
    text = project.config.read_text(encoding="utf-8")
    # an old project: no profile (the best settings are now the defaults), every key a
    # project file could hold before
    project.config.write_text(text.replace('[anneal]\nprofile = "paper"\n', "") + OLD_ANNEAL,
                              encoding="utf-8")
    params = load_model(load_config(project.config)).params
    assert params == AnnealParams(
        n_end=20000, n_l=2000, n_tau=857, tau0=150.0, l0=0.5, c_l=0.7, c_tau=0.8,
        epsilon=0.5, plausibility_threshold=None, reanalysis_threshold=3.0, max_runs=3,
        start="previous", refine=True, seed=1,
        error=ErrorOptions(mode="bidirectional", penalty_weight=2.0, cap_px=None))
    cfg = _anneal_config(tmp_path, "plausibility_threshold = 0.001\ncap_px = 25\n")
    p = anneal_params(cfg)
    assert p.plausibility_threshold == 0.001 and p.error.cap_px == 25.0


def test_a_section_follows_its_record(tmp_path):
    """A field added to a record shows up as a key with no edit of the config module."""

    @dataclasses.dataclass(frozen=True)
    class Inner:
        mode: str = setting("a", "Mode.", choices=("a", "b"))
        limit_px: float | None = setting(None, "Limit; 0: none.", min=0.0, max=9.0, none=0.0)

    @dataclasses.dataclass(frozen=True)
    class Outer:
        count: int = setting(2, "Count.", min=1, max=5)
        inner: Inner = dataclasses.field(default_factory=Inner,
                                         metadata={"doc": "", "flatten": {"mode": "kind"}})

        def __post_init__(self):
            if self.inner.mode == "b" and self.inner.limit_px is None:
                raise KinematicsError("mode b needs a limit", field="inner.limit_px")

    section = record_section("toy", Outer)
    assert [(k.name, k.type, k.default) for k in section.keys] == [
        ("count", "int", 2), ("kind", "str", "a"), ("limit_px", "float", 0.0)]
    table = section.validate({"kind": "b", "limit_px": 4})
    assert record_from_table(Outer, table) == Outer(2, Inner("b", 4.0))
    with pytest.raises(VideoTrackError) as err:
        record_from_table(Outer, section.validate({"kind": "b"}), file="x.toml", where="toy")
    assert str(err.value) == "x.toml: toy.limit_px: mode b needs a limit"


def test_updated_toml_text_keeps_comments_and_drops_removed_keys():
    import tomllib

    from videotrack.project.config import updated_toml_text

    text = ('# project\n[video]\npath = "a.avi"  # camera A\n\n[anneal]\nseed = 3  # lucky\n'
            'n_end = 1000\n')
    table = tomllib.loads(text)
    table["anneal"]["seed"] = 4
    del table["anneal"]["n_end"]
    table["fit"] = {"plot": True}
    out = updated_toml_text(text, table)
    assert tomllib.loads(out) == table
    assert out.startswith("# project\n") and "# camera A" in out and "seed = 4  # lucky" in out
    assert "n_end" not in out
