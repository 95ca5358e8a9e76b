"""A project whose one chain is seen among ghosts in four views: the window decides where its
markers are matched on the whole video, so a re-fit of one frame and a marker hidden by hand
are matched as the fit of every frame was."""

from __future__ import annotations

import tomllib

import tomli_w

from tests.fixtures.projects import cluttered_leg_project
from tests.fixtures.settings import SHORT_ANNEAL
from videotrack.cli import main


def test_a_cluttered_chain_is_matched_in_3d_for_every_task(tmp_path, window_on, wait_idle):
    cluttered_leg_project(tmp_path)
    config = tmp_path / "project.toml"
    raw = tomllib.loads(config.read_text())
    raw["anneal"] = {**raw.get("anneal", {}), **SHORT_ANNEAL}
    config.write_text(tomli_w.dumps(raw))
    assert main(["detect", str(config)]) == 0
    s = window_on(config).session
    assert s.params.match == "auto"
    fitter = s._fitter()  # a task on one frame: decided on the whole video, not that frame
    assert fitter.params.match == "3d"
    notes = []
    s.status.connect(notes.append)
    s.fit([3])
    wait_idle(s)
    assert "markers matched in 3D: 3.0 detections per marker image" in notes[0]
    r = s.results[3]
    assert r.status != "failed"
    view = [s.fit_detections.points_of(3, v) for v in range(len(s.view_names))]
    assert fitter.error(r.angles_deg, view)[0] == r.error
    errors = []
    s.error.connect(errors.append)
    assert not s.toggle_hidden(0, 0)
    assert "matched in 3D" in errors[-1]
