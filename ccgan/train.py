"""CCGAN-GP training (and the WCGAN-GP baseline): pure step/epoch functions and a thin driver.

`make_train(config, data, forward_c_params)` returns a pure `train(key) -> (state, metrics)` that
runs every epoch as one `lax.scan`, so several seeds train at once with
`jax.jit(jax.vmap(train))(keys)`. `train_and_evaluate` drives the same epoch function in chunks
with tqdm, a CSV log and atomic checkpoints; a resumed run ends with exactly the parameters of an
uninterrupted one because every epoch's randomness is `fold_in(key, epoch)`.

One train step updates all four networks: first both critics (Wasserstein loss + gradient
penalty), then both generators against the updated critics (adversarial + lambda_c cycle +
identity + lambda_f feedback). The feedback term runs the frozen forward model F_c open-loop on
G_c's commands, each held for k control periods (the hold factor k), and compares every k-th pose
with the D_s target. Every `stretch_every` epochs, the hold factor k is re-chosen from
`hold_factors` by the tracking error on held-out D_s trajectories.

The settings (`TrainConfig`) live in `ccgan.config`, the flags made from them in `ccgan.cli`.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import warnings
from pathlib import Path
from typing import Any, NamedTuple

import flax
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from ccgan import checkpoint, losses
from ccgan.cli import (
    add_config_flags,
    add_data_flags,
    check_output_dir,
    cli_parser,
    config_from_args,
    data_from_args,
)
from ccgan.config import (
    FEEDBACK_IMPLS,
    RENAMED_FIELDS,
    RETIRED_FEEDBACK_IMPLS,
    TrainConfig,
    check_forward_config,
)
from ccgan.data import PRESSURE_DIM, TranslationData, read_domain
from ccgan.forward import ForwardConfig
from ccgan.models import (
    Critic,
    ForwardModel,
    Generator,
    forward_stretched,
    forward_stretched_masked,
)
from tracking.config import ConfigError  # noqa: F401  (kept importable as ccgan.train.ConfigError)
from tracking.metrics import position_error_cm

# ---------------------------------------------------------------------------------- state


@flax.struct.dataclass
class TrainState:
    """Everything that changes during training.

    Attributes:
      params: {"gen", "critic"}: Flax variables of each network type stacked on a leading axis,
        [G_c, G_s] and [C_c, C_s] (length 1, G_c and C_c only, for the baseline), so that both
        domains' networks run as one vmapped call (`generator(params, i)` picks one).
      opt_gen: AdamW state of the generators.
      opt_critic: AdamW state of the critics.
      k: current hold factor (int32 scalar).
      epoch: epochs done (int32 scalar).
    """

    params: dict
    opt_gen: Any
    opt_critic: Any
    k: jnp.ndarray
    epoch: jnp.ndarray


def generator(params: dict, index: int):
    """One generator's variables from `TrainState.params` (0: G_c, 1: G_s)."""
    return jax.tree.map(lambda x: x[index], params["gen"])


class Trainer(NamedTuple):
    """Pure functions of one configured run.

    init(key) -> TrainState;
    run_epochs(state, key, start_epoch, n_epochs: static int) -> (state, metrics {name: [n]});
    validation_errors(state) -> [len(hold_factors)] mean tip error (cm) per k.
    """

    init: Any
    run_epochs: Any
    validation_errors: Any


METRICS = (
    "critic_c",
    "critic_s",
    "gp_c",
    "gp_s",
    "adversarial",
    "cycle",
    "identity",
    "feedback",
    "generator_total",
    "critic_total",
    "k",
    "val_error_cm",
)


def _optimizer(lr: float, config: TrainConfig):
    return optax.adamw(lr, b1=config.beta1, b2=config.beta2, weight_decay=config.weight_decay)


def _mesh_constraint(batch_size: int):
    """Shards the batch axis over local devices when there are several and they divide it."""
    devices = jax.local_devices()
    if len(devices) < 2 or batch_size % len(devices):
        return lambda x: x
    sharding = NamedSharding(Mesh(np.array(devices), ("batch",)), P("batch"))
    return lambda x: jax.lax.with_sharding_constraint(x, sharding)


