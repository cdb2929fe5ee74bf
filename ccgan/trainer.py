"""The CCGAN-GP training algorithm (and the WCGAN-GP baseline) as pure functions.

`make_train(config, data, forward_c_params)` returns a pure `train(key) -> (state, metrics)` that
runs every epoch as one `lax.scan`, so several seeds train at once with
`jax.jit(jax.vmap(train))(keys)`. `make_trainer` returns the pieces it is made of (`init`,
`run_epochs`, `validation_errors`), which `ccgan.training_run.train_and_evaluate` drives in chunks
with a CSV log and checkpoints. Every epoch's randomness is `fold_in(key, epoch)`, so epochs run in
chunks end with the parameters of one scan over all of them.

One train step updates all four networks: first both critics (Wasserstein loss + gradient
penalty), then both generators against the updated critics (adversarial + lambda_c cycle +
identity + lambda_f feedback). The feedback term runs the frozen forward model F_c open-loop on
G_c's commands, each held for k control periods (the hold factor k), and compares every k-th pose
with the D_s target. Every `stretch_every` epochs, the hold factor k is re-chosen from
`hold_factors` by the tracking error on held-out D_s trajectories: here through F_c when
`k_choice` is "forward", in the target-domain simulator between epochs
(`ccgan.best_generators`, `ccgan.sim_choice`) when it is "simulator", the default.

This module holds no I/O: files and resumption are `ccgan.training_run`'s (with
`ccgan.run_files`), the command line `ccgan.train`'s.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import flax
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from ccgan import losses
from ccgan.config import TrainConfig
from ccgan.data import PRESSURE_DIM, TranslationData
from ccgan.models import (
    Critic,
    ForwardModel,
    Generator,
    forward_stretched,
    forward_stretched_masked,
)
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
    gen = Generator(**config.generator_args, unroll=config.gen_unroll)
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
    # k through F_c, inside the jitted epoch; with "simulator" the host chooses it between epochs.
    in_jit_choice = config.k_choice == "forward"

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
        # Like the authors' code, pick k once before training, with the untrained generator
        # (in the simulator, `ccgan.training_run` does it on the host).
        return choose_k(state)[0] if in_jit_choice else state

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
        total = config.lambda_adversarial * adv + config.lambda_feedback * out["feedback"]
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

        def critic_update(carry, critic_key):
            cp, opt_critic = carry
            (_, c_out), c_grads = jax.value_and_grad(critic_losses, has_aux=True)(
                cp, jax.lax.stop_gradient(fakes), xs, xc, critic_key
            )
            c_updates, opt_critic = tx_critic.update(c_grads, opt_critic, cp)
            return (optax.apply_updates(cp, c_updates), opt_critic), c_out

        with jax.named_scope("critic_update"):
            if config.critic_steps == 1:
                (cp, opt_critic), c_out = critic_update((cp, state.opt_critic), key)
            else:  # several updates on this batch, each with its own penalty sample
                keys = jax.random.split(key, config.critic_steps)
                (cp, opt_critic), c_outs = jax.lax.scan(critic_update, (cp, state.opt_critic), keys)
                c_out = jax.tree.map(lambda v: v[-1], c_outs)

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
        val_err = jnp.array(jnp.nan, jnp.float32)
        if in_jit_choice:
            # `epoch` comes from the scan's xs, so under vmap over seeds the predicate stays
            # unbatched and this stays a real branch (k is evaluated every stretch_every epochs).
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


def init_each(init, keys, *args):
    """Initial states of several members, [M, ...] stacked: `init(keys[m], *(a[m] for a in
    args))` one member at a time (one compiled initialiser, called M times).

    Not `vmap(init)`: under vmap the LSTMs' orthogonal initialisation becomes a batched QR, which
    jaxlib runs on CPU through `jax::ParallelBatchMap`, and on a 2-core CPU that call has been
    seen to wait forever for its pool threads (three members, jaxlib 0.10.2).
    """
    one = jax.jit(init)
    states = [
        one(keys[m], *(jax.tree.map(lambda x, m=m: x[m], a) for a in args))
        for m in range(len(keys))
    ]
    return jax.tree.map(lambda *x: jnp.stack(x), *states)


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
