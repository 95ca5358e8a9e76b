"""Every command on a set of broken inputs ends in one-line messages: never a traceback, never
a raw library warning (issue 16, must-have 5).

One small synthetic project is made once; each case runs ``videotrack.cli.main`` on broken
copies of its files and checks the whole output (Python's and the C libraries' stderr,
captured at the file descriptors). Warnings of other libraries that reach the CLI are caught
by wrapping ``cli._show_warning``.
"""

from __future__ import annotations

import re
import sys
import warnings
from pathlib import Path

import cv2
import pytest

from videotrack import cli
from videotrack.cli import main
from videotrack.errors import VideoTrackWarning

CHAIN_TAIL = "</body>"

HISTOGRAM = """  <histograms>
    <histogram chain="hindleg" joint="{joint}" axis="{axis}" trials="3">
      <run from="{lo}" to="{hi}" value="{value}"/>
    </histogram>
  </histograms>
</body>"""

ARCHIVE = """<?xml version="1.0" encoding="UTF-8"?>
<histogram-archive format="1">
  <histogram chain="hindleg" joint="{joint}" axis="{axis}">
    <run from="{lo}" to="{hi}" value="{value}"/>
  </histogram>
</histogram-archive>
"""


def _spine(n: int) -> str:
    """A chain of ``n`` nested joints (a spine)."""
    head = ['<?xml version="1.0"?>', '<body name="spine" units="mm" format="1">',
            '<chain name="spine">']
    for k in range(n):
        head.append(f'<joint name="V{k}"><axis rot="y" name="ry" locked="0"/>'
                    f'<axis rot="x" name="rx" locked="0"/>'
                    f'<axis rot="z" name="flex" min="-10" max="10"/>'
                    f'<segment name="S{k}" length="1"><marker name="M{k}"/>')
    return "\n".join(head + ["</segment></joint>"] * n + ["</chain>", "</body>", ""])


def _scaled_video(src: Path, dst: Path, factor: float) -> None:
    cap = cv2.VideoCapture(str(src))
    w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH) * factor), int(
        cap.get(cv2.CAP_PROP_FRAME_HEIGHT) * factor)
    out = cv2.VideoWriter(str(dst), cv2.VideoWriter_fourcc(*"FFV1"), 25.0, (w, h))
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        out.write(cv2.resize(frame, (w, h)))
    out.release()
    cap.release()