def resolved_feedback_impl(impl: str) -> str:
    """ "auto" -> "lean_reduce" on a GPU, "lean" elsewhere; any other name unchanged."""
    if impl != "auto":
        return impl
    return "lean_reduce" if jax.default_backend() == "gpu" else "lean"


def _feedback_rollout(config: TrainConfig, fwd: ForwardModel, forward_c_params):
    """`(commands [B, L, 3], pose0 [B, 6], k) -> F_c poses [B, L, 6]`, held k periods each."""
    impl = resolved_feedback_impl(config.feedback_impl)
    return lambda commands, pose0, k: forward_stretched(
        fwd,
        forward_c_params,
        commands,
        pose0,
        k,
        config.k_max,
        config.feedback_unroll,
        impl=impl,
    )


def check_data(config: TrainConfig, data: TranslationData) -> int:
    """Checks that `data` suits `config`; returns the train steps per epoch.

    Raises:
      ValueError: the windows are not config.window_length long, or there are fewer training
        windows in a domain than one batch.
    """
    src = data.constrained if config.baseline else data.source
    n_in, n_c = src.train.shape[0], data.constrained.train.shape[0]
    if src.train.shape[1] != config.window_length or (
        data.constrained.train.shape[1] != config.window_length
    ):
        raise ValueError("data windows do not match config.window_length")
    steps = min(n_in, n_c) // config.batch_size
    if steps < 1:
        raise ValueError(
            f"too few training windows ({n_in} D_s, {n_c} D_c) for batch size"
            f" {config.batch_size}: lower the batch size or window length, or add data"
        )
    return steps


