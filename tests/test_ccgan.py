"""Tests of the CCGAN-GP package: data, networks, losses, checkpoints, training and resumption.

Tiny configurations on CPU. The end-to-end tests share one simulated data set (a 3-segment arm)
and one XLA compilation cache, so the three driver runs of the resume test compile once.
"""

import dataclasses
import math
import os
import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ccgan
import mjx_arm  # noqa: F401  (sets the XLA CPU flag before JAX creates its backend)
from ccgan import checkpoint, losses, models
from ccgan import config as config_lib
from ccgan import data as data_lib
from ccgan import forward as forward_lib
from ccgan import train as train_lib
from mjx_arm.programs import random_held_programs
from tracking import held, metrics
from tracking.config import ConfigError

# ----------------------------------------------------------------------------- data


def test_normalisation_round_trip_and_range():
    rng = np.random.default_rng(0)
    poses = rng.normal(size=(3, 7, 6))
    bounds = data_lib.pose_bounds(poses, poses + 1.0)
    x = data_lib.normalise_pose(poses, bounds)
    assert x.min() >= 0.0 and x.max() <= 1.0
    # mjx_arm.dataset's rule: float64 arithmetic, float32 results.
    assert x.dtype == np.float32
    np.testing.assert_allclose(data_lib.denormalise_pose(x, bounds), poses, atol=1e-6)
    # 3.5 bar is the top of the valve range -> 1.0; 1.75 bar -> 0.5.
    np.testing.assert_allclose(data_lib.normalise_pressure(np.array([3.5, 1.75])), [1.0, 0.5])


def test_windows_and_holdout_unpaired():
    rng = np.random.default_rng(0)
    ps, xs = rng.uniform(0, 3.5, (5, 12, 3)), rng.normal(size=(5, 12, 6))
    pc, xc = rng.uniform(0, 3.5, (4, 9, 3)), rng.normal(size=(4, 9, 6))  # other N and T
    d = data_lib.prepare(ps, xs, pc, xc, window_length=4, n_val=1)
    # D_s: 4 training trajectories x floor(12 / 4) windows; D_c: 3 x floor(9 / 4).
    assert d.source.train.shape == (12, 4, 9)
    assert d.constrained.train.shape == (6, 4, 9)
    assert d.source.val.shape == (1, 12, 9) and d.constrained.val.shape == (1, 9, 9)
    # The held-out trajectory is the last one, untouched by windowing.
    np.testing.assert_allclose(d.source.val[0, :, :3], ps[-1] / 3.5, rtol=1e-6)
    # Window 1 of trajectory 0 is steps 4..7; its previous poses are steps 3..6.
    np.testing.assert_allclose(d.source.train_prev_pose[1, 1:], d.source.train[1, :-1, 3:])
    np.testing.assert_allclose(d.source.train_prev_pose[1, 0], d.source.train[0, -1, 3:])
    with pytest.raises(ValueError):
        data_lib.prepare(ps, xs[:, :5], pc, xc, window_length=4, n_val=1)


# ----------------------------------------------------------------------------- networks


@pytest.mark.parametrize("t", [1, 6])
def test_network_shapes_no_nan(t):
    key = jax.random.PRNGKey(0)
    x = jax.random.uniform(key, (2, t, 9))
    fwd = models.ForwardModel()
    fp = fwd.init(key, x[..., 3:], x[..., :3])
    y = fwd.apply(fp, x[..., 3:], x[..., :3])
    assert y.shape == (2, t, 6) and jnp.isfinite(y).all()
    gen = models.Generator()
    g = gen.apply(gen.init(key, x), x)
    assert g.shape == (2, t, 9) and jnp.isfinite(g).all()
    assert (g[..., :3] >= 0).all() and (g[..., :3] <= 1).all()  # squashed pressures
    critic = models.Critic()
    c = critic.apply(critic.init(key, x), x)
    assert c.shape == (2,) and jnp.isfinite(c).all()


def test_generator_variants_per_sample_and_residual():
    key = jax.random.PRNGKey(1)
    x = jax.random.uniform(key, (2, 7, 9), minval=0.05, maxval=0.95)
    # Per sample (the authors' sequence length 1): each step's output is its own sample's, so
    # reversing time reverses the output; the recurrent G carries its state and does not.
    per = models.Generator(hidden=8, fc=16, per_sample=True)
    params = per.init(key, x)
    np.testing.assert_allclose(per.apply(params, x[:, ::-1]), per.apply(params, x)[:, ::-1], 1e-6)
    rec = models.Generator(hidden=8, fc=16)
    rp = rec.init(key, x)
    assert not np.allclose(rec.apply(rp, x[:, ::-1]), rec.apply(rp, x)[:, ::-1], atol=1e-4)
    # Same variables either way: only the carry differs.
    assert jax.tree.structure(params) == jax.tree.structure(rp)
    # Residual: the identity at initialisation, and a correction once its last layer moves.
    res = models.Generator(hidden=8, fc=16, residual=True)
    r_params = res.init(key, x)
    np.testing.assert_allclose(res.apply(r_params, x), x, atol=1e-6)
    moved = jax.tree.map(lambda v: v + 0.1, r_params)
    y = res.apply(moved, x)
    assert not np.allclose(y, x, atol=1e-3) and (y[..., :3] > 0).all() and (y[..., :3] < 1).all()