def _project(root: Path, name: str, edit=None, **files) -> Path:
    """A copy of the good project named ``name``: ``edit`` (old, new) applied to
    project.toml, and ``files`` (name=text or bytes) written into it."""
    good = root / "good"
    folder = root / name
    folder.mkdir()
    for f in good.iterdir():
        if f.is_file():
            (folder / f.name).write_bytes(f.read_bytes())
    if edit is not None:
        toml = folder / "project.toml"
        text = toml.read_text()
        assert edit[0] in text
        toml.write_text(text.replace(*edit))
    for fname, content in files.items():
        fname = fname.replace("__", ".")
        target = folder / fname
        if isinstance(content, bytes):
            target.write_bytes(content)
        else:
            target.write_text(content)
    return folder / "project.toml"


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("broken")
    good = root / "good"
    assert main(["synth", str(good), "--frames", "6", "--sequences", "1"]) == 0
    assert main(["detect", str(good / "project.toml")]) == 0
    chain = (good / "chain.xml").read_text()
    garbage = bytes(range(256)) * 8

    def histogram(joint="J1", axis="beta", lo="-30", hi="60", value="1"):
        return chain.replace(CHAIN_TAIL, HISTOGRAM.format(joint=joint, axis=axis, lo=lo, hi=hi,
                                                          value=value))

    files = {
        "empty.xml": "",
        "garbage.xml": garbage,
        "truncated.xml": chain[: len(chain) // 2],
        "huge_value.xml": histogram(joint="J0", axis="phi", lo="120", hi="180",
                                    value="1e308"),
        "outside.xml": histogram(lo="90", hi="120"),
        "deep.xml": _spine(130),
        "no_free_axis.xml": chain.replace('min="-30" max="60"', 'locked="0"').replace(
            'min="20" max="160"', 'locked="90"').replace('min="120" max="220"', 'locked="170"')
        .replace('min="-40" max="40"', 'locked="0"').replace('min="-10" max="10"', 'locked="0"'),
        "huge_archive.xml": ARCHIVE.format(joint="J1", axis="beta", lo="-30", hi="60",
                                           value="1e308"),
        "outside_archive.xml": ARCHIVE.format(joint="J1", axis="beta", lo="90", hi="120",
                                              value="1"),
        "garbage.csv": garbage,
        "empty.csv": "",
        "header.csv": "frame,J0.phi\n",
        "text.csv": "hello\nworld\n",
        "garbage.toml": garbage,
        "syntax.toml": "[video\npath = 1\n",
        "a_file": "not a folder\n",
    }
    for name, content in files.items():
        path = root / name
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content)
    (root / "a_folder").mkdir()
    video = (good / "video.avi").read_bytes()
    _project(root, "p_huge_value", chain__xml=files["huge_value.xml"])
    _project(root, "p_outside", chain__xml=files["outside.xml"])
    _project(root, "p_archive", edit=("[cameras]", '[cameras]\n'),
             chain__xml=chain)
    toml = root / "p_archive" / "project.toml"
    toml.write_text(toml.read_text().replace('path = "chain.xml"', 'path = "chain.xml"\n'
                                             'histograms = "archive.xml"'))
    (root / "p_archive" / "archive.xml").write_text(files["outside_archive.xml"])
    _project(root, "p_cameras", cameras__toml=garbage)
    _project(root, "p_toml", project__toml="[video\n")
    _project(root, "p_no_video").with_name("video.avi").unlink()
    _project(root, "p_garbage_video", video__avi=garbage)
    _project(root, "p_truncated_video", video__avi=video[: len(video) // 2])
    small = _project(root, "p_small_video")
    _scaled_video(good / "video.avi", small.with_name("video.avi"), 0.5)
    big = _project(root, "p_big_video")
    _scaled_video(good / "video.avi", big.with_name("video.avi"), 2.0)
    _project(root, "p_no_markers", edit=("value = 96", "value = 254"))
    _project(root, "p_stale", video__avi=video + bytes(64))  # other bytes: stale detections
    (root / "b_garbage").mkdir()
    (root / "b_garbage" / "config.toml").write_bytes(garbage)
    return root


# (name, argv): {r} is the folder of broken inputs, {g} the good project.
CASES = [
    ("chain-check-broken", "chain check {r}/missing.xml {r}/empty.xml {r}/garbage.xml "
     "{r}/truncated.xml {r}/huge_value.xml {r}/outside.xml {r}/deep.xml {r}/no_free_axis.xml "
     "{r}/a_folder {r}/garbage.csv"),
    *[(f"chain-show-{n}", f"chain show {{r}}/{n}.xml") for n in (
        "missing", "empty", "garbage", "truncated", "huge_value", "outside", "deep")],
    ("chain-show-folder", "chain show {r}/a_folder"),
    *[(f"histograms-show-{n}", f"histograms show {{r}}/{n}.xml --plot {{r}}/h.png") for n in (
        "missing", "empty", "garbage", "huge_value", "huge_archive", "outside",
        "outside_archive")],
    ("histograms-show-plot-over-input", "histograms show {g}/chain.xml --plot {g}/chain.xml"),
    ("histograms-show-plot-in-folder", "histograms show {g}/chain.xml --plot {r}/a_file/h.png"),
    ("histograms-merge-broken", "histograms merge {r}/huge_archive.xml {r}/outside_archive.xml "
     "-o {r}/merged.xml"),
    ("histograms-merge-onto-input", "histograms merge {g}/chain.xml -o {g}/chain.xml"),
    *[(f"histograms-update-{n}", f"histograms update {{g}}/chain.xml {{r}}/{n} -o {{r}}/u.xml")
      for n in ("missing.csv", "garbage.csv", "empty.csv", "header.csv", "text.csv")],
    ("histograms-update-broken-chain", "histograms update {r}/huge_value.xml {r}/header.csv "
     "-o {r}/u.xml"),
    ("histograms-update-broken-archive", "histograms update {g}/chain.xml {r}/header.csv "
     "--archive {r}/outside_archive.xml -o {r}/u.xml"),
    ("histograms-update-onto-input", "histograms update {g}/chain.xml {r}/header.csv "
     "-o {g}/chain.xml"),
    *[(f"eval-{n}", f"eval {{r}}/{n} {{g}}/truth.csv") for n in (
        "missing.csv", "garbage.csv", "empty.csv", "header.csv", "text.csv")],
    ("eval-garbage-truth", "eval {r}/header.csv {r}/garbage.csv"),
    ("eval-csv-onto-input", "eval {r}/header.csv {g}/truth.csv --csv {g}/truth.csv"),
    *[(f"{cmd}-{n}", f"{cmd} {{r}}/{n}/project.toml") for cmd in ("detect", "fit") for n in (
        "p_huge_value", "p_outside", "p_archive", "p_cameras", "p_toml", "p_no_video",
        "p_garbage_video", "p_truncated_video", "p_small_video")],
    *[(f"{cmd}-{n}", f"{cmd} {{r}}/{n}") for cmd in ("detect", "fit", "run") for n in (
        "missing.toml", "garbage.toml", "syntax.toml", "a_folder")],
    ("run-big-video", "run {r}/p_big_video/project.toml --n-end 300"),
    ("run-no-markers", "run {r}/p_no_markers/project.toml --n-end 300 --plot"),
    ("fit-stale-detections", "fit {r}/p_stale/project.toml"),
    ("batch-missing", "batch {r}/nothing"),
    ("batch-garbage-config", "batch {r}/b_garbage"),
    ("batch-file", "batch {r}/a_file"),
    ("synth-into-file", "synth {r}/a_file --frames 3 --sequences 1"),
    ("synth-broken-chain", "synth {r}/s1 --frames 3 --chain {r}/huge_value.xml"),
    ("synth-garbage-cameras", "synth {r}/s2 --frames 3 --cameras {r}/garbage.toml"),
    ("synth-garbage-angles", "synth {r}/s3 --frames 3 --angles {r}/garbage.csv"),
    ("gui-missing", "gui {r}/missing.toml"),
    ("demo-into-file", "demo --out {r}/a_file --frames 3"),
]

#: Python's way of naming exceptions and warnings, which the user should never see.
RAW = re.compile(r"Traceback \(most recent call last\)|^\w*(Error|Warning|Exception)\b|"
                 r"\b\w+(Error|Warning|Exception): |internal error", re.M)


def run_cli(argv, capfd, monkeypatch):
    """``(code, out, err, stray warnings)`` of one command."""
    stray = []
    shown = cli._show_warning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, VideoTrackWarning):
            shown(message, category, filename, lineno, file, line)
        else:
            stray.append(f"{category.__name__}: {message}")

    monkeypatch.setattr(cli, "_show_warning", show)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        code = main(argv)
    out, err = capfd.readouterr()
    return code, out, err, stray


def check_clean(code, out, err, stray) -> None:
    assert isinstance(code, int)
    assert not RAW.search(out), out
    assert not RAW.search(err), err
    assert stray == []
    assert "stale detections: stale detections" not in err
    if code != 0:
        assert err.strip(), "a failing command says why"
    for line in err.split("\n"):  # one-line messages: each names the program or a file
        line = line.rsplit("\r", 1)[-1].strip()  # what a terminal shows after progress bars
        assert not line or line.startswith("videotrack: ") or re.match(r"\S+: ", line), line


@pytest.mark.parametrize("name, command", CASES, ids=[c[0] for c in CASES])
def test_no_traceback_and_no_stray_warning(root, name, command, capfd, monkeypatch):
    argv = command.format(r=root, g=root / "good").split()
    code, out, err, stray = run_cli(argv, capfd, monkeypatch)
    check_clean(code, out, err, stray)


def test_batch_scheduler_without_dask_names_the_extra(root, capfd, monkeypatch):
    (root / "b_dask" / "s1" / "t1").mkdir(parents=True, exist_ok=True)
    project = root / "b_dask"
    good = root / "good"
    for name in ("chain.xml", "cameras.toml"):
        (project / name).write_bytes((good / name).read_bytes())
    (project / "config.toml").write_text((good / "project.toml").read_text().replace(
        'path = "video.avi"', 'path = "*.avi"'))
    (project / "s1" / "t1" / "walk.avi").write_bytes((good / "video.avi").read_bytes())
    for module in ("dask", "dask.distributed", "distributed"):
        monkeypatch.setitem(sys.modules, module, None)  # import fails as if not installed
    code, out, err, stray = run_cli(["batch", str(project), "--scheduler",
                                     "tcp://127.0.0.1:9"], capfd, monkeypatch)
    check_clean(code, out, err, stray)
    assert code == 1
    assert "pip install 'videotrack[dask]'" in err


def test_a_bug_is_one_line_with_a_hint(capfd, monkeypatch):
    import videotrack.commands.chain as chain_cmd

    def boom(args):
        raise ValueError("zero-size array\nto reduction")

    monkeypatch.setattr(chain_cmd, "run_show", boom)
    monkeypatch.delenv("VIDEOTRACK_DEBUG", raising=False)
    code, _, err, _ = run_cli(["chain", "show", "x.xml"], capfd, monkeypatch)
    assert code == 1 and "Traceback" not in err
    assert err.count("\n") == 1 and "internal error: ValueError: zero-size array to" in err
    assert "VIDEOTRACK_DEBUG=1" in err
    monkeypatch.setenv("VIDEOTRACK_DEBUG", "1")
    with pytest.raises(ValueError):
        main(["chain", "show", "x.xml"])


def test_library_warnings_are_kept_from_the_user(capfd, monkeypatch):
    import numpy as np

    import videotrack.commands.chain as chain_cmd

    def warns(args):
        np.nanmedian(np.array([np.nan]))  # numpy: "All-NaN slice encountered"
        return 0

    monkeypatch.setattr(chain_cmd, "run_show", warns)
    monkeypatch.delenv("VIDEOTRACK_DEBUG", raising=False)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["chain", "show", "x.xml"]) == 0
    assert capfd.readouterr().err == ""
    monkeypatch.setenv("VIDEOTRACK_DEBUG", "1")
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["chain", "show", "x.xml"]) == 0
    assert "debug: RuntimeWarning" in capfd.readouterr().err