def make_trainer(
    config: TrainConfig,
    data: TranslationData,
    forward_c_params,
    forward_model: ForwardModel | None = None,
) -> Trainer:
    """Builds the pure training functions.

    Args:
      config: settings.
      data: `ccgan.data.prepare(...)` output (window length must equal config.window_length).
      forward_c_params: trained F_c variables (frozen during training).
      forward_model: F_c's module (default `ForwardModel()`).

    Returns:
      `Trainer`.
    """
    # One closure on purpose (purejaxrl's make_train): the data, networks, optimisers and
    # frozen F_c are bound once here, and the named steps below (choose_k, critic_losses,
    # generator_outputs, generator_losses, train_step, epoch_fn) read them without threading a
    # dozen arguments through jit/vmap/scan. Split out, each would take that context as
    # arguments and the compiled program would be the same; read top to bottom, this is the
    # whole training algorithm in one place.
    fwd = forward_model or ForwardModel()
    gen = Generator(hidden=config.gen_hidden, fc=config.gen_fc, unroll=config.gen_unroll)
    critic = Critic(features=config.critic_features)
    tx_gen = _optimizer(config.lr_generator, config)
    tx_critic = _optimizer(config.lr_critic, config)
    cycle = not config.baseline
    shard = _mesh_constraint(config.batch_size)
    feedback_rollout = _feedback_rollout(config, fwd, forward_c_params)

    # The generator's input domain: D_s for CCGAN; D_c only for the WCGAN-GP baseline.
    src = data.constrained if config.baseline else data.source
    steps = check_data(config, data)
    x_in, prev_in = jnp.asarray(src.train), jnp.asarray(src.train_prev_pose)
    x_c = jnp.asarray(data.constrained.train)
    n_in, n_c = x_in.shape[0], x_c.shape[0]
    batch = config.batch_size
    val = jnp.asarray(data.source.val)
    val_prev = jnp.asarray(data.source.val_prev_pose)
    # Held-out windows for the choice of k: [n_val * W, L_val] (a trailing partial window is
    # dropped), each started from its recorded previous pose.
    t_val = val.shape[1]
    l_val = min(config.val_window_length or t_val, t_val)
    n_win = t_val // l_val
    low, high = jnp.asarray(data.bounds.low), jnp.asarray(data.bounds.high)
    choices = jnp.asarray(config.hold_factors, jnp.int32)

    def to_windows(x):
        return x[:, : n_win * l_val].reshape(-1, l_val, x.shape[-1])

    def validation_errors(state: TrainState):
        """Mean tip error (cm) on held-out D_s windows for each k in hold_factors.

        G_c translates whole held-out trajectories (as the translator does); F_c then runs the
        commands of every `val_window_length` window open loop from the window's recorded pose.
        All k run at once: one masked scan of l_val * k_max periods, vmapped over the choices.
        """
        commands = to_windows(gen.apply(generator(state.params, 0), val)[..., :PRESSURE_DIM])
        target = to_windows(val[..., PRESSURE_DIM:])
        pose0 = to_windows(val_prev)[:, 0]

        def for_k(k):
            pred = forward_stretched_masked(
                fwd, forward_c_params, commands, pose0, k, config.k_max, config.feedback_unroll
            )
            span = high - low
            return position_error_cm(pred * span + low, target * span + low).mean()

        return jax.vmap(for_k)(choices)

    def choose_k(state: TrainState):
        errs = validation_errors(state)
        best = jnp.argmin(errs)
        return state.replace(k=choices[best]), errs[best]

    def init(key) -> TrainState:
        k_gen, k_critic = jax.random.split(key)
        # One vmapped init per network type: one compiled initialiser serves both domains (the
        # input shapes are equal) and compiles twice as fast as two separate inits.
        n_nets = 2 if cycle else 1
        gens = jax.vmap(gen.init, in_axes=(0, None))(jax.random.split(k_gen, n_nets), x_in[:1])
        critics = jax.vmap(critic.init, in_axes=(0, None))(
            jax.random.split(k_critic, n_nets), x_c[:1]
        )
        params = {"gen": gens, "critic": critics}
        gp, cp = params["gen"], params["critic"]
        state = TrainState(
            params=params,
            opt_gen=tx_gen.init(gp),
            opt_critic=tx_critic.init(cp),
            k=choices[0],
            epoch=jnp.zeros((), jnp.int32),
        )
        # Like the authors' code, pick k once before training, with the untrained generator.
        return choose_k(state)[0]

    # Both domains' networks of a type run as one call vmapped over the stacked parameters
    # (index 0: G_c / C_c, 1: G_s / C_s): half the sequential kernels of two separate calls.
    gen_pair = jax.vmap(gen.apply)
    critic_pair = jax.vmap(critic.apply)

    def critic_terms(params, real, fake, key):
        """Wasserstein loss and gradient penalty of one critic on real/fake [B, L, 9]."""
        scores = critic.apply(params, jnp.concatenate([real, fake], 0))
        real_score, fake_score = scores[: real.shape[0]], scores[real.shape[0] :]
        score = lambda x: critic.apply(params, x)  # noqa: E731
        return (
            losses.critic_loss(real_score, fake_score),
            losses.gradient_penalty(score, real, fake, key),
        )

    def generator_outputs(gparams, xs, xc):
        """Every generator call of a step, [B, L, 9] each; they depend on the generators only.

        fake_c = G_c(x_s), fake_s = G_s(x_c); same_c = G_c(x_c), same_s = G_s(x_s) (identity);
        back_s = G_s(fake_c), back_c = G_c(fake_s) (cycle). The baseline has fake_c only.
        """
        b = xs.shape[0]
        if not cycle:
            return {"fake_c": gen_pair(gparams, xs[None])[0]}
        # G_c on D_s (translation) and D_c (identity); G_s on D_c and D_s; one call.
        first = gen_pair(gparams, jnp.stack([jnp.concatenate([xs, xc]), jnp.concatenate([xc, xs])]))
        fake_c, fake_s = first[0, :b], first[1, :b]
        back_c, back_s = gen_pair(gparams, jnp.stack([fake_s, fake_c]))
        return {
            "fake_c": fake_c,
            "same_c": first[0, b:],
            "fake_s": fake_s,
            "same_s": first[1, b:],
            "back_c": back_c,
            "back_s": back_s,
        }

    def critic_losses(cparams, fakes, xs, xc, key):
        # Real and generated samples per critic: C_c judges D_c, C_s judges D_s.
        if cycle:
            real, fake = jnp.stack([xc, xs]), jnp.stack([fakes["fake_c"], fakes["fake_s"]])
        else:
            real, fake = xc[None], fakes["fake_c"][None]
        keys = jax.random.split(key, real.shape[0])
        wass, gp = jax.vmap(critic_terms)(cparams, real, fake, keys)
        out = {"critic_c": wass[0], "gp_c": gp[0]}
        if cycle:
            out.update(critic_s=wass[1], gp_s=gp[1])
        total = jnp.sum(wass) + config.lambda_gp * jnp.sum(gp)
        out["critic_total"] = total
        return total, out

    def generator_losses(fakes, cparams, xs, prev_s, xc, k):
        """Generator loss terms from the outputs of `generator_outputs`."""
        fake_c = fakes["fake_c"]
        if cycle:
            scores = critic_pair(cparams, jnp.stack([fake_c, fakes["fake_s"]]))
        else:
            scores = critic_pair(cparams, fake_c[None])
        adv = sum(losses.generator_adversarial_loss(s) for s in scores)
        with jax.named_scope("feedback"):
            pred = feedback_rollout(fake_c[..., :PRESSURE_DIM], prev_s[:, 0], k)
        out = {"feedback": losses.feedback_loss(pred, xs[..., PRESSURE_DIM:])}
        if cycle:
            out["cycle"] = losses.cycle_loss(fakes["back_s"], xs) + losses.cycle_loss(
                fakes["back_c"], xc
            )
            out["identity"] = losses.identity_loss(fakes["same_s"], xs) + losses.identity_loss(
                fakes["same_c"], xc
            )
        out["adversarial"] = adv
        total = adv + config.lambda_feedback * out["feedback"]
        if cycle:
            total = total + config.lambda_cycle * out["cycle"]
            total = total + config.lambda_identity * out["identity"]
        out["generator_total"] = total
        return total, out

    def train_step(state: TrainState, inputs):
        """One critic update then one generator update; inputs = (idx_in [B], idx_c [B], key).

        The generators run once per step: the critics see their outputs before the update (as
        a separate forward pass with the same parameters would give), and the generator
        gradient is the outputs' cotangent pulled back through that same pass.
        """
        idx_in, idx_c, key = inputs
        xs, prev_s, xc = shard(x_in[idx_in]), shard(prev_in[idx_in]), shard(x_c[idx_c])
        gp, cp = state.params["gen"], state.params["critic"]

        with jax.named_scope("generators_forward"):
            fakes, generators_vjp = jax.vjp(lambda g: generator_outputs(g, xs, xc), gp)

        with jax.named_scope("critic_update"):
            (_, c_out), c_grads = jax.value_and_grad(critic_losses, has_aux=True)(
                cp, jax.lax.stop_gradient(fakes), xs, xc, key
            )
            c_updates, opt_critic = tx_critic.update(c_grads, state.opt_critic, cp)
            cp = optax.apply_updates(cp, c_updates)

        with jax.named_scope("generator_losses"):
            (_, g_out), fakes_ct = jax.value_and_grad(generator_losses, has_aux=True)(
                fakes, cp, xs, prev_s, xc, state.k
            )
        with jax.named_scope("generators_backward"):
            (g_grads,) = generators_vjp(fakes_ct)
            g_updates, opt_gen = tx_gen.update(g_grads, state.opt_gen, gp)
            gp = optax.apply_updates(gp, g_updates)

        state = state.replace(
            params={"gen": gp, "critic": cp}, opt_gen=opt_gen, opt_critic=opt_critic
        )
        return state, {**c_out, **g_out}

    def epoch_fn(state: TrainState, epoch, key):
        ek = jax.random.fold_in(key, epoch)
        k_in, k_c, k_steps = jax.random.split(ek, 3)
        idx_in = jax.random.permutation(k_in, n_in)[: steps * batch].reshape(steps, batch)
        idx_c = jax.random.permutation(k_c, n_c)[: steps * batch].reshape(steps, batch)
        state, out = jax.lax.scan(
            train_step, state, (idx_in, idx_c, jax.random.split(k_steps, steps))
        )
        metrics = {name: v.mean() for name, v in out.items()}
        # `epoch` comes from the scan's xs, so under vmap over seeds the predicate stays unbatched
        # and this stays a real branch (k is evaluated every stretch_every epochs, not every one).
        state, val_err = jax.lax.cond(
            (epoch + 1) % config.stretch_every == 0,
            choose_k,
            lambda s: (s, jnp.array(jnp.nan, jnp.float32)),
            state,
        )
        metrics["k"] = state.k.astype(jnp.float32)
        metrics["val_error_cm"] = val_err
        for name in METRICS:
            metrics.setdefault(name, jnp.array(jnp.nan, jnp.float32))
        return state.replace(epoch=epoch + 1), metrics

    def run_epochs(state: TrainState, key, start_epoch, n_epochs: int):
        epochs = start_epoch + jnp.arange(n_epochs, dtype=jnp.int32)
        return jax.lax.scan(lambda s, e: epoch_fn(s, e, key), state, epochs)

    return Trainer(init=init, run_epochs=run_epochs, validation_errors=validation_errors)


