"""Promises about the repository itself: package rooms, lint, the README's commands."""

import ast
import os
import re
import subprocess
import sys

import pytest

from tests.fixtures.paths import BIND_TESTS_PACKAGE, REPO, TESTS


def test_core_packages_never_import_qt():
    code = (
        "import sys, kinematics, videotrack, videotrack.cli\n"
        "import kinematics.model.fk, kinematics.model.histograms, kinematics.model\n"
        "videotrack.cli.build_parser()\n"
        "qt = ('PySide6', 'pyqtgraph', 'ui')\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in qt)\n"
        "print(bad)\nsys.exit(1 if bad else 0)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 0, out.stdout + out.stderr


def test_ruff_is_clean():
    ruff = subprocess.run([sys.executable, "-m", "ruff", "check", "."], capture_output=True,
                          text=True, cwd=REPO)
    if "No module named ruff" in ruff.stderr:
        pytest.skip("ruff is not installed")
    assert ruff.returncode == 0, ruff.stdout + ruff.stderr


def test_ci_runs_the_readme_test_command():
    readme = (REPO / "README.md").read_text()
    commands = re.findall(r"```(?:bash|sh)\n(.*?)```", readme, flags=re.S)
    assert len(commands) >= 2, "README must start with the two commands"
    test_command = commands[1].strip()
    assert "pytest" in test_command
    assert test_command in (REPO / ".ci" / "run").read_text()


def test_numba_cache_stays_out_of_the_package(tmp_path):
    """Compiled kernels are cached under the user's cache folder, never in site-packages
    (files pip does not know would survive an uninstall and shadow the next install)."""
    code = ("import numpy as np\nfrom kinematics.model.fk import forward_kinematics\n"
            "from kinematics.model import *\n" + BIND_TESTS_PACKAGE +
            "from tests.fixtures.bodies import locust_body\nb = locust_body()\n"
            "forward_kinematics(b, b.mean_posture_deg())\n")
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=REPO, env=env)
    assert out.returncode == 0, out.stderr
    cached = list((tmp_path / "videotrack" / "numba").rglob("*.nbi"))
    assert cached, "no kernel was cached in the user's cache folder"
    assert not list((REPO / "kinematics").rglob("*.nbi"))


#: Calls that import the module or file a string names.
IMPORTING_CALLS = {"import_module", "__import__", "spec_from_file_location", "SourceFileLoader",
                   "run_path", "import_path"}
#: A line of a code string that imports (a child process's ``python -c`` script).
IMPORT_LINE = re.compile(r"^[ \t]*(?:from|import)[ \t]+\S.*$", re.M)


def _names_a_test_module(name: str) -> bool:
    """``name`` (dotted, or a file path) names a test module or a conftest."""
    return any(p == "conftest" or p.startswith("test_") for p in re.split(r"[./\\]", name))


def imports_of_test_modules(source: str, where: str = "<string>") -> list[str]:
    """Where ``source`` imports a test module or a conftest: import statements (absolute or
    relative), importing calls (importlib) given such a name or file, and the import lines
    of strings with line breaks (code for a child process)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        at = f"{where}:{getattr(node, 'lineno', '?')}"
        if isinstance(node, ast.Import):
            found += [f"{at}: import {a.name}" for a in node.names if _names_a_test_module(a.name)]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            names = [a.name for a in node.names]
            from_tests = node.level or module.split(".")[0] == "tests"
            if _names_a_test_module(module) or (from_tests and any(map(_names_a_test_module,
                                                                         names))):
                found.append(f"{at}: from {'.' * node.level}{module} import {', '.join(names)}")
        elif isinstance(node, ast.Call):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if name in IMPORTING_CALLS:
                found += [f"{at}: {name}(... {s.value!r} ...)" for s in ast.walk(node)
                          if isinstance(s, ast.Constant) and isinstance(s.value, str)
                          and _names_a_test_module(s.value)]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and "\n" in node.value:
            for line in IMPORT_LINE.findall(node.value):
                try:
                    inner = imports_of_test_modules(line.strip())
                except SyntaxError:  # prose that starts with 'import'
                    continue
                found += [f"{at}: in a code string: {line.strip()}" for _ in inner[:1]]
    return found


def test_no_test_module_imports_another_or_a_conftest():
    """Shared builders live in tests/fixtures (registered as plugins by the root conftest);
    a test module that imports another one runs that module's code twice under two names,
    and a conftest is pytest's to import."""
    found = []
    for path in sorted(TESTS.rglob("*.py")):
        found += imports_of_test_modules(path.read_text(), str(path.relative_to(REPO)))
    assert not found, "import these from tests/fixtures instead:\n" + "\n".join(found)