def test_time_conv_equals_flax_conv():
    """The critic's matmul convolution: nn.Conv's variables, init and values (kernel 3 and 4)."""
    import flax.linen as nn

    x = jax.random.normal(jax.random.PRNGKey(0), (2, 3, 7, 5))  # extra leading axis (vmap-like)
    for kernel in (3, 4):
        ours, ref = models.TimeConv(6, kernel), nn.Conv(6, (kernel,), padding="SAME")
        v_ours, v_ref = ours.init(jax.random.PRNGKey(1), x), ref.init(jax.random.PRNGKey(1), x)
        assert jax.tree.map(jnp.shape, v_ours) == jax.tree.map(jnp.shape, v_ref)
        for a, b in zip(jax.tree.leaves(v_ours), jax.tree.leaves(v_ref), strict=True):
            np.testing.assert_array_equal(a, b)
        v = jax.tree.map(lambda a: a + 0.1, v_ref)  # non-zero bias too
        np.testing.assert_allclose(ours.apply(v, x), ref.apply(v, x), rtol=1e-5, atol=1e-5)


def test_stretched_forward_matches_held_open_loop():
    key = jax.random.PRNGKey(1)
    fwd = models.ForwardModel(hidden=8, fc=5)
    p = jax.random.uniform(key, (2, 4, 3))
    pose0 = jax.random.uniform(jax.random.PRNGKey(2), (2, 6))
    fp = fwd.init(key, pose0[:, None], p[:, :1])
    open_loop = models.forward_open_loop(fwd, fp, p, pose0)
    # k = 1 is a plain open-loop rollout, whatever k_max is.
    np.testing.assert_allclose(
        models.forward_stretched(fwd, fp, p, pose0, 1, 3), open_loop, rtol=1e-5, atol=1e-6
    )
    # k = 2: each command held twice; the pose after every second period is kept.
    held = models.forward_open_loop(fwd, fp, jnp.repeat(p, 2, axis=1), pose0)[:, 1::2]
    np.testing.assert_allclose(
        models.forward_stretched(fwd, fp, p, pose0, jnp.int32(2), 3), held, rtol=1e-5, atol=1e-6
    )


def test_stretched_forward_equals_masked_reference_values_and_gradients():
    """The live-periods-only loop (custom VJP) against the masked k_max scan, for two k."""
    fwd = models.ForwardModel(hidden=8, fc=5)
    p = jax.random.uniform(jax.random.PRNGKey(1), (2, 4, 3))
    pose0 = jax.random.uniform(jax.random.PRNGKey(2), (2, 6))
    fp = fwd.init(jax.random.PRNGKey(0), pose0[:, None], p[:, :1])
    weights = jax.random.normal(jax.random.PRNGKey(3), (2, 4, 6))

    def loss(fn, k, **kw):
        return lambda p, x0: jnp.sum(weights * fn(fwd, fp, p, x0, k, 5, **kw))

    for impl in ("lean", "lean_reduce"):
        # unroll=3 does not divide T * k: the last iteration of the loop is partly masked.
        for k in (2, 5):
            new = models.forward_stretched(fwd, fp, p, pose0, k, 5, unroll=3, impl=impl)
            ref = models.forward_stretched_masked(fwd, fp, p, pose0, k, 5)
            np.testing.assert_allclose(new, ref, rtol=1e-5, atol=1e-6)
            g_new = jax.grad(loss(models.forward_stretched, k, unroll=3, impl=impl), (0, 1))(
                p, pose0
            )
            g_ref = jax.grad(loss(models.forward_stretched_masked, k), (0, 1))(p, pose0)
            for a, b in zip(g_new, g_ref, strict=True):
                np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)

        # Vmapped over k (seeds with different k): the loop runs to the largest k, masked per k.
        ks = jnp.array([2, 5])
        grad_new = jax.vmap(
            lambda k, impl=impl: jax.grad(loss(models.forward_stretched, k, unroll=4, impl=impl))(
                p, pose0
            )
        )
        grad_ref = jax.vmap(lambda k: jax.grad(loss(models.forward_stretched_masked, k))(p, pose0))
        np.testing.assert_allclose(grad_new(ks), grad_ref(ks), rtol=1e-5, atol=1e-6)

        # One compilation serves every k.
        jitted = jax.jit(
            lambda k, impl=impl: models.forward_stretched(fwd, fp, p, pose0, k, 5, impl=impl)
        )
        for k in (1, 2, 5):
            jitted(jnp.int32(k))
        assert jitted._cache_size() == 1