def make_train(
    config: TrainConfig,
    data: TranslationData,
    forward_c_params,
    forward_model: ForwardModel | None = None,
):
    """Pure `train(key) -> (TrainState, metrics {name: [epochs]})` running every epoch in one scan.

    Seeds in parallel: `jax.jit(jax.vmap(make_train(config, data, fc)))(jax.random.split(key, n))`.
    """
    trainer = make_trainer(config, data, forward_c_params, forward_model)

    def train(key):
        init_key, run_key = jax.random.split(key)
        state = trainer.init(init_key)
        return trainer.run_epochs(state, run_key, jnp.int32(0), config.epochs)

    return train


def data_fingerprint(data: TranslationData) -> str:
    return checkpoint.fingerprint(
        data.source.train,
        data.source.val,
        data.constrained.train,
        data.constrained.val,
        data.bounds.low,
        data.bounds.high,
    )


def _write_csv(path: Path, rows: list[dict]) -> None:
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["seed", "epoch", *METRICS])
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


def _read_csv(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return [
        {k: int(v) if k in ("seed", "epoch") else float(v) for k, v in row.items()} for row in rows
    ]


def _resume_expectation(ckpt_path: Path, meta: dict) -> dict:
    """The metadata a stored run must match to be resumed by a run with `meta`.

    A run stored with a retired feedback rollout (`RETIRED_FEEDBACK_IMPLS`) resumes with this
    run's, with a warning: every rollout computes the same function up to float rounding, so
    only the stored name differs. The next checkpoint records this run's rollout.

    A run stored before a field was renamed (`RENAMED_FIELDS`) resumes too: its fields are
    compared under their old names, and the next checkpoint records the new ones.
    """
    stored = checkpoint.read(ckpt_path)[0].get("config")
    if isinstance(stored, dict):
        old_names = {new: old for old, new in RENAMED_FIELDS.items() if old in stored}
        meta = meta | {"config": {old_names.get(k, k): v for k, v in meta["config"].items()}}
    impl = stored.get("feedback_impl") if isinstance(stored, dict) else None
    if impl not in RETIRED_FEEDBACK_IMPLS:
        return meta
    warnings.warn(
        f"{ckpt_path} was trained with feedback_impl={impl!r}, a retired rollout"
        f" (docs/benchmarks.md); resuming with {meta['config']['feedback_impl']!r}, the same"
        " function up to float rounding",
        stacklevel=3,
    )
    return meta | {"config": meta["config"] | {"feedback_impl": impl}}


def train_and_evaluate(
    config: TrainConfig,
    data: TranslationData,
    forward_c_params,
    workdir: str | os.PathLike,
    seeds: tuple[int, ...] = (0,),
    forward_model: ForwardModel | None = None,
    resume: bool = True,
    max_chunks: int | None = None,
    progress: bool = True,
    model_hash: str | None = None,
):
    """Trains one or several seeds (vmapped), with a CSV log, checkpoints and a translator file.

    Files in `workdir`: `state.ckpt` (stacked TrainState of every seed, every checkpoint_every
    epochs), `metrics.csv` (one row per seed and epoch, every loss term), `translator_seed{s}.ckpt`
    and `translator.ckpt` (first seed) for `ccgan.load_translator`.

    Args:
      config, data, forward_c_params, forward_model: as `make_trainer`.
      workdir: output folder.
      seeds: PRNG seeds, trained together with vmap.
      resume: continue from `workdir/state.ckpt` if present (it must match config, data and seeds).
      max_chunks: stop after this many chunks (to test resumption); None runs to the end.
      progress: show a tqdm bar over epochs.
      model_hash: `Arm.model_hash` of the arm the data comes from, recorded in the translator
        files (`ccgan.finetune` and `ccgan.distill` refuse to refine them on another arm).

    Returns:
      (state with a leading seed axis, rows of the metrics CSV).
    """
    from tqdm.auto import tqdm

    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    ckpt_path, csv_path = workdir / "state.ckpt", workdir / "metrics.csv"
    meta = {"config": config.to_dict(), "data": data_fingerprint(data), "seeds": list(seeds)}
    expect = meta
    if resume and ckpt_path.exists():
        expect = _resume_expectation(ckpt_path, meta)
        checkpoint.load(ckpt_path, expect=expect)  # fail fast, before compiling anything
    trainer = make_trainer(config, data, forward_c_params, forward_model)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds))
    init_keys, run_keys = jnp.swapaxes(jax.vmap(jax.random.split)(keys), 0, 1)
    state = jax.jit(jax.vmap(trainer.init))(init_keys)
    rows: list[dict] = []
    if resume and ckpt_path.exists():
        state, _ = checkpoint.load(ckpt_path, target=state, expect=expect)
        done = int(np.asarray(state.epoch)[0])
        rows = [r for r in _read_csv(csv_path) if int(r["epoch"]) <= done]
    done = int(np.asarray(state.epoch)[0])

    chunk = max(1, config.checkpoint_every)
    run = jax.jit(jax.vmap(trainer.run_epochs, in_axes=(0, 0, None, None)), static_argnums=3)
    starts = list(range(done, config.epochs, chunk))
    if max_chunks is not None:
        starts = starts[:max_chunks]
    bar = tqdm(total=config.epochs, initial=done, unit="epoch", disable=not progress, desc="ccgan")

    def record(start, n, state, metrics):
        """Host side of a finished chunk: CSV rows, checkpoint, progress bar."""
        metrics = jax.device_get(metrics)
        for s_i, seed in enumerate(seeds):
            for e in range(n):
                row = {"seed": seed, "epoch": start + e + 1}
                row.update({m: float(metrics[m][s_i, e]) for m in METRICS})
                rows.append(row)
        checkpoint.save(ckpt_path, jax.device_get(state), meta | {"epoch": start + n})
        _write_csv(csv_path, rows)
        bar.set_postfix({m: float(np.nanmean(metrics[m][:, -1])) for m in ("generator_total", "k")})
        bar.update(n)

    # The next chunk is dispatched before the last one's files are written, so the device keeps
    # working while the host saves (JAX dispatch is asynchronous; the arrays are immutable).
    pending = None
    for start in starts:
        n = min(chunk, config.epochs - start)
        state, metrics = run(state, run_keys, jnp.int32(start), n)
        if pending is not None:
            record(*pending)
        pending = (start, n, state, metrics)
    if pending is not None:
        record(*pending)
    bar.close()

    if int(np.asarray(state.epoch)[0]) >= config.epochs:
        from ccgan.translator import save_translator

        for s_i, seed in enumerate(seeds):
            one = jax.tree.map(lambda x, i=s_i: np.asarray(x)[i], state)
            names = [f"translator_seed{seed}.ckpt"] + (["translator.ckpt"] if s_i == 0 else [])
            for name in names:
                save_translator(
                    workdir / name,
                    generator(one.params, 0),
                    int(one.k),
                    data.bounds,
                    config,
                    forward_c_params,
                    forward_model,
                    model_hash=model_hash,
                )
    return state, rows