@pytest.mark.parametrize("source", [
    "from tests.kinematics.test_partitions import planted",
    "from .test_anneal import planted",
    "from test_free_root import mouse_like",
    "from tests.conftest import CHAINS",
    "from tests.ui.conftest import SHORT_ANNEAL",
    "import conftest",
    "import tests.kinematics.test_lanes as lanes",
    "from . import test_lanes",
    "from tests.kinematics import test_lanes",
    'spec = importlib.util.spec_from_file_location("kp", here.with_name("test_io_keypoints.py"))',
    'mod = importlib.import_module("tests.kinematics.test_anneal")',
    'SCRIPT = "import sys\\nsys.path.insert(0, \'tests\')\\nfrom conftest import locust_body\\n"',
])
def test_the_import_check_finds_test_modules_and_conftests(source):
    assert len(imports_of_test_modules(source)) == 1


@pytest.mark.parametrize("source", [
    "from tests.fixtures.bodies import leg",
    "from .bodies import LEG_XML",
    "import pytest",
    "from kinematics.anneal import Fitter",
    'WINDOWLESS = {"test_adapters.py", "test_session.py"}',
    'CODE = "import numpy\\nfrom tests.fixtures.bodies import locust_body\\n"',
    'DOC = """Import the tracks.\\nimport them all, then fit."""',
])
def test_the_import_check_lets_fixtures_and_others_pass(source):
    assert imports_of_test_modules(source) == []


def _kernel_functions():
    """(module path, name, parameter count) of every numba function of the packages."""
    found = []
    for path in [*sorted((REPO / "kinematics" / "_kernels").glob("*.py")),
                 REPO / "videotrack" / "detect" / "_kernels.py"]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef) and any(
                    "jit" in ast.unparse(d) for d in node.decorator_list):
                found.append((path, node.name, len(node.args.args) + bool(node.args.vararg)))
    return found


def _called_from_outside_the_kernels() -> set[str]:
    """Names the library's other modules take from a kernel module (its entry points):
    imported from one, or read as an attribute of a kernel module imported under a name."""
    names = set()
    for path in [*REPO.glob("kinematics/**/*.py"), *REPO.glob("videotrack/**/*.py"),
                 *REPO.glob("ui/**/*.py")]:
        if "_kernels" in path.parts or path.name == "_kernels.py":
            continue
        modules = set()
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and "_kernels" in node.module:
                for alias in node.names:
                    if node.module.endswith("_kernels"):  # a kernel module under a name
                        modules.add(alias.asname or alias.name)
                    else:
                        names.add(alias.name)
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and \
                    node.value.id in modules:
                names.add(node.attr)
    return names


def test_kernels_take_records_not_long_argument_lists():
    """At most 24 parameters for a numba function, 16 for an entry point (called from
    outside the kernel modules): the rest travels in named records."""
    entry = _called_from_outside_the_kernels()
    assert {"fit_frames", "fit_frames_lanes", "refine_frames"} <= entry
    long = [f"{path.name}:{name} ({n})" for path, name, n in _kernel_functions()
            if n > (16 if name in entry else 24)]
    assert not long, long
