"""mjx_arm.machine.usable_cores: the thread count of MuJoCo C rollouts and tracking."""

import os

import numpy as np
import pytest

from mjx_arm import machine


def test_the_environment_sets_the_thread_count(monkeypatch):
    monkeypatch.setenv(machine.THREADS_ENV, "3")
    assert machine.usable_cores() == 3


@pytest.mark.parametrize("bad", ["0", "-2", "two", "1.5"])
def test_a_bad_thread_count_is_refused_by_name(monkeypatch, bad):
    monkeypatch.setenv(machine.THREADS_ENV, bad)
    with pytest.raises(ValueError, match=machine.THREADS_ENV):
        machine.usable_cores()


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="no CPU affinity on this OS")
def test_without_the_variable_the_cpu_affinity_counts(monkeypatch):
    monkeypatch.delenv(machine.THREADS_ENV, raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    assert machine.usable_cores() == 1


def test_rollout_pools_take_their_threads_from_it(monkeypatch):
    """MuJoCo C rollouts size their thread pools by usable_cores, and the poses do not depend on
    the thread count."""
    import mjx_arm
    from mjx_arm.rollout_c import make_pool

    arm = mjx_arm.load("models/softarm.xml", "constrained")
    program = np.full((3, 20, 3), 1.0)
    monkeypatch.setenv(machine.THREADS_ENV, "1")
    with make_pool(8, 8) as pool:
        assert pool.nthread == 1
    one_thread = arm.rollout(program, backend="c")
    monkeypatch.setenv(machine.THREADS_ENV, "2")
    with make_pool(8, 8) as pool, make_pool(1, 8) as single:
        assert pool.nthread == 2
        assert single.nthread == 1  # never more threads than trajectories
    assert np.array_equal(arm.rollout(program, backend="c"), one_thread)