def load_npz(*paths: str | os.PathLike):
    """Concatenated (pressures [N, T, 3] bar, poses [N, T, 6], bounds) of one domain's files.

    The files are read and checked by `ccgan.data.read_domain` (one domain, one arm, one program
    length; a corrupt file raises `mjx_arm.dataset.DatasetError` naming it); the bounds span
    every file's. List the validation file last (the last `n_val` trajectories are held out).
    """
    d = read_domain(paths)
    return d.pressures_bar, d.poses, d.bounds


def train_forward_models(fconf: ForwardConfig, data: TranslationData, workdir: Path, progress=True):
    """Trains F_s and F_c, writes `forward_{s,c}.ckpt` and `forward_metrics.json` to workdir.

    F_s is not used by the CCGAN; it is trained for the report, as in the paper. The bar
    advances per epoch (minutes per model on a CPU at the default 300 epochs).
    """
    from tqdm.auto import tqdm

    from ccgan import forward as forward_lib

    f_meta = {"config": dataclasses.asdict(fconf), "data": data_fingerprint(data)}
    report = {}
    models = (("forward_s", data.source), ("forward_c", data.constrained))
    bar = tqdm(
        total=len(models) * fconf.epochs, desc="forward models", unit="epoch", disable=not progress
    )
    for name, split in models:
        bar.set_postfix_str(name)
        params, hist, metrics = forward_lib.train_forward(
            fconf, split, data.bounds, on_epoch=lambda _: bar.update(1)
        )
        checkpoint.save(workdir / f"{name}.ckpt", params, f_meta)
        report[name] = metrics | {"final_loss": float(hist[-1])}
        bar.write(f"{name} {json.dumps(report[name])}")
    bar.close()
    (workdir / "forward_metrics.json").write_text(json.dumps(report, indent=2))
    return report