# ----------------------------------------------------------------------------- losses


def test_wasserstein_and_adversarial_losses():
    real, fake = jnp.array([1.0, 3.0]), jnp.array([0.0, 2.0])
    # E[fake] - E[real] = 1 - 2 = -1.
    assert losses.critic_loss(real, fake) == pytest.approx(-1.0)
    # -E[fake] = -(0 + 2) / 2 = -1.
    assert losses.generator_adversarial_loss(fake) == pytest.approx(-1.0)


def test_gradient_penalty_by_hand():
    key = jax.random.PRNGKey(0)
    real = jnp.zeros((2, 1, 2))
    fake = jnp.ones((2, 1, 2))
    # Linear critic C(x) = 2 * x[..., 0]: gradient (2, 0) everywhere, norm 2, (2 - 1)^2 = 1.
    linear = lambda x: 2.0 * x[:, 0, 0]  # noqa: E731
    assert losses.gradient_penalty(linear, real, fake, key) == pytest.approx(1.0, rel=1e-5)
    # C(x) = 0.5 * |x|^2 has gradient x. With real = fake = (3, 4) every interpolate is (3, 4):
    # norm 5, (5 - 1)^2 = 16.
    quad = lambda x: 0.5 * jnp.sum(x**2, axis=(1, 2))  # noqa: E731
    x = jnp.tile(jnp.array([3.0, 4.0]), (2, 1, 1))
    assert losses.gradient_penalty(quad, x, x, key) == pytest.approx(16.0, rel=1e-5)
    # A 1-Lipschitz critic with unit gradient (C = x0) pays nothing.
    unit = lambda x: x[:, 0, 0]  # noqa: E731
    assert losses.gradient_penalty(unit, real, fake, key) == pytest.approx(0.0, abs=1e-5)


def test_cycle_identity_feedback_and_errors_by_hand():
    a = jnp.array([[[1.0, -3.0]]])
    zero = jnp.zeros_like(a)
    # L1: (|1| + |-3|) / 2 = 2.
    assert losses.cycle_loss(a, zero) == pytest.approx(2.0)
    assert losses.identity_loss(zero, a) == pytest.approx(2.0)
    # MSE: (1 + 9) / 2 = 5.
    assert losses.feedback_loss(a, zero) == pytest.approx(5.0)
    pred = jnp.array([0.03, 0.04, 0.0, 1.0, 0.0, 0.0])
    target = jnp.array([0.0, 0.0, 0.0, 0.0, 2.0, 0.0])  # d3 need not be unit for the cosine
    # ||(3, 4, 0) cm|| = 5 cm; d3 at right angles: pi / 2.
    assert metrics.position_error_cm(pred, target) == pytest.approx(5.0, rel=1e-5)
    assert metrics.orientation_error_rad(pred, target) == pytest.approx(math.pi / 2, rel=1e-5)


def test_one_adamw_step_lowers_forward_loss():
    key = jax.random.PRNGKey(0)
    fwd = models.ForwardModel(hidden=8, fc=8)
    x = jax.random.uniform(key, (4, 5, 9))
    params = fwd.init(key, x[..., 3:], x[..., :3])
    target = jnp.full((4, 5, 6), 0.5)

    def loss_fn(p):
        return jnp.mean((fwd.apply(p, x[..., 3:], x[..., :3]) - target) ** 2)

    import optax

    tx = optax.adamw(1e-2, weight_decay=1e-4)
    before, grads = jax.value_and_grad(loss_fn)(params)
    updates, _ = tx.update(grads, tx.init(params), params)
    assert loss_fn(optax.apply_updates(params, updates)) < before


# ----------------------------------------------------------------------------- checkpoints


