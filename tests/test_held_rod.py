"""The reference rod through `tracking.held`: `RodArm.rollout`'s backend keyword, and
`rollout_grouped`'s padded batches (the GPU's path) giving the poses of one call per group.

Programs are 0.2-0.8 s (2-8 control periods), so each compiled shape costs about a second.
"""

import numpy as np
import pytest

import mjx_arm
from mjx_arm.programs import held_program
from tracking import held


@pytest.fixture(scope="module")
def rod_c() -> mjx_arm.RodArm:
    return mjx_arm.load_rod("constrained")


class _Spy:
    """A rod that records the [B, N, 3] shape of every call."""

    def __init__(self, rod):
        self.rod, self.calls = rod, []

    def rollout(self, pressures_bar, backend=None):
        self.calls.append(np.shape(pressures_bar))
        return self.rod.rollout(pressures_bar, backend=backend)


def test_rod_rollout_takes_arm_rollouts_backend_keyword_and_refuses_the_chains(rod_c):
    program = held_program(0, 0.3, (1, 2))  # [3, 3] bar
    plain = rod_c.rollout(program)
    for backend in (None, "rod"):
        np.testing.assert_array_equal(rod_c.rollout(program, backend=backend), plain)
    for backend in ("c", "mjx", "ROD", ""):
        with pytest.raises(ValueError, match="reference rod") as err:
            rod_c.rollout(program, backend=backend)
        assert repr(backend) in str(err.value) and "\n" not in str(err.value)


def test_hold_last_pads_with_each_programs_last_command():
    a, b = np.arange(6.0).reshape(2, 3), np.arange(12.0).reshape(4, 3)
    padded = held.hold_last([a, b])
    assert padded.shape == (2, 4, 3)
    np.testing.assert_array_equal(padded[0], [a[0], a[1], a[1], a[1]])
    np.testing.assert_array_equal(padded[1], b)


def test_padding_changes_no_pose(rod_c, monkeypatch, capsys):
    """Jobs of k = 1, 2, 3 and different lengths (a duplicate among them): the padded batches
    give every pose of one call per (length, k) group, to 1e-12 m in float64."""
    programs = [held_program(seed, n / 10, (1, 2)) for seed, n in ((0, 5), (1, 4), (2, 2), (3, 3))]
    # Command lengths 5, 8, 6 and 3 periods.
    jobs = [(held.stretch(p, k), k) for p, k in zip(programs, (1, 2, 3, 1), strict=True)]
    jobs.append(jobs[1])  # a repetition is simulated once and copied
    grouped = held.rollout_grouped(rod_c, jobs, "rod", progress="grouped", padded=False)
    spy = _Spy(rod_c)
    monkeypatch.setattr(held, "ROD_CHUNK", 2)  # two calls: the 4 distinct jobs in chunks of 2
    monkeypatch.setattr(held, "_on_accelerator", lambda: True)  # the GPU's default path
    padded = held.rollout_grouped(spy, jobs, "rod", progress="padded")
    # Longest first, each chunk padded to its own longest: (8, 6 -> 8) then (5, 3 -> 5) periods.
    assert spy.calls == [(2, 8, 3), (2, 5, 3)]
    for (cmd, k), a, b in zip(jobs, grouped, padded, strict=True):
        assert a.shape == b.shape == (len(cmd) // k, 6)
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)
    assert padded[4] is not padded[1] and np.array_equal(padded[4], padded[1])
    # The poses are the jobs' own, not one job's or the rest pose's.
    direct = held.every_kth(rod_c.rollout(jobs[0][0]), 1)
    np.testing.assert_allclose(grouped[0], direct, rtol=0, atol=1e-12)
    assert np.abs(grouped[0][-1, :3] - rod_c.rest_pose()[:3]).max() > 1e-3
    err = capsys.readouterr().err
    for sim_s, longest_s in ((1.4, 0.8), (0.8, 0.5)):
        line = f"padded: the rod runs 2 trajectories together ({sim_s} simulated s, the longest"
        assert f"{line} {longest_s} s)" in err
    # On a CPU the default is one call per (length, k) group, as for the chain.
    monkeypatch.setattr(held, "_on_accelerator", lambda: False)
    spy.calls.clear()
    held.rollout_grouped(spy, jobs[:2], "rod")
    assert sorted(spy.calls) == [(1, 5, 3), (1, 8, 3)]
