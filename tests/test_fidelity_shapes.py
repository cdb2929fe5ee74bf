"""mjx_arm.fidelity_shapes: the chain against the rod on the five shapes, its distances worked
out by hand, its table, the report section and the update-only command."""

import json

import numpy as np
import pytest

from mjx_arm import fidelity, fidelity_report, fidelity_shapes

ROW = {
    "tip_rms_cm": 1.29,
    "tip_max_cm": 1.42,
    "tip_rms_of_length": 0.0645,
    "rod_rms_excursion_cm": 12.54,
    "tip_rms_of_excursion": 0.103,
}


def test_tip_differences_are_the_rms_and_largest_tip_distance():
    chain = np.zeros((2, 6))
    rod = np.zeros((2, 6))
    rod[0, :3] = [0.03, 0.04, 0.0]  # 5 cm off
    rod[1, 3:] = [1.0, 0.0, 0.0]  # d3 differs: not a tip distance
    rms, largest = fidelity_shapes.tip_differences(chain, rod)
    assert largest == pytest.approx(0.05)
    assert rms == pytest.approx(np.sqrt(0.05**2 / 2))


def test_rms_excursion_is_measured_from_rest():
    poses = np.zeros((2, 6))
    poses[:, 2] = [0.1, 0.3]
    assert fidelity_shapes.rms_excursion(poses, np.array([0.0, 0.0, 0.2])) == pytest.approx(0.1)


def test_the_table_has_a_row_per_domain_and_shape():
    result = {"duration_s": 60.0, "table": {"source": {"damped_circle": ROW}}}
    lines = fidelity_shapes.shapes_lines(result)
    assert lines[-1] == "| source | damped circle | 1.29 | 6.5% | 1.42 | 12.54 | 10% |"


def test_the_comparison_runs_both_arms_on_every_shape():
    result = fidelity_shapes.shape_comparison(0.3, log=lambda _: None)
    for domain in fidelity_shapes.DOMAINS:
        rows = result["table"][domain]
        assert len(rows) == 5
        for row in rows.values():
            assert 0 <= row["tip_rms_cm"] <= row["tip_max_cm"]
            assert row["tip_rms_of_length"] == pytest.approx(row["tip_rms_cm"] / 20.0)
    with pytest.raises(ValueError, match="duration_s"):
        fidelity_shapes.shape_comparison(0.0)


def test_only_shapes_updates_the_stored_report(tmp_path, monkeypatch):
    committed = json.loads((fidelity.constants.ROOT / "results" / "fidelity.json").read_text())
    committed.pop("shapes", None)
    (tmp_path / "fidelity.json").write_text(json.dumps(committed))
    table = {"duration_s": 60.0, "arm_length_m": 0.2, "table": {"source": {"circle": ROW}}}
    monkeypatch.setattr(fidelity_shapes, "shape_comparison", lambda: table)
    assert fidelity.main(["--out", str(tmp_path), "--only", "shapes"]) == 0
    stored = json.loads((tmp_path / "fidelity.json").read_text())
    assert stored["shapes"] == table and stored["rows"] == committed["rows"]
    report = (tmp_path / "fidelity.md").read_text()
    assert "## The five shapes' programs" in report and "| source | circle | 1.29 |" in report
    assert report == fidelity_report.to_markdown(stored)


def test_only_shapes_needs_a_stored_report(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        fidelity.main(["--out", str(tmp_path), "--only", "shapes"])
    assert stop.value.code == 2 and "does not exist" in capsys.readouterr().err
