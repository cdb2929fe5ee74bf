"""`mjx_arm.babble` estimates its memory before any work and refuses a run that cannot fit."""

import dataclasses

import pytest

from mjx_arm import babble
from mjx_arm.babble import cli


def test_memory_estimate_counts_every_dataset_kept():
    config = dataclasses.replace(babble.PAPER, n_train=100, n_val=10, duration_s=10.0)
    per_trajectory = 100 * (3 + 6) * 4  # T = 100 steps of 3 pressures and 6 pose values, float32
    kept = 2 * 110 * per_trajectory  # both domains, both splits
    again = 100 * per_trajectory  # the largest split once more while it is made and written
    chunk = 100 * babble.C_BYTES_PER_TRAJECTORY  # one MuJoCo C chunk of min(4096, 100)
    assert babble.memory_estimate_bytes(config) == kept + again + chunk


def test_a_run_too_large_for_the_memory_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    big = dataclasses.replace(babble.PAPER, n_train=2_000_000)
    with pytest.raises(babble.NotEnoughMemoryError, match="GB of memory") as exc:
        babble.check_memory(big, available=16 * 10**9)
    assert "16 GB are available" in str(exc.value) and "per domain fit" in str(exc.value)
    assert babble.check_memory(babble.PAPER, available=16 * 10**9) < 10**9
    # The library refuses too, before loading any arm.
    monkeypatch.setattr(babble, "available_memory_bytes", lambda: 16 * 10**9)
    monkeypatch.setattr(babble.arm_lib, "load", lambda *a, **k: pytest.fail("did work"))
    with pytest.raises(babble.NotEnoughMemoryError):
        babble.babble(big, progress=False)
    # The command line: a usage error naming the estimate, no folder made.
    out = tmp_path / "babble"
    with pytest.raises(SystemExit) as stopped:
        cli.main(["--n", "2000000", "--out", str(out)])
    assert stopped.value.code == 2 and "GB of memory" in capsys.readouterr().err
    assert not out.exists()