def test_checkpoint_round_trip_and_refusals(tmp_path):
    tree = {"a": np.arange(4.0), "b": {"c": np.ones((2, 2), np.float32)}}
    path = checkpoint.save(tmp_path / "x.ckpt", tree, {"config": {"lr": 1.0}})
    restored, meta = checkpoint.load(path, target=tree, expect={"config": {"lr": 1.0}})
    np.testing.assert_array_equal(restored["b"]["c"], tree["b"]["c"])
    assert meta["config"] == {"lr": 1.0}
    assert not list(tmp_path.glob("*.tmp"))  # the temporary file was renamed away

    with pytest.raises(checkpoint.CheckpointError, match="does not match this run"):
        checkpoint.load(path, target=tree, expect={"config": {"lr": 2.0}})
    with pytest.raises(checkpoint.CheckpointError, match="fit|shapes"):
        checkpoint.load(path, target={"a": np.arange(5.0), "b": {"c": np.ones((2, 2))}})

    blob = bytearray(path.read_bytes())
    blob[-5] ^= 0xFF  # flip a payload byte
    bad = tmp_path / "bad.ckpt"
    bad.write_bytes(bytes(blob))
    with pytest.raises(checkpoint.CheckpointError, match="corrupt"):
        checkpoint.load(bad, target=tree)
    bad.write_bytes(path.read_bytes()[: len(blob) // 2])  # truncated, as by a crash mid-write
    with pytest.raises(checkpoint.CheckpointError):
        checkpoint.load(bad, target=tree)
    with pytest.raises(checkpoint.CheckpointError, match="no checkpoint"):
        checkpoint.load(tmp_path / "missing.ckpt")


# ----------------------------------------------------------------------------- training


TINY = config_lib.TrainConfig(
    epochs=4,
    batch_size=4,
    window_length=5,
    n_val=1,
    hold_factors=(1, 2),
    stretch_every=2,
    k_choice="forward",
    checkpoint_every=2,
    gen_hidden=8,
    gen_fc=16,
    critic_features=(8, 8, 8, 8, 8),
)


@pytest.fixture(scope="module")
def compile_cache(tmp_path_factory):
    """A persistent XLA cache for this module, so identical driver runs compile once."""
    old = {
        n: getattr(jax.config, n)
        for n in (
            "jax_compilation_cache_dir",
            "jax_persistent_cache_min_compile_time_secs",
            "jax_persistent_cache_min_entry_size_bytes",
        )
    }
    jax.config.update("jax_compilation_cache_dir", str(tmp_path_factory.mktemp("xla")))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    yield
    for n, v in old.items():
        jax.config.update(n, v)


@pytest.fixture(scope="module")
def tiny_setup(compile_cache):
    """Simulated babbling in both domains (3-segment arm), prepared data and a trained F_c."""
    xml = mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), n_segments=3))
    rng = np.random.default_rng(0)
    arrays = []
    for domain, n in (("source", 5), ("constrained", 4)):  # unpaired: different counts
        arm = mjx_arm.load(xml=xml, domain=domain)
        p = random_held_programs(rng, n, 30)
        arrays += [p, data_lib.simulate(arm, p)]
    data = data_lib.prepare(*arrays, window_length=TINY.window_length, n_val=TINY.n_val)
    fconf = forward_lib.ForwardConfig(epochs=15, batch_size=6, hidden=16, fc=16)
    fparams, hist, metrics = forward_lib.train_forward(fconf, data.constrained, data.bounds)
    return data, fconf, fparams, hist, metrics


def test_forward_model_learns(tiny_setup):
    _, _, _, hist, metrics = tiny_setup
    assert hist[-1] < hist[0]
    assert all(np.isfinite(v) for v in metrics.values())
    assert set(metrics) == {"one_step_cm", "one_step_rad", "open_loop_cm", "open_loop_rad"}


def test_forward_open_loop_training_rolls_out_its_own_predictions(tiny_setup):
    """Open-loop training equals teacher forcing on one-step windows (the first prediction of
    both starts from the recorded pose) and differs from it on longer windows."""
    data = tiny_setup[0]
    split = data.constrained
    fconf = forward_lib.ForwardConfig(epochs=3, batch_size=6, hidden=8, fc=8)

    def trained(open_loop: bool, window: int):
        one = data_lib.DomainSplit(
            train=split.train[:, :window],
            train_prev_pose=split.train_prev_pose[:, :window],
            val=split.val,
            val_prev_pose=split.val_prev_pose,
        )
        conf = dataclasses.replace(fconf, open_loop=open_loop)
        return jax.jit(forward_lib.make_train_forward(conf, one))(jax.random.PRNGKey(0))

    (tf1, h_tf1), (ol1, h_ol1) = trained(False, 1), trained(True, 1)
    np.testing.assert_allclose(np.asarray(h_ol1), np.asarray(h_tf1), rtol=1e-5)
    for a, b in zip(jax.tree.leaves(tf1), jax.tree.leaves(ol1), strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-4, atol=1e-6)
    (_, h_tf), (_, h_ol) = trained(False, split.train.shape[1]), trained(True, split.train.shape[1])
    assert not np.allclose(np.asarray(h_tf), np.asarray(h_ol))
    assert np.isfinite(np.asarray(h_ol)).all() and h_ol[-1] < h_ol[0]


def _params_equal(a, b):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(np.array_equal(x, y) for x, y in zip(la, lb, strict=True))