def build_parser() -> argparse.ArgumentParser:
    """The options of `python -m ccgan.train`."""
    parser = cli_parser("ccgan.train", __doc__)
    add_data_flags(parser)
    parser.add_argument(
        "--workdir",
        default="runs/ccgan_train",
        help="output folder: state.ckpt, metrics.csv, forward_*.ckpt, translator*.ckpt",
    )
    parser.add_argument(
        "--seeds", type=int, nargs="+", default=[0], help="PRNG seeds, trained together"
    )
    parser.add_argument(
        "--no-resume",
        action="store_true",
        help="train afresh instead of continuing from the workdir's checkpoints",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_config_flags(parser, ForwardConfig, prefix="forward-")
    add_config_flags(parser, TrainConfig, choices={"feedback_impl": FEEDBACK_IMPLS})
    return parser


def main(argv=None) -> None:
    """CLI: `python -m ccgan.train --source S.npz... --constrained C.npz... --workdir DIR [...]`.

    Every option and every data file is checked before anything is computed or written; a bad
    one exits with status 2 and a message naming it.
    """
    from ccgan import data as data_lib

    parser = build_parser()
    args = parser.parse_args(argv)
    config = config_from_args(parser, args, TrainConfig)
    fconf = config_from_args(
        parser, args, ForwardConfig, prefix="forward-", check=check_forward_config
    )
    if len(set(args.seeds)) != len(args.seeds):
        parser.error(f"--seeds must be distinct, got {args.seeds}")
    check_output_dir(parser, "--workdir", args.workdir)
    d_s, d_c = data_from_args(parser, args)

    from mjx_arm.machine import enable_compilation_cache

    try:
        data = data_lib.prepare(
            d_s.pressures_bar,
            d_s.poses,
            d_c.pressures_bar,
            d_c.poses,
            config.window_length,
            config.n_val,
            config.stride,
            bounds=data_lib.union_bounds(d_s.bounds, d_c.bounds),
        )
        check_data(config, data)
    except ValueError as err:
        parser.error(f"the data do not suit the options: {err}")
    enable_compilation_cache()
    workdir = Path(args.workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    f_meta = {"config": dataclasses.asdict(fconf), "data": data_fingerprint(data)}
    fc_path = workdir / "forward_c.ckpt"
    if args.no_resume or not fc_path.exists():
        train_forward_models(fconf, data, workdir, progress=not args.no_progress)
    fc_params, _ = checkpoint.load(fc_path, expect=f_meta)
    train_and_evaluate(
        config,
        data,
        fc_params,
        workdir,
        seeds=tuple(args.seeds),
        resume=not args.no_resume,
        forward_model=fconf.model,
        progress=not args.no_progress,
        model_hash=d_s.model_hash,
    )


if __name__ == "__main__":
    main()