def test_messages_of_the_reproductions(root, capfd, monkeypatch):
    """What the issue's reproductions now say (each failed silently or with a traceback)."""
    r = root

    def err_of(command):
        code, out, err, stray = run_cli(command.format(r=r).split(), capfd, monkeypatch)
        check_clean(code, out, err, stray)
        return code, err

    code, err = err_of("chain check {r}/huge_value.xml")
    assert code == 1 and "run value 1e+308 is too large" in err
    code, err = err_of("histograms show {r}/huge_value.xml")
    assert code == 1 and "run value 1e+308 is too large" in err
    code, err = err_of("fit {r}/p_huge_value/project.toml")
    assert code == 1 and "too large" in err
    code, err = err_of("chain check {r}/outside.xml")
    assert code == 1 and "entirely outside the axis range [-30, 60]" in err
    code, err = err_of("fit {r}/p_archive/project.toml")
    assert code == 1 and "archive.xml" in err and "entirely outside the axis range" in err
    code, err = err_of("chain check {r}/no_free_axis.xml")
    assert code == 1 and "nothing to fit" in err
    code, err = err_of("detect {r}/p_small_video/project.toml")
    assert code == 1 and "the views need a frame of at least 720x288" in err
    code, err = err_of("detect {r}/p_big_video/project.toml --force")
    assert "1440x576 pixels, but its views' ROIs reach only the top-left 720x288" in err


