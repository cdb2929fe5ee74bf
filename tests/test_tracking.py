"""Tests of tracking/: metrics (numpy and JAX), the tracking loss, held commands, the oracle."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import optax
import pytest

import mjx_arm  # (before jax computes: the XLA CPU flag)
from mjx_arm import programs
from tracking import held, metrics
from tracking.config import ConfigError
from tracking.oracle import OracleConfig, _load_progress, oracle_commands, start_commands


def test_position_error_by_hand():
    pred = np.array([[0.0, 0.0, 0.0, 0, 0, 1], [0.03, 0.04, 0.0, 0, 0, 1]])
    target = np.zeros((2, 6))
    target[:, 5] = 1.0
    # ||(0.03, 0.04, 0)|| = 0.05 m = 5 cm.
    np.testing.assert_allclose(metrics.position_error_cm(pred, target), [0.0, 5.0])


def test_orientation_error_by_hand():
    d3 = np.array([[0, 0, 1], [0, 1, 0], [0, 0, -1], [1, 1, 0]], dtype=float)
    pred = np.concatenate([np.zeros((4, 3)), d3], axis=1)
    target = np.tile([0, 0, 0, 0, 0, 1.0], (4, 1))
    target[3, 3:] = [1, 0, 0]
    # Same: 0; perpendicular: pi/2; opposite: pi; (1,1,0) unnormalised vs (1,0,0): 45 deg.
    np.testing.assert_allclose(
        metrics.orientation_error_rad(pred, target), [0, np.pi / 2, np.pi, np.pi / 4], atol=1e-7
    )
    # Rounding that pushes the cosine past 1 must not give NaN.
    almost = np.array([[0, 0, 0, 0, 0, 1 + 1e-15]])
    assert metrics.orientation_error_rad(almost, target[:1])[0] == 0.0


def test_tracking_loss_by_hand():
    """1 cm off and 0.1 rad tilted at one of two steps: (1 + 10^2 * 2 (1 - cos 0.1)) / 2."""
    target = np.zeros((2, 6))
    target[:, 5] = 1.0
    poses = target.copy()
    poses[1, 0] = 0.01
    poses[1, 3:] = [np.sin(0.1), 0.0, np.cos(0.1)]
    expected = (1.0 + 100.0 * 2.0 * (1.0 - np.cos(0.1))) / 2.0
    np.testing.assert_allclose(metrics.tracking_loss(poses, target, 10.0), expected, rtol=1e-12)
    got = metrics.tracking_loss(jnp.asarray(poses, jnp.float32), jnp.asarray(target), 10.0)
    np.testing.assert_allclose(float(got), expected, rtol=1e-5)


def test_metrics_take_jax_arrays_under_jit_and_grad():
    """One copy for numpy (float64) and JAX (the inputs' precision, traceable): same values."""
    import jax

    rng = np.random.default_rng(0)
    pred = rng.normal(size=(4, 5, 6))
    target = rng.normal(size=(4, 5, 6))
    for fn in (metrics.position_error_cm, metrics.orientation_error_rad):
        ref = fn(pred, target)
        assert isinstance(ref, np.ndarray) and ref.dtype == np.float64 and ref.shape == (4, 5)
        got = jax.jit(fn)(jnp.asarray(pred, jnp.float32), jnp.asarray(target, jnp.float32))
        assert got.dtype == jnp.float32
        np.testing.assert_allclose(np.asarray(got), ref, rtol=1e-5, atol=1e-5)
    loss = metrics.tracking_loss(pred, target, 10.0)
    assert loss.shape == (4,)

    def total(p):
        return metrics.tracking_loss(p, jnp.asarray(target, jnp.float32), 10.0).sum()

    grad = jax.grad(total)(jnp.asarray(pred, jnp.float32))
    assert grad.shape == pred.shape and np.isfinite(np.asarray(grad)).all()


def test_one_config_error_for_every_layer():
    """ccgan's settings raise the type tracking's do, so one except clause serves every CLI."""
    from ccgan import train

    assert train.ConfigError is ConfigError
    with pytest.raises(ConfigError, match="^oracle.init must be 'mpc' or 'stretch'"):
        OracleConfig(init="zeros")
    with pytest.raises(ConfigError, match="^oracle.learning_rate must be a finite number > 0"):
        OracleConfig(learning_rate=0.0)
    with pytest.raises(ConfigError, match="^oracle.horizon_s must be a length"):
        OracleConfig(horizon_s=0.01)


def test_mean_std_and_summary():
    assert metrics.mean_std([1.0, 3.0]) == (2.0, 1.0)
    assert metrics.format_mean_std([1.0, 3.0]) == "2.00 ± 1.00"
    reps = np.zeros((2, 4, 6))
    reps[1, :, 0] = 0.02  # the two runs are 2 cm apart: each is 1 cm from the mean
    spread = metrics.repetition_spread_cm(reps)
    assert spread["spread_cm_mean"] == pytest.approx(1.0)
    assert spread["spread_cm_max"] == pytest.approx(1.0)


def test_stretch_and_every_kth():
    p = np.arange(6.0).reshape(2, 3)
    s = held.stretch(p, 3)
    assert s.shape == (6, 3)
    np.testing.assert_array_equal(s[:3], np.tile(p[0], (3, 1)))
    poses = np.arange(12.0)[:, None].repeat(6, axis=1)
    np.testing.assert_array_equal(held.every_kth(poses, 4)[:, 0], [3, 7, 11])


@pytest.mark.slow
def test_oracle_lowers_the_loss_and_batches_like_one_program(small_xml, tmp_path):
    """Adam through the MJX rollout: better than its start, in the valve range, and two programs
    optimised together get exactly the iterates each gets alone (Adam acts elementwise)."""
    arm_s = mjx_arm.load(xml=small_xml, domain="source")
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    k, n = 2, 4
    sources = [programs.circle(3.0)[10 : 10 + n], programs.kite(3.0)[10 : 10 + n]]
    targets = np.stack([arm_s.rollout(p, backend="c") for p in sources])
    inits = np.stack([held.stretch(p, k) for p in sources])
    cfg = OracleConfig(steps=4, learning_rate=0.3)
    both, info = oracle_commands(arm_c, targets, inits, k, cfg)
    assert both.shape == (2, n * k, 3)
    lo, hi = arm_c.valve.p_min_bar, arm_c.valve.p_max_bar
    assert both.min() >= lo and both.max() <= hi
    history = np.asarray(info["loss_history"])
    assert history.shape == (4, 2) and np.isfinite(history).all()
    np.testing.assert_allclose(info["best_loss"], history.min(axis=0))
    assert (history.min(axis=0) < history[0]).all()  # it improved on the stretch program
    # One program alone, stopped after two steps with its state in a file, then continued from
    # the file to four: the same iterates as in the batch.
    path = tmp_path / "oracle_progress.npz"
    half = dataclasses.replace(cfg, steps=2)
    oracle_commands(arm_c, targets[1], inits[1], k, half, progress_path=path)
    with np.load(path) as f:
        assert f["history"].shape == (2, 1)
        fingerprint = str(f["fingerprint"])
    one, info_one = oracle_commands(arm_c, targets[1], inits[1], k, cfg, progress_path=path)
    np.testing.assert_allclose(one, both[1], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(info_one["loss_history"], history[:, 1], rtol=1e-5)
    assert len(info_one["step_wall_s"]) == 4
    # The file of another optimisation is not used; a corrupt one is refused by name.
    opt_state = optax.inject_hyperparams(optax.adam)(learning_rate=0.3).init(jnp.zeros((1, 8, 3)))
    assert _load_progress(path, fingerprint + "x", opt_state) is None
    path.write_bytes(b"not an npz")
    with pytest.raises(ValueError, match="unreadable oracle progress"):
        _load_progress(path, fingerprint, opt_state)
    # The tracking error of the returned commands in the C simulator is the optimised one.
    poses = held.run_dc(arm_c, one, k, "c")
    x_err = metrics.position_error_cm(poses, targets[1])
    stretch_err = metrics.position_error_cm(held.run_dc(arm_c, inits[1], k, "c"), targets[1])
    assert x_err.mean() < stretch_err.mean()
    with pytest.raises(ValueError, match="do not match"):
        oracle_commands(arm_c, targets, inits[:, :-1], k, cfg)
    # Held like a translator's output: one command per source step, still better than stretch,
    # and no better than the free oracle, which can do everything the held one can.
    held_cmds, info_held = oracle_commands(arm_c, targets, inits, k, cfg, held=[True, False])
    blocks = held_cmds[0].reshape(n, k, 3)
    np.testing.assert_allclose(blocks, np.broadcast_to(blocks[:, :1], blocks.shape))
    assert not np.allclose(both[0].reshape(n, k, 3), both[0].reshape(n, k, 3)[:, :1])
    np.testing.assert_allclose(held_cmds[1], both[1], rtol=1e-5, atol=1e-6)  # free one untouched
    h = np.asarray(info_held["loss_history"])[:, 0]
    assert h.min() < h[0]
    with pytest.raises(ValueError, match="constant over each step"):
        oracle_commands(arm_c, targets, both, k, cfg, held=True)


def test_stretch_start_and_stretch_k(small_xml):
    """The oracle's "stretch" start is the stretch program; the chosen k has the lowest error."""
    arm_s = mjx_arm.load(xml=small_xml, domain="source")
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    p = programs.validation_program(1.0)
    start = start_commands(arm_c, None, p, 3, OracleConfig(init="stretch"))
    np.testing.assert_array_equal(start, held.stretch(p, 3))
    k, errors = held.choose_stretch_k(arm_s, arm_c, p, (1, 3), progress=False)
    assert set(errors) == {1, 3} and errors[k] == min(errors.values())
    target = arm_s.rollout(p, backend="c")
    poses = held.run_dc(arm_c, held.stretch(p, 3), 3, "c")
    assert errors[3] == pytest.approx(metrics.position_error_cm(poses, target).mean())


def test_saturated_share_counts_commands_at_either_limit():
    from studies.mpc_saturation import saturated_share

    commands = np.array([[0.2, 1.0, 3.5], [0.2 + 1e-3, 3.5 - 1e-7, 2.0]])
    assert saturated_share(commands, 0.2, 3.5) == 3 / 6


def test_stretch_k_study_tries_what_eval_tries():
    from eval.pipeline import EvalConfig
    from studies.stretch_k import CANDIDATES

    assert CANDIDATES == EvalConfig().hold_factors


def test_grouped_rollouts_simulate_equal_commands_once(small_xml, monkeypatch):
    """Equal (commands, k) jobs, such as a deterministic method's repetitions, are simulated once
    and get the poses each job would get on its own; a job that differs is simulated apart."""
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    p = programs.validation_program(0.5)
    other = p.copy()
    other[2, 0] += 0.5
    jobs = [(held.stretch(p, 2), 2), (held.stretch(other, 2), 2), (held.stretch(p, 2), 2)]
    jobs += [(p, 1), (held.stretch(p, 2), 2)]
    simulated = []
    run_dc = held.run_dc
    monkeypatch.setattr(
        held, "run_dc", lambda arm, c, k, b: simulated.append(len(c)) or run_dc(arm, c, k, b)
    )
    got = held.rollout_grouped(arm_c, jobs, "c", progress="test")
    assert sum(simulated) == 3  # the two different programs at k = 2, and the one at k = 1
    for (commands, k), poses in zip(jobs, got, strict=True):
        np.testing.assert_array_equal(poses, run_dc(arm_c, commands, k, "c"))
    assert got[0] is not got[2] and got[0] is not got[4]  # copies, not one shared array
