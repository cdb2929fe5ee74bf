"""`mjx_arm.babble` estimates its memory before any work and refuses a run that cannot fit."""

import dataclasses
import re

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
    assert "16 GB are available" in str(exc.value) and "trajectories per domain" in str(exc.value)
    assert babble.check_memory(babble.PAPER, available=16 * 10**9) < 10**9
    # The library refuses too, before loading any arm.
    monkeypatch.setattr(babble.memory, "available_memory_bytes", lambda: 16 * 10**9)
    monkeypatch.setattr(babble.arm_lib, "load", lambda *a, **k: pytest.fail("did work"))
    with pytest.raises(babble.NotEnoughMemoryError):
        babble.babble(big, progress=False)
    # The command line: a usage error naming the estimate, no folder made.
    out = tmp_path / "babble"
    with pytest.raises(SystemExit) as stopped:
        cli.main(["--n", "2000000", "--out", str(out)])
    assert stopped.value.code == 2 and "GB of memory" in capsys.readouterr().err
    assert not out.exists()


def test_mujoco_c_runs_count_the_chunk_they_hold_not_the_flag():
    """MuJoCo C simulates C_MAX_CHUNK trajectories at a time whatever --chunk is: 5000 x 60 s
    (18.8 GB with the whole --chunk 4096 counted) fits 16 GB, as the run with --chunk 256 does;
    MJX keeps its states on the device, only one chunk's programs and poses on the host."""
    config = dataclasses.replace(babble.PAPER, n_train=5000, duration_s=60.0, backend="c")
    small_chunk = dataclasses.replace(config, chunk=babble.C_MAX_CHUNK)
    need = babble.memory_estimate_bytes(config)
    assert need == babble.memory_estimate_bytes(small_chunk) < 2 * 10**9
    assert babble.check_memory(config, available=16 * 10**9) == need
    per_trajectory = 600 * (3 + 6) * 4
    kept_and_again = (2 * 5003 + 5000) * per_trajectory
    mjx = dataclasses.replace(config, backend="mjx")
    assert babble.memory_estimate_bytes(mjx) == kept_and_again + 4096 * per_trajectory
    auto = dataclasses.replace(config, backend="auto")
    assert babble.memory_estimate_bytes(auto) == max(need, babble.memory_estimate_bytes(mjx))


@pytest.mark.parametrize("backend", ["c", "mjx", "auto"])
@pytest.mark.parametrize("available_gb", [2, 16])
def test_following_the_hint_is_accepted(backend, available_gb):
    big = dataclasses.replace(babble.PAPER, n_train=20_000_000, duration_s=60.0, backend=backend)
    available = available_gb * 10**9
    with pytest.raises(babble.NotEnoughMemoryError) as exc:
        babble.check_memory(big, available=available)
    n_fit = int(re.search(r"--n (\d+) ", str(exc.value)).group(1))
    assert n_fit > 0
    babble.check_memory(dataclasses.replace(big, n_train=n_fit), available=available)
    with pytest.raises(babble.NotEnoughMemoryError):  # and it is the most that fits
        babble.check_memory(dataclasses.replace(big, n_train=n_fit + 1), available=available)


def test_the_hint_says_when_nothing_fits():
    config = dataclasses.replace(babble.PAPER, n_val=3, backend="c")
    with pytest.raises(babble.NotEnoughMemoryError, match="not even --n 1 fits"):
        babble.check_memory(config, available=10**7)
