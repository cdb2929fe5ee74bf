"""studies.program_length: the window split of X_err, and one tiny run end to end."""

import json

import numpy as np
import pytest

from studies.program_length import main, split_errors


def test_split_errors_separates_the_window_from_the_rest():
    err = np.array([[1.0, 1.0, 4.0, 4.0, 4.0], [3.0, 3.0, 6.0, 6.0, 6.0]])
    out = split_errors(err, window=2)
    assert out["window"] == pytest.approx(2.0)
    assert out["after"] == pytest.approx(5.0)
    assert out["whole"] == pytest.approx(err.mean())


@pytest.mark.parametrize("window", [0, 5, 9])
def test_split_errors_refuses_a_window_that_splits_nothing(window):
    with pytest.raises(ValueError, match="must split"):
        split_errors(np.ones((2, 5)), window)


def test_a_tiny_run_scores_every_method_against_the_teacher(tmp_path):
    out = tmp_path / "length"
    main(["--n", "1", "--duration", "1.5", "--window-s", "0.5", "--out", str(out)])
    result = json.loads(out.with_suffix(".json").read_text())
    methods = set(result["x_err_cm"])
    assert methods == {"stretch", "teacher (mpc)"} | {f"translator seed {s}" for s in range(3)}
    for errors in result["x_err_cm"].values():
        assert all(np.isfinite(v) and v > 0 for v in errors.values())
    # On the same programs the teacher tracks better than holding the source commands.
    assert result["x_err_cm"]["teacher (mpc)"]["whole"] < result["x_err_cm"]["stretch"]["whole"]
    assert "| teacher (mpc) | " in out.with_suffix(".md").read_text()
    assert out.with_suffix(".png").stat().st_size > 0


def test_a_window_as_long_as_the_programs_is_a_usage_error(tmp_path):
    with pytest.raises(SystemExit):
        main(["--n", "1", "--duration", "1", "--window-s", "1", "--out", str(tmp_path / "x")])
