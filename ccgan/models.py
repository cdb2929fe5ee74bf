"""Flax Linen networks of the CCGAN-GP: forward model F, generator G and critic C.

All inputs and outputs are in the normalised units of `ccgan.data`: pressures / P_MAX_BAR and poses
in [0, 1]. Sequences are batch-major, `[B, T, features]`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp

from mjx_arm.constants import N_CHAMBERS, POSE_DIM

PRESSURE_DIM = N_CHAMBERS


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


def _period(model: ForwardModel, params, carry, pressure):
    """One control period of F: carry ((c, h), pose [B, 6]) and command [B, 3] -> next carry."""
    lstm, pose = carry
    lstm, out = model.apply(params, pose[:, None], pressure[:, None], lstm, return_carry=True)
    return lstm, out[:, 0]


def forward_stretched_masked(
    model: ForwardModel, params, pressure, pose0, k, k_max: int, unroll: int = 1
):
    """Reference `forward_stretched`: k_max periods per command, those past k masked.

    Every command costs k_max LSTM periods whatever k is; kept as the test oracle of
    `forward_stretched` and for vmapping over several k at once (one fixed-length scan, e.g. the
    choice of k, which runs forward only).

    Args:
      model, params, pressure, pose0, k, k_max: as `forward_stretched`.
      unroll: periods per iteration of the inner scan (numerics unchanged).

    Returns:
      [B, T, 6] normalised poses after each command's k-th period.
    """

    def period(carry, j, p_t):
        new = _period(model, params, carry, p_t)
        keep = lambda new, old: jnp.where(j < k, new, old)  # noqa: E731
        return jax.tree.map(keep, new, carry), None

    def command(carry, p_t):
        periods = jnp.arange(k_max)
        carry, _ = jax.lax.scan(lambda c, j: period(c, j, p_t), carry, periods, unroll=unroll)
        return carry, carry[1]

    carry0 = (model.zero_carry(pressure.shape[0]), pose0)
    _, poses = jax.lax.scan(command, carry0, jnp.swapaxes(pressure, 0, 1))
    return jnp.swapaxes(poses, 0, 1)


def forward_stretched(
    model: ForwardModel,
    params,
    pressure,
    pose0,
    k,
    k_max: int,
    unroll: int = 10,
    impl: str = "lean",
):
    """F's open-loop response when each command is held k control periods (hold factor k).

    Every command is applied k times in a row and the pose after its k-th period is kept, so the
    result lines up step by step with the D_s trajectory the commands came from. `k` may be a
    traced integer in [1, k_max], so one compiled function serves every k; only the T * k live
    periods run (a while loop of ceil(T * k / unroll) iterations, each `unroll` periods long),
    forward and backward, instead of T * k_max. Under vmap over k the loop runs to the largest k.

    Reverse-mode differentiable in `pressure` and `pose0` through a custom VJP: the LSTM is
    written out with its four gates as one matrix product, the forward loop stores every
    period's activations and a hand-written backward walks them back, so a period costs a few
    larger kernels instead of many small ones, forward and backward, with no recomputation
    (F's parameters are frozen: `stop_gradient`). Equal to `forward_stretched_masked` up to
    float rounding.

    Args:
      model: the module.
      params: its variables (treated as constants).
      pressure: [B, T, 3] normalised commands.
      pose0: [B, 6] normalised pose before the first command.
      k: hold factor k, int (traced or static), 1 <= k <= k_max.
      k_max: static upper bound on k (sizes the stored activations).
      unroll: periods per loop iteration (fewer, longer iterations; numerics unchanged).
      impl: "lean" (matrix products) or "lean_reduce" (each small matrix product written as a
        broadcast multiply and a sum, which XLA can fuse with the elementwise work around it:
        the faster on a GPU, the slower on a CPU; `ccgan.trainer.resolved_feedback_impl` picks).

    Returns:
      [B, T, 6] normalised poses after each command's k-th period.
    """
    makers = {
        "lean": _make_stretched_lean,
        "lean_reduce": functools.partial(_make_stretched_lean, matmul=_multiply_sum),
    }
    if impl not in makers:
        raise ValueError(f"impl must be one of {tuple(makers)}: {impl!r}")
    fn = makers[impl](model, k_max, unroll)
    return fn(jax.lax.stop_gradient(params), pressure, pose0, jnp.asarray(k, jnp.int32))


def _loop_sizes(pressure, k, k_max: int, unroll: int):
    """(T, live periods T k, loop iterations, static buffer length in whole iterations)."""
    t = pressure.shape[1]
    n = t * k
    padded = -(-t * k_max // unroll) * unroll
    return t, n, (n + unroll - 1) // unroll, padded


class LstmWeights(NamedTuple):
    """F's variables with the four gates side by side (Flax gate order i, f, g, o).

    w_in [6 + H, 4H] (rows: pose, then hidden state), w_pressure [3, 4H], b_gate [4H],
    w_fc [H, F], b_fc [F], w_out [F, 6], b_out [6].
    """

    w_in: jax.Array
    w_pressure: jax.Array
    b_gate: jax.Array
    w_fc: jax.Array
    b_fc: jax.Array
    w_out: jax.Array
    b_out: jax.Array


def lstm_weights(params) -> LstmWeights:
    """`ForwardModel` variables ({"params": ...}) -> `LstmWeights`."""
    p = params["params"]
    cell = next(v for v in p.values() if isinstance(v, dict) and "hi" in v)
    w_x = jnp.concatenate([cell[f"i{g}"]["kernel"] for g in "ifgo"], 1)  # [6 + 3, 4H]
    w_h = jnp.concatenate([cell[f"h{g}"]["kernel"] for g in "ifgo"], 1)  # [H, 4H]
    return LstmWeights(
        w_in=jnp.concatenate([w_x[:POSE_DIM], w_h], 0),
        w_pressure=w_x[POSE_DIM:],
        b_gate=jnp.concatenate([cell[f"h{g}"]["bias"] for g in "ifgo"]),
        w_fc=p["fc"]["kernel"],
        b_fc=p["fc"]["bias"],
        w_out=p["out"]["kernel"],
        b_out=p["out"]["bias"],
    )


def _multiply_sum(x, w):
    """x [..., M] @ w [M, N] as a broadcast product and a sum over M (a fusible reduction)."""
    return jnp.sum(x[..., :, None] * w, axis=-2)


class _LeanLoop(NamedTuple):
    """Static settings of the lean rollout: LSTM width H, the bound k_max on k, periods per loop
    iteration and `matmul(x, w)`, the product every per-period matrix product uses."""

    hidden: int
    k_max: int
    unroll: int
    matmul: Callable


def _lean_cell(loop: _LeanLoop, w: LstmWeights, c, h, pose, gate_p):
    """One period forward: carry (c [B, H], h [B, H], pose [B, 6]) and the command's gate input
    gate_p [B, 4H] -> (new carry, saved [B, 6H + F]: the input cell state and every activation,
    all the backward needs)."""
    hidden, matmul = loop.hidden, loop.matmul
    z = matmul(jnp.concatenate([pose, h], -1), w.w_in) + gate_p
    s_i, s_f, s_o = (jax.nn.sigmoid(z[:, j * hidden : (j + 1) * hidden]) for j in (0, 1, 3))
    t_g = jnp.tanh(z[:, 2 * hidden : 3 * hidden])
    c_new = s_f * c + s_i * t_g
    tanh_c = jnp.tanh(c_new)
    h_new = s_o * tanh_c
    act = jnp.tanh(matmul(h_new, w.w_fc) + w.b_fc)
    pose_new = matmul(act, w.w_out) + w.b_out
    saved = jnp.concatenate([c, s_i, s_f, t_g, s_o, tanh_c, act], -1)
    return (c_new, h_new, pose_new), saved


def _lean_forward(loop: _LeanLoop, w: LstmWeights, pressure, pose0, k):
    """The live periods forward: (poses [B, T, 6] after each command's k-th period, saved
    activations [padded, B, 6H + F] of every period, those past T k unused)."""
    hidden, unroll = loop.hidden, loop.unroll
    t, n, n_iter, padded = _loop_sizes(pressure, k, loop.k_max, unroll)
    b = pressure.shape[0]
    gate_p = jnp.einsum("btp,pg->tbg", pressure, w.w_pressure) + w.b_gate  # [T, B, 4H]
    zeros = jnp.zeros((b, hidden), pressure.dtype)
    carry0 = (zeros, zeros, pose0)
    width = 6 * hidden + w.w_fc.shape[1]
    saved_buf = jnp.zeros((padded, b, width), pressure.dtype)
    pose_buf = jnp.zeros((padded, b, POSE_DIM), pressure.dtype)

    def body(state):
        j, carry, saved_buf, pose_buf = state
        saved_block, pose_block = [], []
        for u in range(unroll):
            i = j * unroll + u
            new, saved = _lean_cell(loop, w, *carry, gate_p[jnp.clip(i // k, 0, t - 1)])
            carry = jax.tree.map(lambda a, b, i=i: jnp.where(i < n, a, b), new, carry)
            saved_block.append(saved)
            pose_block.append(carry[2])
        saved_buf = jax.lax.dynamic_update_slice_in_dim(
            saved_buf, jnp.stack(saved_block), j * unroll, 0
        )
        pose_buf = jax.lax.dynamic_update_slice_in_dim(
            pose_buf, jnp.stack(pose_block), j * unroll, 0
        )
        return j + 1, carry, saved_buf, pose_buf

    state = (0, carry0, saved_buf, pose_buf)
    _, _, saved_buf, pose_buf = jax.lax.while_loop(lambda s: s[0] < n_iter, body, state)
    poses = pose_buf[(jnp.arange(t) + 1) * k - 1]  # after period (t + 1) k - 1
    return jnp.swapaxes(poses, 0, 1), saved_buf


def _lean_cell_backward(loop: _LeanLoop, w_t, saved, ct_pose, d_carry):
    """One period backward, from its saved activations [B, 6H + F].

    Args:
      w_t: (w_in^T, w_fc^T, w_out^T), transposed once outside the loop.
      ct_pose: cotangent [B, 6] of the period's output pose from the loss (non-zero where a
        command closes).
      d_carry: cotangents (d_c [B, H], d_h [B, H], d_pose [B, 6]) of the period's output carry,
        from the later periods.

    Returns:
      (cotangents (d_c, d_h, d_pose) of the period's input carry, d_z [B, 4H]: the cotangent of
      its gate pre-activations).
    """
    hidden, matmul = loop.hidden, loop.matmul
    w_in_t, w_fc_t, w_out_t = w_t
    c, s_i, s_f, t_g, s_o, tanh_c = (saved[:, m * hidden : (m + 1) * hidden] for m in range(6))
    act = saved[:, 6 * hidden :]
    d_c, d_h, d_pose = d_carry
    d_pose_new = d_pose + ct_pose
    d_fc = matmul(d_pose_new, w_out_t) * (1.0 - act * act)
    d_h_new = d_h + matmul(d_fc, w_fc_t)
    d_c_new = d_c + d_h_new * s_o * (1.0 - tanh_c * tanh_c)
    d_z = jnp.concatenate(
        [
            d_c_new * t_g * s_i * (1.0 - s_i),
            d_c_new * c * s_f * (1.0 - s_f),
            d_c_new * s_i * (1.0 - t_g * t_g),
            d_h_new * tanh_c * s_o * (1.0 - s_o),
        ],
        -1,
    )
    d_in = matmul(d_z, w_in_t)
    return (d_c_new * s_f, d_in[:, POSE_DIM:], d_in[:, :POSE_DIM]), d_z


def _lean_backward(loop: _LeanLoop, w: LstmWeights, pressure, k, saved_buf, ct):
    """The live periods backward, last first: cotangent ct [B, T, 6] of the poses ->
    (d_pressure [B, T, 3], d_pose0 [B, 6])."""
    hidden, unroll = loop.hidden, loop.unroll
    t, n, n_iter, padded = _loop_sizes(pressure, k, loop.k_max, unroll)
    b = pressure.shape[0]
    # Cotangent of the pose after each period (non-zero where a command closes).
    ct_buf = jnp.zeros((padded, b, POSE_DIM), ct.dtype)
    ct_buf = ct_buf.at[(jnp.arange(t) + 1) * k - 1].set(jnp.swapaxes(ct, 0, 1))
    w_t = (w.w_in.T, w.w_fc.T, w.w_out.T)
    zeros = jnp.zeros((b, hidden), ct.dtype)
    d_gate_buf = jnp.zeros((padded, b, 4 * hidden), ct.dtype)

    def body(state):
        j, (d_c, d_h, d_pose), d_gate_buf = state
        block = jax.lax.dynamic_slice_in_dim(saved_buf, j * unroll, unroll, 0)
        cts = jax.lax.dynamic_slice_in_dim(ct_buf, j * unroll, unroll, 0)
        d_gates = [None] * unroll
        for u in reversed(range(unroll)):
            live = j * unroll + u < n
            new, d_z = _lean_cell_backward(loop, w_t, block[u], cts[u], (d_c, d_h, d_pose))
            d_c, d_h, d_pose = (
                jnp.where(live, a, old) for a, old in zip(new, (d_c, d_h, d_pose), strict=True)
            )
            d_gates[u] = jnp.where(live, d_z, 0.0)
        d_gate_buf = jax.lax.dynamic_update_slice_in_dim(
            d_gate_buf, jnp.stack(d_gates), j * unroll, 0
        )
        return j - 1, (d_c, d_h, d_pose), d_gate_buf

    state = (n_iter - 1, (zeros, zeros, jnp.zeros_like(ct[:, 0])), d_gate_buf)
    _, (_, _, d_pose0), d_gate_buf = jax.lax.while_loop(lambda s: s[0] >= 0, body, state)
    # Sum each command's k periods: differences of a cumulative sum at the block ends.
    csum = jnp.cumsum(d_gate_buf, 0)
    ends = csum[(jnp.arange(t) + 1) * k - 1]
    d_cmd = ends - jnp.concatenate([jnp.zeros_like(ends[:1]), ends[:-1]], 0)  # [T, B, 4H]
    d_pressure = jnp.einsum("tbg,pg->btp", d_cmd, w.w_pressure)
    return d_pressure, d_pose0


def _make_stretched_lean(model: ForwardModel, k_max: int, unroll: int, matmul=jnp.matmul):
    """The custom-VJP function (params, pressure [B, T, 3], pose0 [B, 6], k) -> poses [B, T, 6].

    Live periods only: a while loop of ceil(T k / unroll) iterations, `unroll` periods each, the
    periods past T k masked. Per period the forward runs one gate product
    [B, 6 + H] x [6 + H, 4H] (the pressure part, constant over a command's k periods, is
    computed once per command), one fused gate update and the two output layers, and stores the
    activations (`_lean_forward`); the backward runs three products and two fused updates per
    period, no recomputation (`_lean_backward`). The per-command pressure gradients are block
    sums of the per-period gate gradients (a cumulative sum, no scatter). `matmul(x, w)`
    computes the six per-period products.
    """
    loop = _LeanLoop(model.hidden, k_max, unroll, matmul)

    @jax.custom_vjp
    def stretched(w, pressure, pose0, k):
        return _lean_forward(loop, w, pressure, pose0, k)[0]

    def fwd(w, pressure, pose0, k):
        poses, saved_buf = _lean_forward(loop, w, pressure, pose0, k)
        return poses, (w, pressure, k, saved_buf)

    def bwd(res, ct):
        w, pressure, k, saved_buf = res
        d_pressure, d_pose0 = _lean_backward(loop, w, pressure, k, saved_buf, ct)
        return jax.tree.map(jnp.zeros_like, w), d_pressure, d_pose0, None

    stretched.defvjp(fwd, bwd)

    def apply(params, pressure, pose0, k):
        return stretched(lstm_weights(params), pressure, pose0, k)

    return apply


class Generator(nn.Module):
    """Generator G: one domain's sample sequence -> the other domain's.

    9 in (pressure 3 + pose 6), two LSTM layers of 32, FC 128 + ReLU, linear 9. The pressure part is
    squashed with a sigmoid into the normalised valve range [0, 1]; the pose part is linear.

    Two variants, both off by default:
      per_sample: every time step on its own, as the authors' code trains G (sequences of length
        1): the same layers, the LSTMs starting from a zero carry at each step, so G is a static
        map of the current sample.
      residual: G starts as the identity and learns a correction: the pressure part is
        sigmoid(logit(p_in) + d), the pose part x_in + d, with the last layer zero at
        initialisation. D_s and D_c share their statics, so at long holds the right translation
        is near the identity; a plain G must first learn it.

    Conditioned (`n_condition` > 0, issue 51): the target medium's condition features
    (`ccgan.media_range.MediaRange.condition`, C = 2) follow the sample at every step, x
    [B, T, 9 + C], and enter the first LSTM layer with it; nothing else changes, so
    `with_condition_inputs` can start a conditioned G from a trained one. With 0 (every file
    written before) the layers, parameters and numerics are the unconditioned G's.
    """

    hidden: int = 32
    fc: int = 128
    n_layers: int = 2
    #: Time steps per iteration of the LSTM scans (numerics unchanged; the parameters do not
    #: depend on it).
    unroll: int = 1
    per_sample: bool = False
    residual: bool = False
    #: Condition features appended to each sample (0: an unconditioned G).
    n_condition: int = 0

    @nn.compact
    def __call__(self, x):
        """x: [B, T, 9 + n_condition] normalised samples (then the condition) -> [B, T, 9]
        (pressure in [0, 1], then pose)."""
        if x.shape[-1] != PRESSURE_DIM + POSE_DIM + self.n_condition:
            raise ValueError(
                f"G takes samples of {PRESSURE_DIM + POSE_DIM} features plus its"
                f" {self.n_condition} condition features, got {x.shape[-1]}"
            )
        h = x.reshape(-1, 1, x.shape[-1]) if self.per_sample else x
        for i in range(self.n_layers):
            h = nn.RNN(nn.OptimizedLSTMCell(self.hidden), unroll=self.unroll, name=f"lstm_{i}")(h)
        h = h.reshape(*x.shape[:-1], self.hidden)
        h = nn.relu(nn.Dense(self.fc, name="fc")(h))
        init = nn.initializers.zeros_init() if self.residual else nn.initializers.lecun_normal()
        out = nn.Dense(PRESSURE_DIM + POSE_DIM, kernel_init=init, name="out")(h)
        if self.residual:
            p_in = jnp.clip(x[..., :PRESSURE_DIM], 1e-3, 1 - 1e-3)
            pressure = nn.sigmoid(jnp.log(p_in) - jnp.log1p(-p_in) + out[..., :PRESSURE_DIM])
            pose_in = x[..., PRESSURE_DIM : PRESSURE_DIM + POSE_DIM]
            return jnp.concatenate([pressure, pose_in + out[..., PRESSURE_DIM:]], -1)
        return jnp.concatenate([nn.sigmoid(out[..., :PRESSURE_DIM]), out[..., PRESSURE_DIM:]], -1)


def with_condition_inputs(generator: Generator, g_params, n_condition: int):
    """A conditioned G started from a trained unconditioned one: (the generator with
    `n_condition` condition inputs, its parameters).

    The first LSTM layer's input kernels [9, H] gain `n_condition` zero rows [9 + C, H]; every
    other parameter is copied. The new G then gives the old one's output whatever the
    condition (to float rounding: the kernels' products have C more terms, each zero), and
    training moves the new rows from there.

    Args:
      generator: the trained G (`n_condition` 0).
      g_params: its variables ({"params": ...}).
      n_condition: C >= 1.

    Raises:
      ValueError: `generator` is conditioned already, or C < 1.
    """
    if generator.n_condition or n_condition < 1:
        raise ValueError(
            f"need an unconditioned G and n_condition >= 1, got {generator.n_condition} and"
            f" {n_condition}"
        )
    wide = generator.clone(n_condition=n_condition)
    sample = jnp.zeros((1, 1, PRESSURE_DIM + POSE_DIM + n_condition))
    template = jax.eval_shape(wide.init, jax.random.PRNGKey(0), sample)

    def widen(want, have):
        have = jnp.asarray(have)
        if want.shape == have.shape:
            return have
        if want.shape[1:] == have.shape[1:] and want.shape[0] == have.shape[0] + n_condition:
            return jnp.concatenate([have, jnp.zeros((n_condition,) + have.shape[1:], have.dtype)])
        raise ValueError(f"a parameter of shape {have.shape} cannot become {want.shape}")

    return wide, jax.tree.map(widen, template, g_params)


def with_hidden(generator: Generator, g_params, hidden: int, seed: int = 0):
    """A wider G started from a trained one, computing what it computed: (the generator with
    `hidden` units in each LSTM layer, its parameters).

    Every kernel [in, out] keeps its trained block; the rows of the new units (their outputs
    into the next gates and into fc) are zero, and the columns of the new units (their gates'
    inputs) and their biases are the wider G's own initialisation (`seed`). The old units then
    never read a new one, so the output is the trained G's (to float rounding: sums with zero
    terms), while the new units run and their zero rows get gradients from the first step. For
    a conditioned G over many media (issue 51), whose 32 units fit 24 media's teacher 4-9x
    worse than one medium's (`studies/results/cpu/range_fit/`).

    Args:
      generator: the trained G.
      g_params: its variables ({"params": ...}).
      hidden: units per LSTM layer, at least the trained G's.
      seed: the new units' initialisation.

    Raises:
      ValueError: `hidden` is below the trained G's.
    """
    if hidden < generator.hidden:
        raise ValueError(f"hidden {hidden} is below the trained G's {generator.hidden}")
    if hidden == generator.hidden:
        return generator, g_params
    wide = generator.clone(hidden=hidden)
    sample = jnp.zeros((1, 1, PRESSURE_DIM + POSE_DIM + generator.n_condition))
    fresh = wide.init(jax.random.PRNGKey(seed), sample)

    def widen(new, have):
        have = jnp.asarray(have)
        if have.ndim == 1:
            return new.at[: have.shape[0]].set(have)
        rows, cols = have.shape
        return new.at[rows:, :cols].set(0.0).at[:rows, :cols].set(have)

    return wide, jax.tree.map(widen, fresh, g_params)


class TimeConv(nn.Module):
    """Conv1D over time, "SAME" padding, written as one matrix product of shifted copies.

    Same variables as `nn.Conv(features, (kernel,))` (kernel [K, C, F], bias [F]) and the same
    result up to float rounding; as a product it runs as one small GEMM on the GPU, where cuDNN
    picks a slow direct convolution for these tiny shapes (`bench.profile_step` shows it;
    docs/benchmarks.md).
    """

    features: int
    kernel: int = 3

    @nn.compact
    def __call__(self, x):
        """x: [B, T, C] -> [B, T, F]."""
        w = self.param(
            "kernel", nn.initializers.lecun_normal(), (self.kernel, x.shape[-1], self.features)
        )
        b = self.param("bias", nn.initializers.zeros_init(), (self.features,))
        left = (self.kernel - 1) // 2
        t = x.shape[-2]
        padded = jnp.pad(x, [(0, 0)] * (x.ndim - 2) + [(left, self.kernel - 1 - left), (0, 0)])
        shifted = jnp.stack([padded[..., j : j + t, :] for j in range(self.kernel)], -2)
        return jnp.einsum("...tkc,kcf->...tf", shifted, w) + b


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
            h = TimeConv(f, self.kernel, name=f"conv_{i}")(h)
            h = nn.GroupNorm(num_groups=None, group_size=1, name=f"norm_{i}")(h)
            h = nn.leaky_relu(h, self.slope)
        return nn.Dense(1, name="out")(h.mean(1))[:, 0]
