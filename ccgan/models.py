"""Flax Linen networks of the CCGAN-GP: forward model F, generator G and critic C.

All inputs and outputs are in the normalised units of `ccgan.data`: pressures / 3.5 bar and poses
in [0, 1]. Sequences are batch-major, `[B, T, features]`.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

POSE_DIM = 6
PRESSURE_DIM = 3


class ForwardModel(nn.Module):
    """Forward dynamics F: (pose before the step, command) -> pose after the step.

    One LSTM layer (64), FC 50 + tanh, linear 6 (paper Sec. II-B).
    """

    hidden: int = 64
    fc: int = 50

    @nn.compact
    def __call__(self, prev_pose, pressure, initial_carry=None, return_carry: bool = False):
        """Runs F over a sequence.

        Args:
          prev_pose: [B, T, 6] normalised pose before each command.
          pressure: [B, T, 3] normalised commands.
          initial_carry: LSTM carry ((c [B, H], h [B, H])) or None for zeros.
          return_carry: also return the final carry.

        Returns:
          poses [B, T, 6] normalised (and the carry when `return_carry`).
        """
        x = jnp.concatenate([prev_pose, pressure], -1)
        rnn = nn.RNN(nn.OptimizedLSTMCell(self.hidden), name="lstm")
        carry, h = rnn(x, initial_carry=initial_carry, return_carry=True)
        h = jnp.tanh(nn.Dense(self.fc, name="fc")(h))
        pose = nn.Dense(POSE_DIM, name="out")(h)
        return (carry, pose) if return_carry else pose

    def zero_carry(self, batch: int):
        """Zero LSTM carry for `batch` sequences."""
        z = jnp.zeros((batch, self.hidden))
        return (z, z)


def forward_open_loop(model: ForwardModel, params, pressure, pose0):
    """F in closed loop on its own predictions (an open-loop rollout of the commands).

    Args:
      model: the module.
      params: its variables ({"params": ...}).
      pressure: [B, T, 3] normalised commands.
      pose0: [B, 6] normalised pose before the first command.

    Returns:
      [B, T, 6] predicted normalised poses.
    """

    def step(carry, p_t):
        lstm, pose = carry
        lstm, out = model.apply(params, pose[:, None], p_t[:, None], lstm, return_carry=True)
        return (lstm, out[:, 0]), out[:, 0]

    carry0 = (model.zero_carry(pressure.shape[0]), pose0)
    _, poses = jax.lax.scan(step, carry0, jnp.swapaxes(pressure, 0, 1))
    return jnp.swapaxes(poses, 0, 1)


def forward_stretched(model: ForwardModel, params, pressure, pose0, k, k_max: int):
    """F's open-loop response when each command is held k control periods (time stretching).

    Every command is applied k times in a row and the pose after its k-th period is kept, so the
    result lines up step by step with the D_s trajectory the commands came from. `k` may be a
    traced integer in [1, k_max]; periods past k are masked (the state is carried through
    unchanged), so one compiled function serves every k.

    Args:
      model: the module.
      params: its variables.
      pressure: [B, T, 3] normalised commands.
      pose0: [B, 6] normalised pose before the first command.
      k: hold factor, int (traced or static), 1 <= k <= k_max.
      k_max: static upper bound on k.

    Returns:
      [B, T, 6] normalised poses after each command's k-th period.
    """

    def period(carry, j, p_t):
        lstm, pose = carry
        new_lstm, out = model.apply(params, pose[:, None], p_t[:, None], lstm, return_carry=True)
        live = j < k
        keep = lambda new, old: jnp.where(live, new, old)  # noqa: E731
        return (jax.tree.map(keep, new_lstm, lstm), keep(out[:, 0], pose)), None

    def command(carry, p_t):
        carry, _ = jax.lax.scan(lambda c, j: period(c, j, p_t), carry, jnp.arange(k_max))
        return carry, carry[1]

    carry0 = (model.zero_carry(pressure.shape[0]), pose0)
    _, poses = jax.lax.scan(command, carry0, jnp.swapaxes(pressure, 0, 1))
    return jnp.swapaxes(poses, 0, 1)


class Generator(nn.Module):
    """Generator G: one domain's sample sequence -> the other domain's.

    9 in (pressure 3 + pose 6), two LSTM layers of 32, FC 128 + ReLU, linear 9. The pressure part is
    squashed with a sigmoid into the normalised valve range [0, 1]; the pose part is linear.
    """

    hidden: int = 32
    fc: int = 128
    n_layers: int = 2

    @nn.compact
    def __call__(self, x):
        """x: [B, T, 9] normalised samples -> [B, T, 9] (pressure in [0, 1], then pose)."""
        h = x
        for i in range(self.n_layers):
            h = nn.RNN(nn.OptimizedLSTMCell(self.hidden), name=f"lstm_{i}")(h)
        h = nn.relu(nn.Dense(self.fc, name="fc")(h))
        out = nn.Dense(PRESSURE_DIM + POSE_DIM, name="out")(h)
        return jnp.concatenate([nn.sigmoid(out[..., :PRESSURE_DIM]), out[..., PRESSURE_DIM:]], -1)


class Critic(nn.Module):
    """Critic C: a sample sequence -> one realness score (higher = more real).

    Five Conv1D layers (kernel 3, same padding), each followed by instance norm and LeakyReLU(0.2),
    then a mean over time and a linear scalar. Instance norm (per sample, per channel, over time)
    keeps samples independent, which the gradient penalty requires. Needs T >= 2: over one time step
    instance norm outputs zeros.
    """

    features: tuple[int, ...] = (32, 64, 64, 128, 128)
    kernel: int = 3
    slope: float = 0.2

    @nn.compact
    def __call__(self, x):
        """x: [B, T, 9] normalised samples -> [B] scores."""
        h = x
        for i, f in enumerate(self.features):
            h = nn.Conv(f, (self.kernel,), padding="SAME", name=f"conv_{i}")(h)
            h = nn.GroupNorm(num_groups=None, group_size=1, name=f"norm_{i}")(h)
            h = nn.leaky_relu(h, self.slope)
        return nn.Dense(1, name="out")(h.mean(1))[:, 0]
