"""Training and evaluation of the forward dynamics models F_s and F_c.

F maps (pose before the step, command) to the pose after it. It is trained on windows of babbling
data (Adam with decoupled weight decay 1e-4, MSE), teacher-forced as the paper trains it, or in
open loop (`ForwardConfig.open_loop`): each window rolled out on F's own predictions from its
first recorded pose, the way the feedback loss and the choice of k use F_c over held commands
(`studies.forward_data` compares the two). It is evaluated on held-out trajectories two ways:
one-step (teacher-forced on the true previous poses) and open-loop (fed its own predictions from
the first pose), in cm and rad.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ccgan.data import PRESSURE_DIM, DomainSplit, PoseBounds, denormalise_pose
from ccgan.models import ForwardModel, forward_open_loop
from tracking.metrics import orientation_error_rad, position_error_cm


@dataclasses.dataclass(frozen=True)
class ForwardConfig:
    """Forward-model training settings."""

    #: Passes over the training windows.
    epochs: int = 300
    #: Windows per optimiser step.
    batch_size: int = 32
    #: Adam learning rate (not given in the paper).
    lr: float = 1e-3
    #: Decoupled weight decay (paper: 1e-4).
    weight_decay: float = 1e-4
    #: LSTM width (paper: 64).
    hidden: int = 64
    #: Width of the tanh layer (paper: 50).
    fc: int = 50
    #: Train on F's own predictions over each window, from its first recorded pose (the paper
    #: trains teacher-forced, on the recorded previous poses).
    open_loop: bool = False

    @property
    def model(self) -> ForwardModel:
        return ForwardModel(hidden=self.hidden, fc=self.fc)


def make_train_forward(config: ForwardConfig, split: DomainSplit, on_epoch=None):
    """Builds a pure `train(key) -> (variables, loss per epoch [E])` for one domain's F.

    Args:
      config: settings.
      split: the domain's windows (`train` [M, L, 9], `train_prev_pose` [M, L, 6]).
      on_epoch: called on the host with each finished epoch's index (a progress bar), through
        `jax.debug.callback`: the epochs run as one compiled scan, minutes long on a CPU.
    """
    model = config.model
    x = jnp.asarray(split.train)
    prev = jnp.asarray(split.train_prev_pose)
    n_windows = x.shape[0]
    batch = min(config.batch_size, n_windows)
    steps = n_windows // batch
    tx = optax.adamw(config.lr, weight_decay=config.weight_decay)

    def loss_fn(params, xb, pb):
        if config.open_loop:
            pred = forward_open_loop(model, params, xb[..., :PRESSURE_DIM], pb[:, 0])
        else:
            pred = model.apply(params, pb, xb[..., :PRESSURE_DIM])
        return jnp.mean((pred - xb[..., PRESSURE_DIM:]) ** 2)

    def train(key):
        key, init_key = jax.random.split(key)
        params = model.init(init_key, prev[:1], x[:1, :, :PRESSURE_DIM])
        opt_state = tx.init(params)

        def epoch(carry, e):
            params, opt_state = carry
            perm = jax.random.permutation(jax.random.fold_in(key, e), n_windows)
            idx = perm[: steps * batch].reshape(steps, batch)

            def step(carry, i):
                params, opt_state = carry
                loss, g = jax.value_and_grad(loss_fn)(params, x[i], prev[i])
                updates, opt_state = tx.update(g, opt_state, params)
                return (optax.apply_updates(params, updates), opt_state), loss

            (params, opt_state), l = jax.lax.scan(step, (params, opt_state), idx)
            if on_epoch is not None:
                jax.debug.callback(on_epoch, e)
            return (params, opt_state), l.mean()

        (params, _), hist = jax.lax.scan(epoch, (params, opt_state), jnp.arange(config.epochs))
        return params, hist

    return train


def evaluate_forward(model: ForwardModel, params, split: DomainSplit, bounds: PoseBounds) -> dict:
    """One-step and open-loop errors of F on the held-out trajectories.

    Args:
      model: the module; params: its variables.
      split: `val` [V, T, 9] and `val_prev_pose` [V, T, 6].
      bounds: pose bounds, to report in m and rad.

    Returns:
      {"one_step_cm", "one_step_rad", "open_loop_cm", "open_loop_rad"}: means over all samples.
    """
    val = jnp.asarray(split.val)
    prev = jnp.asarray(split.val_prev_pose)
    pressure, target = val[..., :PRESSURE_DIM], val[..., PRESSURE_DIM:]
    one = model.apply(params, prev, pressure)
    ol = forward_open_loop(model, params, pressure, prev[:, 0])
    target_m = denormalise_pose(np.asarray(target), bounds)
    out = {}
    for name, pred in (("one_step", one), ("open_loop", ol)):
        pred_m = denormalise_pose(np.asarray(pred), bounds)
        out[f"{name}_cm"] = float(np.mean(position_error_cm(pred_m, target_m)))
        out[f"{name}_rad"] = float(np.mean(orientation_error_rad(pred_m, target_m)))
    return out


def train_forward(
    config: ForwardConfig, split: DomainSplit, bounds: PoseBounds, seed: int = 0, on_epoch=None
):
    """Trains one F and evaluates it; returns (variables, loss history [E], metrics dict).

    `on_epoch(epoch)` is called on the host after each epoch (see `make_train_forward`)."""
    train = make_train_forward(config, split, on_epoch)
    params, hist = jax.block_until_ready(jax.jit(train)(jax.random.PRNGKey(seed)))
    return params, np.asarray(hist), evaluate_forward(config.model, params, split, bounds)