def test_end_to_end_and_resume_equals_uninterrupted(tiny_setup, tmp_path):
    data, fconf, fparams, _, _ = tiny_setup
    kw = dict(seeds=(0, 1), forward_model=fconf.model, progress=False)
    full, rows = train_lib.train_and_evaluate(TINY, data, fparams, tmp_path / "full", **kw)

    # End to end: every loss term logged and finite for both seeds, k from the choices.
    assert len(rows) == 2 * TINY.epochs
    for row in rows:
        for m in train_lib.METRICS:
            if m != "val_error_cm":
                assert np.isfinite(float(row[m])), m
        assert int(float(row["k"])) in TINY.hold_factors
    assert np.isfinite([float(r["val_error_cm"]) for r in rows if int(r["epoch"]) % 2 == 0]).all()
    # Written without the data's domains and arm, so unlabelled (ccgan.train's CLI labels them).
    tr = ccgan.load_translator(tmp_path / "full" / "translator.ckpt", trust_unlabelled=True)
    ps = np.full((7, 3), 1.0)
    xs = np.tile(data_lib.denormalise_pose(data.source.val[0, 0, 3:], data.bounds), (7, 1))
    pc, k = tr.translate(ps, xs)
    assert k in TINY.hold_factors and pc.shape == (7 * k, 3)
    assert np.isfinite(pc).all() and pc.min() >= 0.0 and pc.max() <= 3.5
    assert tr.predict_poses(pc, xs[0]).shape == (7 * k, 6)

    # Killed after the first checkpoint, then resumed: the same parameters, bit for bit.
    half, _ = train_lib.train_and_evaluate(
        TINY, data, fparams, tmp_path / "cut", max_chunks=1, **kw
    )
    assert int(half.epoch[0]) == 2 and not _params_equal(half.params, full.params)
    # Stored under a retired feedback rollout: resumed with this run's, with a warning.
    ckpt = tmp_path / "cut" / "state.ckpt"
    tree, meta = checkpoint.load(ckpt)
    checkpoint.save(ckpt, tree, meta | {"config": meta["config"] | {"feedback_impl": "pallas"}})
    with pytest.warns(UserWarning, match="feedback_impl='pallas', a retired rollout"):
        resumed, rows2 = train_lib.train_and_evaluate(TINY, data, fparams, tmp_path / "cut", **kw)
    assert _params_equal(resumed.params, full.params)
    assert _params_equal(resumed.opt_gen, full.opt_gen)
    assert [r["epoch"] for r in rows2] == [r["epoch"] for r in rows]

    # Asked to stop (SIGTERM in the CLI) during its first epoch: it checkpoints after that
    # epoch, off the chunk grid, writes no translator, and the resumed run ends bit for bit.
    stop = threading.Event()
    stop.set()
    stopped, _ = train_lib.train_and_evaluate(
        TINY, data, fparams, tmp_path / "stopped", stop=stop, **kw
    )
    assert int(stopped.epoch[0]) == 1 and not (tmp_path / "stopped" / "translator.ckpt").exists()
    resumed, _ = train_lib.train_and_evaluate(TINY, data, fparams, tmp_path / "stopped", **kw)
    assert _params_equal(resumed.params, full.params)

    # A run with another config refuses the checkpoint, naming the changed field.
    other = dataclasses.replace(TINY, lambda_cycle=3.0)
    with pytest.raises(checkpoint.CheckpointError, match="lambda_cycle: stored 10.0, this run 3.0"):
        train_lib.train_and_evaluate(other, data, fparams, tmp_path / "cut", **kw)


