"""The user's manual stays true: generated references are current, every TOML example loads,
and the examples of the guides run as written.

Conventions for examples in docs/ (a Markdown comment on the line before a fenced block):

- ``<!-- test -->`` before a ```bash or ```python block: the test suite runs it;
- ``<!-- test: OLD => NEW -->``: runs it with OLD replaced by NEW (smaller sizes, so the
  suite stays quick, while the page shows the command a user types);
- ``<!-- test file: PATH -->`` before any block: its text is written to PATH first (a config
  file the following commands use);
- ``<!-- not run: why -->``: deliberately not run (e.g. installing the package).

The blocks of one page run in order in one temporary folder. In the guides listed in GUIDES
every bash and python block must carry one of these marks.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import re
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import videotrack.project.folders  # noqa: F401  (registers [batch])
from videotrack.project.config import SECTIONS, parse_layer

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
GUIDES = ("getting-started.md", "concepts.md", "batch.md", "config.md", "fitting.md",
          "markerless.md", "calibration.md")
BLOCK = re.compile(r"(?:<!-- (?P<mark>[^\n]*?) -->\n)?```(?P<lang>[\w-]*)\n(?P<body>.*?)^```",
                   re.S | re.M)


def blocks(path: Path):
    """(mark or None, language, text) of every fenced block of a Markdown file."""
    return [(m["mark"], m["lang"], m["body"]) for m in BLOCK.finditer(path.read_text())]


def load_tool(name: str):
    spec = importlib.util.spec_from_file_location(name, REPO / "tools" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cli_reference_is_up_to_date():
    expected = load_tool("make_cli_docs").render()
    assert (DOCS / "cli.md").read_text() == expected, "run python tools/make_cli_docs.py"
    for command in ("batch", "demo", "eval", "detect", "fit", "synth", "calibrate",
                    "keypoints"):
        assert f"## `videotrack {command}`" in expected


def test_config_reference_is_up_to_date():
    tool = load_tool("make_config_docs")
    text = (DOCS / "config.md").read_text()
    assert tool.render(text) == text, "run python tools/make_config_docs.py"
    for name, section in SECTIONS.items():  # every key, with type and default
        head = f"[[{name}]]" if section.array else f"[{name}]"
        assert f"### `{head}`" in text, name
        for key in section.keys:
            cell = key.type.replace("|", "\\|")
            assert f"| `{key.name}` | {cell} |" in text, f"{name}.{key.name}"


def toml_blocks():
    for path in sorted([*DOCS.glob("*.md"), REPO / "README.md"]):
        for i, (_, lang, body) in enumerate(blocks(path)):
            if lang == "toml":
                yield pytest.param(path, body, id=f"{path.name}-{i}")


@pytest.mark.parametrize("path, body", list(toml_blocks()))
def test_toml_examples_load(path, body, tmp_path):
    raw = tomllib.loads(body)
    # a project config (not a camera file, whose [cameras.NAME] tables share a name)
    cameras = raw.get("cameras", {})
    if set(raw) <= set(SECTIONS) and set(cameras) <= {"path"}:
        parse_layer(raw, tmp_path / "config.toml")


@pytest.mark.parametrize("guide", GUIDES)
def test_every_example_of_the_guides_is_marked(guide):
    for mark, lang, body in blocks(DOCS / guide):
        if lang in ("bash", "sh", "python"):
            assert mark and (mark == "test" or mark.startswith(("test:", "test file:",
                                                                "not run:"))), body


def run_block(lang: str, body: str, cwd: Path) -> None:
    env = {**os.environ, "PATH": os.path.dirname(sys.executable) + os.pathsep
           + os.environ.get("PATH", ""), "PYTHONUNBUFFERED": "1"}
    command = (["bash", "-euo", "pipefail", "-c", body] if lang == "bash" else
               [sys.executable, "-c", body])
    proc = subprocess.Popen(command, cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=240)
    finally:  # background processes the block started (a Dask scheduler, workers)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, f"{body}\n---\n{out.decode(errors='replace')}"


@pytest.mark.parametrize("guide", [g for g in GUIDES if any(
    m and m.startswith("test") for m, _, _ in blocks(DOCS / g))])
def test_examples_run(guide, tmp_path):
    ran = 0
    for mark, lang, body in blocks(DOCS / guide):
        if not mark or not mark.startswith("test"):
            continue
        if mark.startswith("test file:"):
            target = tmp_path / mark.removeprefix("test file:").strip()
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(body)
            continue
        if mark.startswith("test:"):
            old, new = (s.strip() for s in mark.removeprefix("test:").split("=>"))
            assert old in body, f"{old!r} is not in the block"
            body = body.replace(old, new)
        run_block(lang, body, tmp_path)
        ran += 1
    assert ran
