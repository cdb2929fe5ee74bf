"""The reference rod through `tracking.held`: `RodArm.rollout`'s backend keyword, and
`rollout_grouped`'s padded batches (the GPU's path) giving the poses of one call per group.

Programs are 0.2-0.8 s (2-8 control periods), so each compiled shape costs about a second.
"""

import os
import subprocess
import sys

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

    def __init__(self, rod, call_size=None):
        self.rod, self.calls, self.size = rod, [], call_size

    def call_size(self):
        return self.size

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


def test_padding_changes_no_pose(rod_c, capsys):
    """Jobs of k = 1, 2, 3 and different lengths (a duplicate among them): the padded batches
    give every pose of one call per (length, k) group, to 1e-12 m in float64."""
    programs = [held_program(seed, n / 10, (1, 2)) for seed, n in ((0, 5), (1, 4), (2, 2), (3, 3))]
    # Command lengths 5, 8, 6 and 3 periods.
    jobs = [(held.stretch(p, k), k) for p, k in zip(programs, (1, 2, 3, 1), strict=True)]
    jobs.append(jobs[1])  # a repetition is simulated once and copied
    grouped = held.rollout_grouped(rod_c, jobs, "rod", progress="grouped", padded=False)
    spy = _Spy(rod_c, call_size=2)  # as on a GPU or the host's devices: two calls of 2
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
    # On one CPU device (no call size) the default is one call per (length, k) group, as for
    # the chain.
    spy.size = None
    spy.calls.clear()
    held.rollout_grouped(spy, jobs[:2], "rod")
    assert sorted(spy.calls) == [(1, 5, 3), (1, 8, 3)]


def test_host_devices_split_the_rod_and_change_no_pose():
    """Two fake host CPU devices (a fresh process): `RodArm.rollout` splits 3 programs (padded to
    4) over them, and the poses are those of one device, to 1e-12 m in float64; the grouped and
    babbling paths take `call_size` (4 per device) calls."""
    code = """
import numpy as np
import jax, mjx_arm
from mjx_arm import rod_arm
from mjx_arm.babble import rod as rod_babble
from mjx_arm.programs import held_program
from tracking import held
assert len(jax.devices("cpu")) == 2 and len(rod_arm.host_devices()) == 2
rod = mjx_arm.load_rod("constrained")
assert rod.placement() == "host" and rod.call_size() == 8
programs = np.stack([held_program(seed, 0.4, (1, 2)) for seed in range(3)])
split = rod.rollout(programs)
grouped = held.rollout_grouped(rod, [(p, 1) for p in programs[:2]] + [(programs[2][:2], 1)], "rod")
babbled = rod_babble.simulate_rod(rod, programs, chunk=2)
rod_arm.host_devices = lambda: []
assert rod.placement() == "cpu" and rod.call_size() is None
one = rod.rollout(programs)
assert split.shape == one.shape == (3, 4, 6)
np.testing.assert_allclose(split, one, rtol=0, atol=1e-12)
np.testing.assert_allclose(babbled, one, rtol=0, atol=1e-12)
for a, b in zip(grouped, [one[0], one[1], rod.rollout(programs[2][:2])]):
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
assert np.abs(one[0] - one[1]).max() > 1e-4
print("ok")
"""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    env["JAX_PLATFORMS"] = "cpu"
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-3000:]