def test_outputs_never_replace_an_input(root, capfd, monkeypatch):
    good = root / "good"
    before = (good / "chain.xml").read_bytes()
    for command in ("histograms update {g}/chain.xml {r}/header.csv -o {g}/chain.xml --as-chain",
                    "histograms merge {g}/chain.xml -o {g}/chain.xml --force",
                    "histograms show {g}/chain.xml --plot {g}/chain.xml"):
        code, _, err, _ = run_cli(command.format(r=root, g=good).split(), capfd, monkeypatch)
        assert code == 1 and "an output never replaces an input" in err
    assert (good / "chain.xml").read_bytes() == before


def test_histograms_show_lists_locked_axes_apart(root, capfd, monkeypatch):
    code, out, err, _ = run_cli(["histograms", "show", str(root / "good" / "chain.xml"),
                                 "--plot", str(root / "hist.png")], capfd, monkeypatch)
    assert code == 0, err
    rows = [line.split()[0] for line in out.splitlines()[1:] if not line.startswith(
        ("locked", "wrote"))]
    assert rows == ["J0.phi", "J0.psi", "J0.alpha", "J1.beta", "J2.gamma"]
    assert "locked (not shown): J1.ry, J1.rx, J2.ry, J2.rx" in out
    code, out, _, _ = run_cli(["histograms", "show", str(root / "good" / "chain.xml"),
                               "--axis", "J1.rx"], capfd, monkeypatch)
    assert code == 0 and "J1.rx" in out and "locked (not shown)" not in out


