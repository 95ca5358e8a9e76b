"""`videotrack histograms update/merge/show` on a results file with known angles."""

import numpy as np
import pytest

from kinematics.model.chain_xml import load_body
from kinematics.model.histogram_xml import load_archive
from kinematics.model.histograms import bin_index
from videotrack.cli import main
from videotrack.results.files import results_from_fit, write_results


@pytest.fixture
def results_file(tmp_path, locust):
    from kinematics.fit import FrameResult

    chain = tmp_path / "chain.xml"
    from kinematics.model.chain_xml import save_body

    save_body(chain, locust)
    base = locust.mean_posture_deg()
    rows = []
    for k, status in enumerate(["ok", "ok", "failed"]):
        a = base.copy()
        a[-1] = 30.5 + k  # gamma: 30.5, 31.5 (ok) and 32.5 (failed)
        rows.append(FrameResult(k, a, 1.0, np.array([0.5, 0.5]), 1, 100, 0, status,
                                np.zeros((1, 3))))
    path = tmp_path / "r.csv"
    write_results(path, results_from_fit(locust, rows, ["side", "top"]), {"markers": 4})
    return chain, path


def test_update_applies_eq4_to_ok_frames(results_file, tmp_path, capsys):
    chain, res = results_file
    out = tmp_path / "learned.xml"
    assert main(["histograms", "update", str(chain), str(res), "-o", str(out)]) == 0
    assert "learned from 2 frames" in capsys.readouterr().out
    h = load_archive(out)[("hindleg", "J2", "gamma")]
    # uniform over 140 bins with N = 1, then two observations: (1/140 + 1) / 3 in their bins
    assert h.n_trials == 3
    assert h.values[bin_index(30.5)] == pytest.approx((1 / 140 + 1) / 3)
    assert h.values[bin_index(32.5)] == pytest.approx((1 / 140) / 3)
    locked = load_archive(out)[("hindleg", "J1", "rx")]
    assert locked.n_trials == 1  # locked axes are not learned
    # as a chain file, with every frame
    chain_out = tmp_path / "chain2.xml"
    assert main(["histograms", "update", str(chain), str(res), "--all-frames", "--as-chain",
                 "-o", str(chain_out)]) == 0
    body = load_body(chain_out)
    assert body.chains[0].root_joint.segments[0].joints[0].segments[0].joints[0].axes[
        2].histogram.n_trials == 4


def test_merge_and_show(results_file, tmp_path, capsys):
    chain, res = results_file
    a = tmp_path / "a.xml"
    main(["histograms", "update", str(chain), str(res), "-o", str(a)])
    merged = tmp_path / "m.xml"
    assert main(["histograms", "merge", str(a), str(chain), "-o", str(merged)]) == 0
    assert load_archive(merged)[("hindleg", "J2", "gamma")].n_trials == 4
    capsys.readouterr()
    assert main(["histograms", "show", str(merged), "--axis", "J2.gamma", "--plot",
                 str(tmp_path / "h.png")]) == 0
    out = capsys.readouterr().out
    assert "J2.gamma" in out and "J0.phi" not in out and (tmp_path / "h.png").exists()
    assert main(["histograms", "show", str(merged), "--axis", "J9.nope"]) == 1


def test_update_rejects_results_of_another_chain(results_file, tmp_path, capsys):
    chain, res = results_file
    res.write_text(res.read_text().replace("J2.gamma", "J2.delta"))
    assert main(["histograms", "update", str(chain), str(res), "-o",
                 str(tmp_path / "x.xml")]) == 1
    assert "no column for axis J2.gamma" in capsys.readouterr().err
    assert not (tmp_path / "x.xml").exists()
