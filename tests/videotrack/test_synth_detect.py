"""The two halves agree: videos made by ``videotrack synth`` detect at their ground truth."""

import numpy as np
import pytest

from videotrack.cli import main
from videotrack.detect.detections import load_detections
from videotrack.results.tables import read_table


@pytest.mark.parametrize("options", [[], ["--interlaced", "--bottom-field-first"]])
def test_detections_match_synth_ground_truth(tmp_path, capsys, options):
    out = tmp_path / "proj"
    assert main(["synth", str(out), "--frames", "12", "--sequences", "2", "--noise", "2",
                 "--seed", "3", *options]) == 0
    assert main(["detect", str(out / "project.toml")]) == 0
    capsys.readouterr()
    det = load_detections(out / "detections.npz")
    cols, truth = read_table(out / "truth.csv")
    assert det.n_records == truth.shape[0] == 12  # one record per rendered image (field)
    errors = []
    for v, view in enumerate(det.view_names):
        markers = sorted({c.split(".")[1] for c in cols if c.startswith(f"{view}.")})
        u = truth[:, [cols.index(f"{view}.{m}.u") for m in markers]]
        w = truth[:, [cols.index(f"{view}.{m}.v") for m in markers]]
        for r in range(det.n_records):
            planted = np.c_[u[r], w[r]]
            found = det.points_of(r, v)
            # markers whose discs overlap another's are fused by design: skip them
            gaps = np.linalg.norm(planted[:, None] - planted[None], axis=2)
            alone = (gaps + 1e3 * np.eye(len(planted))).min(axis=1) > 8
            d = np.linalg.norm(planted[alone][:, None] - found[None], axis=2).min(axis=1)
            errors += list(d)
    errors = np.array(errors)
    assert len(errors) > 50
    interlaced = bool(options)  # each field keeps every other row of a 4-px disc
    assert errors.max() < (0.6 if interlaced else 0.1)
    assert np.sqrt(np.mean(errors**2)) < (0.25 if interlaced else 0.05)