def test_k_chosen_in_the_target_arm_like_the_authors_and_resumed_exactly(tiny_setup, tmp_path):
    """k_choice "simulator": G_c's held-out commands run in the D_c arm at every k, per seed."""
    from ccgan.sim_choice import SimulatorChoice

    data, fconf, fparams, _, _ = tiny_setup
    xml = mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), n_segments=3))
    arm_c = mjx_arm.load(xml=xml, domain="constrained")
    config = dataclasses.replace(
        TINY, k_choice="simulator", hold_factors=(1, 3), stretch_every=3, k_choice_seconds=2.0
    )
    judge = SimulatorChoice(arm_c, data, config)
    assert judge.n_steps == 20  # 2 s at 10 Hz

    # Refused without the simulator.
    with pytest.raises(ValueError, match="SimulatorChoice"):
        train_lib.train_and_evaluate(config, data, fparams, tmp_path / "none", progress=False)

    kw = dict(seeds=(0, 1), forward_model=fconf.model, progress=False, k_choice=judge)
    full, rows = train_lib.train_and_evaluate(config, data, fparams, tmp_path / "full", **kw)
    choices = train_lib.read_rows(tmp_path / "full" / "k_choices.csv")
    # Before training, after epoch 3 (stretch_every) and after the last (4), for both seeds.
    assert [(r["epoch"], r["seed"]) for r in choices] == [(e, s) for e in (0, 3, 4) for s in (0, 1)]
    last = {r["seed"]: r for r in choices if r["epoch"] == 4}
    _, best_meta = checkpoint.load(tmp_path / "full" / "best_gen.ckpt")
    for s_i, seed in enumerate((0, 1)):
        errors = [last[seed][f"error_cm_k{k}"] for k in config.hold_factors]
        assert int(full.k[s_i]) == config.hold_factors[int(np.argmin(errors))]
        row = next(r for r in rows if r["seed"] == seed and r["epoch"] == 4)
        assert row["val_error_cm"] == pytest.approx(min(errors), rel=1e-6)
        # keep_best: the translator is the seed's trained G_c at its scored epoch (3 or 4) with
        # the lowest held-out error, with that epoch's k; the untrained one (epoch 0) never counts.
        scored = [r for r in choices if r["seed"] == seed and r["epoch"] > 0]
        best = min(scored, key=lambda r: r[f"error_cm_k{int(r['k'])}"])
        assert best_meta["best_epoch"][s_i] == best["epoch"]
        tr = ccgan.load_translator(
            tmp_path / "full" / f"translator_seed{seed}.ckpt", trust_unlabelled=True
        )
        assert tr.k == int(best["k"])
        final_g_c = train_lib.generator(jax.tree.map(lambda x, i=s_i: x[i], full.params), 0)
        if best["epoch"] == 4:
            assert _params_equal(tr.g_c_params, final_g_c)

        # The error at each k, by hand: seed's G_c on the first 2 s of the held-out program,
        # held k periods, from rest in the D_c arm, every k-th pose against the D_s poses.
        gen = models.Generator(hidden=config.gen_hidden, fc=config.gen_fc)
        g_c = train_lib.generator(jax.tree.map(lambda x, i=s_i: x[i], full.params), 0)
        out = np.asarray(gen.apply(g_c, jnp.asarray(data.source.val)))[:, :20]
        cmd = data_lib.denormalise_pressure(out[..., :3]).astype(np.float64)
        target = data_lib.denormalise_pose(data.source.val[:, :20, 3:], data.bounds)
        for k, err in zip(config.hold_factors, errors, strict=True):
            poses = held.every_kth(arm_c.rollout(held.stretch(cmd, k), backend="c"), k)
            assert metrics.position_error_cm(poses, target).mean() == pytest.approx(err, rel=1e-4)

    # The D_c arm is slower: the untranslated program held 3 periods tracks better than at 1.
    stretch_only = judge.stretch_only_errors()
    assert stretch_only[1] < stretch_only[0]

    # Cut after the first chunk and resumed: the same parameters, k and choice log.
    train_lib.train_and_evaluate(config, data, fparams, tmp_path / "cut", max_chunks=1, **kw)
    resumed, _ = train_lib.train_and_evaluate(config, data, fparams, tmp_path / "cut", **kw)
    assert _params_equal(resumed.params, full.params)
    assert np.array_equal(resumed.k, full.k)
    assert train_lib.read_rows(tmp_path / "cut" / "k_choices.csv") == choices
    for seed in (0, 1):
        a, b = (
            ccgan.load_translator(
                tmp_path / run / f"translator_seed{seed}.ckpt", trust_unlabelled=True
            )
            for run in ("full", "cut")
        )
        assert a.k == b.k and _params_equal(a.g_c_params, b.g_c_params)
    # keep_best off: the last epoch's G_c and k, as before.
    last_only = dataclasses.replace(config, keep_best=False)
    final, _ = train_lib.train_and_evaluate(last_only, data, fparams, tmp_path / "last", **kw)
    tr = ccgan.load_translator(tmp_path / "last" / "translator_seed1.ckpt", trust_unlabelled=True)
    assert tr.k == int(final.k[1])
    assert _params_equal(
        tr.g_c_params, train_lib.generator(jax.tree.map(lambda x: x[1], final.params), 0)
    )


class _ScriptedChoice:
    """A `SimulatorChoice` stand-in whose held-out errors (cm, one row [S] per scoring, the
    same at every k) follow a script, so that the early stop is decided by known numbers."""

    def __init__(self, script, hold_factors):
        self.script, self.hold_factors, self.calls = list(script), hold_factors, 0

    def choose(self, g_c_params):
        from ccgan.sim_choice import Choice

        error = np.asarray(self.script[self.calls], float)
        self.calls += 1
        errors = np.repeat(error[:, None], len(self.hold_factors), 1)
        return Choice(k=np.full(len(error), self.hold_factors[0]), error_cm=error, errors_cm=errors)


