"""A wrong set-up is refused before fitting, with its cause in one line and exit ≠ 0; a right
one fits; --accept-setup fits a wrong one and keeps the warning with the results."""

import json
import shutil

import pytest

from tests.fixtures.setup_cases import make_case
from videotrack.cli import main


@pytest.fixture(scope="module")
def synth_project(tmp_path_factory):
    out = tmp_path_factory.mktemp("setup") / "base"
    assert main(["synth", str(out), "--frames", "60", "--sequences", "1"]) == 0
    return out


@pytest.mark.parametrize("case, cause", [
    ("camera scale x2", "disagree in 3D"),
    ("views swapped", "the chain does not fit the detections"),
    ("chain lengths x3", "the chain does not fit the detections"),
    ("another animal's chain", "the chain does not fit the detections"),
    ("video of noise", ("too few detections", "disagree in 3D", "blobs are not the markers")),
])
def test_a_wrong_set_up_is_refused_with_its_cause(synth_project, tmp_path, capsys, case, cause):
    project = make_case(case, synth_project, tmp_path / "p")
    assert main(["run", str(project)]) == 1
    err = capsys.readouterr().err
    line = next(ln for ln in err.splitlines() if "error:" in ln)
    causes = (cause,) if isinstance(cause, str) else cause
    assert any(c in line for c in causes), line
    assert "--accept-setup" in line and "Traceback" not in err
    assert not (tmp_path / "p" / "detections.results.csv").exists()  # nothing half-done


def test_a_right_set_up_fits_and_records_its_noise(synth_project, tmp_path):
    project = make_case("right", synth_project, tmp_path / "p")
    assert main(["run", str(project)]) == 0
    side = json.loads((tmp_path / "p" / "detections.results.csv.json").read_text())
    assert side["noise"]["source"] == "measured"
    assert all(0.5 <= s < 1.0 for s in side["noise"]["sigma_px"])
    assert not any("set-up" in w for w in side["warnings"])


def test_accept_setup_fits_and_keeps_the_warning(synth_project, tmp_path, capsys):
    project = make_case("camera scale x2", synth_project, tmp_path / "p")
    assert main(["run", str(project), "--accept-setup"]) in (0, 3)
    side = json.loads((tmp_path / "p" / "detections.results.csv.json").read_text())
    assert any("disagree in 3D" in w for w in side["warnings"])
    capsys.readouterr()
    main(["fit", str(project), "--accept-setup"])  # up to date: the warning is said again
    assert "disagree in 3D" in capsys.readouterr().err
    # and the config key does what the flag does
    shutil.rmtree(tmp_path / "p")
    project = make_case("camera scale x2", synth_project, tmp_path / "p")
    with project.open("a") as f:
        f.write("\n[anneal]\naccept_setup = true\n")
    assert main(["run", str(project)]) in (0, 3)
