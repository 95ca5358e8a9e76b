"""docs/detection.md: the worked example runs as written; the reference matches the schema."""

import re
from pathlib import Path

import numpy as np

from videotrack.cli import main
from videotrack.detect.detections import load_detections
from videotrack.detect.views import View
from videotrack.project.config import FILTER_STEPS, MARKERS, OUTPUT, VIDEO, VIEWS, describe_section
from videotrack.synth.render import render_markers

DOC = Path(__file__).resolve().parents[2] / "docs" / "detection.md"


def test_reference_is_generated_from_the_schema():
    text = DOC.read_text()
    for section in (VIDEO, VIEWS, MARKERS, OUTPUT):
        assert describe_section(section) in text, section.name
    assert describe_section(FILTER_STEPS, level=4) in text
    overview = text[text.index("## Filters"):text.index("## Marker regions")]
    for kind, section in FILTER_STEPS.sections.items():  # every step and key explained
        assert f"`{kind}`" in overview, kind
        assert all(f"`{key.name}`" in overview for key in section.keys), kind


def positions(tau):
    """Planted markers at instant tau (frame coordinates): two moving in the side view, one
    moving in the top view, a static reflection in the side view, one in the mirror's edge."""
    side = [(60 + 7 * tau, 100.3 + 0.5 * tau), (200.6 - 6 * tau, 400.2)]
    top = [(500.4 + 5 * tau, 300.7 - 4 * tau)]
    return np.array(side + top + [(300.0, 50.0), (710.0, 280.0)])


def test_worked_example_runs(tmp_path, video_writer, capsys):
    text = DOC.read_text()
    example = text[text.index("## Worked example"):]
    toml = re.search(r"```toml\n(.*?)```", example, flags=re.S).group(1)
    config = tmp_path / "project.toml"
    config.write_text(toml)
    rng = np.random.default_rng(0)
    frames = []
    for t in range(8):  # bottom field (odd rows) first: odd rows at 2t, even rows at 2t + 1
        frame = render_markers((576, 720), positions(2 * t), 5.0, 200.0, 20.0, 1.0, rng)
        later = render_markers((576, 720), positions(2 * t + 1), 5.0, 200.0, 20.0, 1.0, rng)
        frame[0::2] = later[0::2]
        frames.append(frame)
    video_writer(tmp_path / "walk01.avi", frames)

    assert main(["detect", str(config)]) == 0
    out = capsys.readouterr().out
    assert "markers per view per half-frame (16 half-frames" in out and "walk01.detections" in out
    det = load_detections(tmp_path / "walk01.detections.npz")
    assert det.n_records == 16 and det.frame_rate == 50.0
    np.testing.assert_array_equal(det.parities[:2], [1, 0])
    side, top = View("side", (0, 0, 360, 576)), View("top", (360, 0, 360, 576), flip_x=True)
    for r in range(16):
        truth = positions(r)
        # The reflection is background, the marker on the mirror's edge is masked.
        found_side = side.to_frame(det.points_of(r, "side"))
        found_top = top.to_frame(det.points_of(r, "top"))
        assert len(found_side) == 2 and len(found_top) == 1, r
        d = np.linalg.norm(found_side[:, None] - truth[None, :2], axis=2).min(axis=0)
        assert d.max() < 0.5  # every other row of a 5-px disc: a little aliasing
        assert np.linalg.norm(found_top[0] - truth[2]) < 0.5