def test_patience_stops_once_no_seed_improves_and_writes_the_best(tiny_setup, tmp_path):
    """patience 2 with a scoring every 2 epochs: seed 0 improves last at epoch 4, seed 1 at 2,
    so the scorings at 6 and 8 improve nothing and training ends at epoch 8 of 40, with each
    seed's best G_c written; a rerun in the same folder trains no further."""
    data, fconf, fparams, _, _ = tiny_setup
    config = dataclasses.replace(
        TINY, epochs=40, k_choice="simulator", hold_factors=(1, 2), stretch_every=2, patience=2
    )
    # Before training (never counts), then after epochs 2, 4, 6, 8, ...
    script = [[9, 9], [5, 4], [3, 4.5], [3.5, 4.1], [3.2, 4.2]] + [[1, 1]] * 20
    judge = _ScriptedChoice(script, config.hold_factors)
    kw = dict(seeds=(0, 1), forward_model=fconf.model, progress=False, k_choice=judge)
    state, rows = train_lib.train_and_evaluate(config, data, fparams, tmp_path / "run", **kw)
    assert int(state.epoch[0]) == 8 and judge.calls == 5
    assert max(r["epoch"] for r in rows) == 8
    _, best_meta = checkpoint.load(tmp_path / "run" / "best_gen.ckpt")
    assert best_meta["best_epoch"] == [4, 2]
    assert best_meta["best_error_cm"] == [3.0, 4.0]
    for seed in (0, 1):
        assert (tmp_path / "run" / f"translator_seed{seed}.ckpt").is_file()
    # Resumed (a chain's rerun): settled already, so no epoch and no scoring more.
    again, _ = train_lib.train_and_evaluate(config, data, fparams, tmp_path / "run", **kw)
    assert int(again.epoch[0]) == 8 and judge.calls == 5
    # Without patience the same script trains all 40 epochs.
    judge = _ScriptedChoice(script, config.hold_factors)
    kw["k_choice"] = judge
    full, _ = train_lib.train_and_evaluate(
        dataclasses.replace(config, epochs=10, patience=0), data, fparams, tmp_path / "all", **kw
    )
    assert int(full.epoch[0]) == 10 and judge.calls == 6


def test_patience_needs_the_simulator_scores():
    with pytest.raises(train_lib.ConfigError, match="patience"):
        config_lib.TrainConfig(patience=2, keep_best=False)
    with pytest.raises(train_lib.ConfigError, match="patience"):
        config_lib.TrainConfig(patience=2, k_choice="forward")


def test_retired_feedback_rollouts_are_refused_by_name():
    for impl in config_lib.RETIRED_FEEDBACK_IMPLS:
        with pytest.raises(train_lib.ConfigError, match=f"got '{impl}', a retired rollout"):
            config_lib.TrainConfig(feedback_impl=impl)


def test_corrupt_training_checkpoint_refused(tiny_setup, tmp_path):
    data, fconf, fparams, _, _ = tiny_setup
    workdir = tmp_path / "run"
    workdir.mkdir()
    (workdir / "state.ckpt").write_bytes(b"\x85garbage")
    with pytest.raises(checkpoint.CheckpointError):
        train_lib.train_and_evaluate(
            TINY, data, fparams, workdir, forward_model=fconf.model, progress=False
        )


def test_baseline_and_vmapped_make_train(tiny_setup):
    data, fconf, fparams, _, _ = tiny_setup
    config = dataclasses.replace(TINY, baseline=True, epochs=2)
    train = train_lib.make_train(config, data, fparams, fconf.model)
    state, metrics = jax.jit(jax.vmap(train))(jax.random.split(jax.random.PRNGKey(0), 2))
    assert set(state.params) == {"gen", "critic"}
    # One generator and one critic (G_c, C_c) per seed: a stack of length 1.
    assert {x.shape[:2] for x in jax.tree.leaves(state.params)} == {(2, 1)}
    assert metrics["generator_total"].shape == (2, 2)
    assert np.isfinite(metrics["feedback"]).all() and np.isfinite(metrics["critic_c"]).all()
    assert np.isnan(metrics["cycle"]).all()  # no cycle loss in the baseline
    # Two seeds give two different generators.
    g = state.params["gen"]["params"]["out"]["kernel"][:, 0]
    assert not np.array_equal(g[0], g[1])


