"""bench.step_latency: an unrolled physics loop gives the same poses to float32 rounding."""

import json

import pytest

from bench.step_latency import main


@pytest.mark.slow
def test_an_unrolled_loop_steps_the_same_arm(tmp_path):
    """Two compiles of the arm's rollout (unroll 1 and 2) on a CPU: minutes."""
    out = tmp_path / "latency"
    main(["--batch", "1", "--periods", "2", "--unrolls", "1", "2", "--repeats", "1"]
         + ["--out", str(out)])  # fmt: skip
    rows = json.loads(out.with_suffix(".json").read_text())["rows"]
    assert [row["unroll"] for row in rows] == [1, 2]
    assert rows[1]["tip_diff_mm"] < 1e-5  # float32 rounding of other fusions: 3e-8 mm seen
    assert all(row["ms_per_step"] > 0 and row["compile_s"] > 0 for row in rows)
    assert out.with_suffix(".md").read_text().count("\n| ") == 3  # header and two rows


def test_bad_sizes_are_refused(capsys):
    with pytest.raises(SystemExit):
        main(["--unrolls", "0", "--out", "unused"])
    assert "must be >= 1" in capsys.readouterr().err