def test_views_that_do_not_fit_the_video_say_so():
    from kinematics.cameras import OrthographicCamera
    from videotrack.detect.views import View, check_camera_sizes, check_views, scaled_video_problem
    from videotrack.errors import VideoTrackError

    views = [View("side", (0, 0, 360, 288)), View("top", (360, 0, 360, 288))]
    with pytest.warns(VideoTrackWarning, match=r"1440x576 pixels, but its views' ROIs reach "
                                               r"only the top-left 720x288"):
        check_views(views, [(1440, 576)])
    assert scaled_video_problem(views, 0, 720, 288) is None
    assert scaled_video_problem(views, 0, 1920, 1080) is None  # other proportions: a crop
    assert scaled_video_problem([View("a", (100, 100, 200, 200))], 0, 1920, 1080) is None
    assert scaled_video_problem([View("a")], 0, 1440, 576) is None  # whole frame
    with pytest.raises(VideoTrackError, match=r"views need a frame of at least 720x288"):
        check_views(views, [(360, 144)])

    cams = {name: OrthographicCamera.from_axes(name, 1.0, ("x", "-y"), (0, 0), size=(360, 288))
            for name in ("side", "top")}
    check_camera_sizes(views, [(720, 288)], cams)
    with pytest.raises(VideoTrackError) as info:
        check_camera_sizes([View("side")], [(720, 576)], cams)
    assert info.value.field == "views[0]"
    assert "view 'side' is 720x576 pixels (the whole frame), but its camera 'side' is " \
           "calibrated for 360x288 images" in str(info.value)
    no_size = {"side": OrthographicCamera.from_axes("side", 1.0, ("x", "-y"), (0, 0))}
    check_camera_sizes([View("side")], [(720, 576)], no_size)
    assert View.from_dict(views[1].to_dict()) == views[1]
