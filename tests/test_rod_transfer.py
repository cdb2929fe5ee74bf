"""`studies.rod_transfer`'s held-out programs: each family asked for, none when it is not."""

from __future__ import annotations

import numpy as np
import pytest

from studies import rod_transfer


@pytest.mark.parametrize("n_shape_like", [0, 1])
def test_the_programs_hold_each_family_asked_for(n_shape_like):
    programs, families = rod_transfer.programs_by_family(n_shape_like, 1, 2.0)
    assert programs.shape == (2 * n_shape_like + 2, 20, 3) and len(families) == len(programs)
    assert families[-2:] == ["babbling", "held"] and np.isfinite(programs).all()
    assert len(set(families[:-2])) <= 2 * n_shape_like  # the shape-like programs' kinds


def test_no_program_at_all_is_refused_before_any_work(capsys):
    with pytest.raises(SystemExit):
        rod_transfer.main(["--translators", "x=y.ckpt", "--n-shape-like", "0", "--n-other", "0",
                           "--out", "/tmp/never"])  # fmt: skip
    assert "no program to score" in capsys.readouterr().err
