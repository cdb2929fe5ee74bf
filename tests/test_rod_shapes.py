"""studies.rod_shapes: its distances worked out by hand, its table, and its refusals."""

import numpy as np
import pytest

from studies import rod_shapes


def test_tip_differences_are_the_rms_and_largest_tip_distance():
    chain = np.zeros((2, 6))
    rod = np.zeros((2, 6))
    rod[0, :3] = [0.03, 0.04, 0.0]  # 5 cm off
    rod[1, 3:] = [1.0, 0.0, 0.0]  # d3 differs: not a tip distance
    rms, largest = rod_shapes.tip_differences(chain, rod)
    assert largest == pytest.approx(0.05)
    assert rms == pytest.approx(np.sqrt(0.05**2 / 2))


def test_rms_excursion_is_measured_from_rest():
    poses = np.zeros((2, 6))
    poses[:, 2] = [0.1, 0.3]
    assert rod_shapes.rms_excursion(poses, np.array([0.0, 0.0, 0.2])) == pytest.approx(0.1)


def test_the_table_has_a_row_per_domain_and_shape():
    row = {
        "tip_rms_cm": 1.29,
        "tip_max_cm": 1.42,
        "tip_rms_of_length": 0.0645,
        "rod_rms_excursion_cm": 12.54,
        "tip_rms_of_excursion": 0.103,
    }
    result = {"duration_s": 60.0, "table": {"source": {"damped_circle": row}}}
    lines = rod_shapes.report_lines(result)
    assert lines[-1] == "| source | damped circle | 1.29 | 6.5% | 1.42 | 12.54 | 10% |"


def test_a_program_length_of_zero_is_refused_before_any_work(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        rod_shapes.main(["--out", str(tmp_path), "--seconds", "0"])
    assert stop.value.code == 2 and "--seconds" in capsys.readouterr().err
