"""Promises about the repository itself: package rooms, lint, the README's commands."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_core_packages_never_import_qt():
    code = (
        "import sys, kinematics, videotrack, videotrack.cli\n"
        "import kinematics.fk, kinematics.histograms, kinematics.model\n"
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
    code = ("import numpy as np\nfrom kinematics.fk import forward_kinematics\n"
            "from kinematics.model import *\nimport sys\nsys.path.insert(0, 'tests')\n"
            "from conftest import locust_body\nb = locust_body()\n"
            "forward_kinematics(b, b.mean_posture_deg())\n")
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=REPO, env=env)
    assert out.returncode == 0, out.stderr
    cached = list((tmp_path / "videotrack" / "numba").rglob("*.nbi"))
    assert cached, "no kernel was cached in the user's cache folder"
    assert not list((REPO / "kinematics").rglob("*.nbi"))