def test_variant_settings_train(tiny_setup):
    """Two critic updates per step, the authors' per-sample G and the residual G train together
    (one compile); with lambda_adversarial 0 the generators ignore the critics, so their update
    does not depend on the critics' values."""
    data, fconf, fparams, _, _ = tiny_setup
    config = dataclasses.replace(
        TINY,
        epochs=1,
        critic_steps=2,
        gen_per_sample=True,
        gen_residual=True,
        lambda_adversarial=0.0,
    )
    trainer = train_lib.make_trainer(config, data, fparams, fconf.model)
    s0 = trainer.init(jax.random.PRNGKey(0))
    other_critic = jax.tree.map(lambda v: v * 1.5, s0.params["critic"])
    s1 = s0.replace(params={"gen": s0.params["gen"], "critic": other_critic})
    run = jax.jit(trainer.run_epochs, static_argnums=3)
    a, metrics = run(s0, jax.random.PRNGKey(1), jnp.int32(0), 1)
    b, _ = run(s1, jax.random.PRNGKey(1), jnp.int32(0), 1)
    assert np.isfinite(metrics["generator_total"]).all() and np.isfinite(metrics["critic_c"]).all()
    assert _params_equal(a.params["gen"], b.params["gen"])
    assert not _params_equal(a.params["critic"], b.params["critic"])
    assert not _params_equal(a.params["gen"], s0.params["gen"])  # the generators did move


@pytest.mark.slow
def test_two_devices_train_like_one(tiny_setup, tmp_path):
    """Two fake CPU devices (a fresh process): the batch is split over both, same parameters."""
    import pickle
    import subprocess
    import sys

    data, fconf, fparams, _, _ = tiny_setup
    config = dataclasses.replace(TINY, epochs=2)
    (tmp_path / "setup.pkl").write_bytes(pickle.dumps((data, fconf, jax.device_get(fparams))))
    code = f"""
import dataclasses, pickle, numpy as np
import mjx_arm, jax
from ccgan import config as config_lib, train as train_lib
from tracking import held, metrics
from tracking.config import ConfigError
assert len(jax.devices()) == 2
data, fconf, fparams = pickle.loads(open({str(tmp_path / "setup.pkl")!r}, "rb").read())
config = config_lib.TrainConfig(**{config.to_dict()!r})
config = dataclasses.replace(config, **{{f: tuple(getattr(config, f)) for f in
    ("hold_factors", "critic_features")}})
train = train_lib.make_train(config, data, fparams, fconf.model)
_, metrics = jax.jit(train)(jax.random.PRNGKey(0))
np.savez({str(tmp_path / "two.npz")!r}, **jax.device_get(metrics))
print("ok")
"""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-3000:]
    _, metrics = jax.jit(train_lib.make_train(config, data, fparams, fconf.model))(
        jax.random.PRNGKey(0)
    )
    # Every loss term of every epoch agrees (the parameters themselves may not, bit for bit:
    # Adam's first steps are ~lr * sign(gradient), and a near-zero gradient's sign follows the
    # summation order).
    with np.load(tmp_path / "two.npz") as two:
        for name in ("critic_total", "generator_total", "feedback", "cycle", "identity"):
            np.testing.assert_allclose(metrics[name], two[name], rtol=2e-3, atol=1e-6)


def test_k_chosen_on_held_out_shape_like_programs(tiny_setup):
    """k_choice_programs "shape_like": the judge scores on shape-like programs (never a test
    shape) whose D_s targets it simulates from rest, not on the training data's babbling."""
    from ccgan.sim_choice import SHAPE_LIKE_SPLIT, SimulatorChoice, describe_programs
    from mjx_arm.programs import shape_like_programs

    data = tiny_setup[0]
    xml = mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), n_segments=3))
    arm_s, arm_c = (mjx_arm.load(xml=xml, domain=d) for d in ("source", "constrained"))
    config = dataclasses.replace(
        TINY,
        hold_factors=(1, 3),
        k_choice_seconds=2.0,
        k_choice_programs="shape_like",
        k_choice_n_programs=2,
    )
    with pytest.raises(ValueError, match="source_arm"):
        SimulatorChoice(arm_c, data, config)
    with pytest.raises(ConfigError, match="k_choice_programs"):
        dataclasses.replace(config, k_choice_programs="shapes")
    with pytest.raises(ConfigError, match="k_choice_seconds"):
        dataclasses.replace(config, k_choice_seconds=0.0)

    judge = SimulatorChoice(arm_c, data, config, source_arm=arm_s)
    programs = shape_like_programs(2, 2.0, seed=0, split=SHAPE_LIKE_SPLIT, full_scale=True)
    assert judge._samples.shape == (2, 20, 9)
    np.testing.assert_allclose(
        data_lib.denormalise_pressure(np.asarray(judge._samples[..., :3])), programs, atol=1e-5
    )
    targets = arm_s.rollout(programs.astype(np.float64), backend="c")
    np.testing.assert_allclose(judge.target, targets, atol=1e-5)
    # Stretch only on those programs, by hand at k = 3.
    poses = held.every_kth(arm_c.rollout(held.stretch(programs, 3), backend="c"), 3)
    expected = metrics.position_error_cm(poses, targets).mean()
    assert judge.stretch_only_errors()[1] == pytest.approx(expected, rel=1e-4)
    assert "2 held-out shape-like" in describe_programs(config.to_dict())
    assert "babbling" in describe_programs(TINY.to_dict())
