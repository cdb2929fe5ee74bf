"""F_c's time-stretched open-loop rollout as two fused Pallas (Triton) GPU kernels (an option).

The feedback loss runs the frozen forward model F_c for T * k control periods one after another
(`ccgan.models.forward_stretched`). Each period is a handful of tiny matrix products (batch 10,
hidden 64), so on a GPU the XLA loop is bound by kernel launches, not arithmetic. Here the whole
rollout is one kernel and its backward pass another: the LSTM carry stays on chip and the loop
over periods runs on the GPU. Same function and gradients as `forward_stretched` (tested in the
Pallas interpreter on CPU).

Measured on an H200 (`bench/results/h200/feedback_pallas.md`), these kernels are 1.2-2.3x
*slower* than the XLA loop (about 40-50 us per period forward + backward, for every warp count
tried), so training uses the XLA "lean" rollout; `TrainConfig(feedback_impl="pallas")` selects
this one.

Layout: one Triton program per rollout (vmapping over seeds adds programs that run side by side).
Triton wants every in-kernel array to be a power of two of at least 16 per dimension, so the
batch is padded to `_padded(B)`, the pose to 16 features and F_c's FC layer to `_padded(fc)`;
padded rows and columns are zero and stay zero. The pressure part of the input gates is the same
for the k periods of a command, so it is computed once per command outside the kernel.

Only the commands (and the first pose) get gradients; F_c's parameters are frozen.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.experimental import pallas as pl

from ccgan.models import POSE_DIM, lstm_weights

#: Pose features padded to Triton's smallest matrix-product size.
_POSE_PAD = 16
_N_GATES = 4  # i, f, g, o (Flax's LSTM gate order)


def _padded(n: int) -> int:
    """The smallest power of two >= max(n, 16)."""
    return max(16, 1 << (int(n) - 1).bit_length())


class FusedWeights(NamedTuple):
    """F_c's variables laid out for the kernels (zero padded).

    w_pose [4, 16, H], w_hidden [4, H, H], w_pressure [4, 3, H], b_gate [4, 1, H],
    w_fc [H, F], b_fc [1, F], w_out [F, 16], b_out [1, 16].
    """

    w_pose: jax.Array
    w_hidden: jax.Array
    w_pressure: jax.Array
    b_gate: jax.Array
    w_fc: jax.Array
    b_fc: jax.Array
    w_out: jax.Array
    b_out: jax.Array


def fused_weights(params) -> FusedWeights:
    """`ForwardModel` variables ({"params": ...}) -> `FusedWeights`.

    Raises:
      ValueError: the LSTM width is not a power of two >= 16 (use the XLA rollout then).
    """
    w = lstm_weights(params)
    hidden = w.w_fc.shape[0]
    if hidden != _padded(hidden):
        raise ValueError(f"fused F_c rollout needs an LSTM width 2^n >= 16, got {hidden}")

    def per_gate(m):  # [rows, 4H] -> [4, rows, H]
        return jnp.moveaxis(m.reshape(m.shape[0], _N_GATES, hidden), 1, 0)

    fc = w.w_fc.shape[1]
    pad_fc = _padded(fc) - fc
    pad_pose = _POSE_PAD - POSE_DIM
    return FusedWeights(
        w_pose=jnp.pad(per_gate(w.w_in[:POSE_DIM]), ((0, 0), (0, pad_pose), (0, 0))),
        w_hidden=per_gate(w.w_in[POSE_DIM:]),
        w_pressure=per_gate(w.w_pressure),
        b_gate=per_gate(w.b_gate[None]),
        w_fc=jnp.pad(w.w_fc, ((0, 0), (0, pad_fc))),
        b_fc=jnp.pad(w.b_fc, (0, pad_fc))[None],
        w_out=jnp.pad(w.w_out, ((0, pad_fc), (0, pad_pose))),
        b_out=jnp.pad(w.b_out, (0, pad_pose))[None],
    )


def _sigmoid(x):
    return 1.0 / (1.0 + jnp.exp(-x))


def _period(c, h, pose, gate_in, w_pose, w_hidden, w_fc, b_fc, w_out, b_out):
    """One period of F_c; returns the new carry and what the backward needs.

    The weights are values or refs (`w[g]`, `w[...]` read either).
    """
    z = [jnp.dot(pose, w_pose[g]) + jnp.dot(h, w_hidden[g]) + gate_in[g] for g in range(_N_GATES)]
    s_i, s_f, t_g, s_o = _sigmoid(z[0]), _sigmoid(z[1]), jnp.tanh(z[2]), _sigmoid(z[3])
    c_new = s_f * c + s_i * t_g
    tanh_c = jnp.tanh(c_new)
    h_new = s_o * tanh_c
    act_fc = jnp.tanh(jnp.dot(h_new, w_fc[...]) + b_fc[...])
    pose_new = jnp.dot(act_fc, w_out[...]) + b_out[...]
    return (c_new, h_new, pose_new), (s_i, s_f, t_g, s_o, tanh_c, act_fc)


def _load_weights(refs, hoist: bool):
    """F_c's weight refs as values read once (hoist) or as the refs, read where used."""
    w_pose_ref, w_hidden_ref, w_fc_ref, b_fc_ref, w_out_ref, b_out_ref = refs
    if not hoist:
        return w_pose_ref, w_hidden_ref, w_fc_ref, b_fc_ref, w_out_ref, b_out_ref
    w_pose = [w_pose_ref[g] for g in range(_N_GATES)]
    w_hidden = [w_hidden_ref[g] for g in range(_N_GATES)]
    return w_pose, w_hidden, w_fc_ref[...], b_fc_ref[...], w_out_ref[...], b_out_ref[...]


def _forward_kernel(
    nk_ref,
    gate_in_ref,
    pose0_ref,
    w_pose_ref,
    w_hidden_ref,
    w_fc_ref,
    b_fc_ref,
    w_out_ref,
    b_out_ref,
    c_buf,
    h_buf,
    pose_buf,
    *,
    hoist: bool,
):
    """Runs the n = nk[0] live periods; buffers row i holds the carry before period i."""
    n, k = nk_ref[0], nk_ref[1]
    weight_refs = (w_pose_ref, w_hidden_ref, w_fc_ref, b_fc_ref, w_out_ref, b_out_ref)
    weights = _load_weights(weight_refs, hoist)
    zeros = jnp.zeros(c_buf.shape[1:], jnp.float32)
    pose0 = pose0_ref[...]
    c_buf[0], h_buf[0], pose_buf[0] = zeros, zeros, pose0

    def body(i, carry):
        cmd = i // k
        gate_in = [gate_in_ref[g, cmd] for g in range(_N_GATES)]
        (c, h, pose), _ = _period(*carry, gate_in, *weights)
        c_buf[i + 1], h_buf[i + 1], pose_buf[i + 1] = c, h, pose
        return c, h, pose

    jax.lax.fori_loop(0, n, body, (zeros, zeros, pose0))


def _backward_kernel(
    nk_ref,
    gate_in_ref,
    c_buf,
    h_buf,
    pose_buf,
    ct_pose_buf,
    w_pose_ref,
    w_hidden_ref,
    w_fc_ref,
    b_fc_ref,
    w_out_ref,
    b_out_ref,
    w_pose_t_ref,
    w_hidden_t_ref,
    w_fc_t_ref,
    w_out_t_ref,
    d_gate_buf,
    d_pose0_ref,
    *,
    hoist: bool,
):
    """Reverse loop over the live periods: recompute each from its stored carry, then backprop.

    ct_pose_buf row i + 1 is the loss cotangent of the pose after period i; d_gate_buf [4, N, B, H]
    receives each period's gate pre-activation gradients (summed per command outside).
    """
    n, k = nk_ref[0], nk_ref[1]
    weight_refs = (w_pose_ref, w_hidden_ref, w_fc_ref, b_fc_ref, w_out_ref, b_out_ref)
    weights = _load_weights(weight_refs, hoist)
    w_pose_t, w_hidden_t, w_fc_t, _, w_out_t, _ = _load_weights(
        (w_pose_t_ref, w_hidden_t_ref, w_fc_t_ref, b_fc_ref, w_out_t_ref, b_out_ref), hoist
    )

    def body(j, cts):
        d_c, d_h, d_pose = cts
        i = n - 1 - j
        c, h, pose = c_buf[i], h_buf[i], pose_buf[i]
        gate_in = [gate_in_ref[g, i // k] for g in range(_N_GATES)]
        _, (s_i, s_f, t_g, s_o, tanh_c, act_fc) = _period(c, h, pose, gate_in, *weights)
        d_pose_new = d_pose + ct_pose_buf[i + 1]
        d_fc = jnp.dot(d_pose_new, w_out_t[...]) * (1.0 - act_fc * act_fc)
        d_h_new = d_h + jnp.dot(d_fc, w_fc_t[...])
        d_c_new = d_c + d_h_new * s_o * (1.0 - tanh_c * tanh_c)
        d_z = (
            d_c_new * t_g * s_i * (1.0 - s_i),
            d_c_new * c * s_f * (1.0 - s_f),
            d_c_new * s_i * (1.0 - t_g * t_g),
            d_h_new * tanh_c * s_o * (1.0 - s_o),
        )
        d_h_prev = jnp.dot(d_z[0], w_hidden_t[0])
        d_pose_prev = jnp.dot(d_z[0], w_pose_t[0])
        for g in range(1, _N_GATES):
            d_h_prev += jnp.dot(d_z[g], w_hidden_t[g])
            d_pose_prev += jnp.dot(d_z[g], w_pose_t[g])
        for g in range(_N_GATES):
            d_gate_buf[g, i] = d_z[g]
        return d_c_new * s_f, d_h_prev, d_pose_prev

    zeros_h = jnp.zeros(c_buf.shape[1:], jnp.float32)
    zeros_pose = jnp.zeros(pose_buf.shape[1:], jnp.float32)
    d_pose0_ref[...] = jax.lax.fori_loop(0, n, body, (zeros_h, zeros_h, zeros_pose))[2]


def make_forward_stretched_fused(
    k_max: int, interpret: bool = False, num_warps: int = 4, hoist_weights: bool = False
):
    """`fn(weights, pressure [B, T, 3], pose0 [B, 6], k) -> poses [B, T, 6]` (custom VJP).

    Same contract as `ccgan.models.forward_stretched` with F_c's weights prepared by
    `fused_weights`; gradients flow to pressure and pose0, not to the weights.

    Args:
      k_max: the largest hold factor (static buffer length T * k_max + 1).
      interpret: run the kernels in the Pallas interpreter (CPU tests).
      num_warps: Triton warps per rollout.
      hoist_weights: read F_c's weights into registers once, before the loop (else on use).
    """
    params = {}
    if not interpret:
        from jax.experimental.pallas import triton as plgpu

        params["compiler_params"] = plgpu.CompilerParams(num_warps=num_warps, num_stages=1)
    forward_kernel = functools.partial(_forward_kernel, hoist=hoist_weights)
    backward_kernel = functools.partial(_backward_kernel, hoist=hoist_weights)

    def sizes(pressure):
        b, t, _ = pressure.shape
        return b, t, _padded(b), t * k_max

    def gate_inputs(w: FusedWeights, pressure, b_pad):
        """[4, T, B_pad, H]: the pressure part of the gate pre-activations plus the biases."""
        p_tm = jnp.swapaxes(pressure, 0, 1)
        p_tm = jnp.pad(p_tm, ((0, 0), (0, b_pad - p_tm.shape[1]), (0, 0)))
        return jnp.einsum("tbp,gph->gtbh", p_tm, w.w_pressure) + w.b_gate[:, None]

    def run(w: FusedWeights, pressure, pose0, k):
        b, t, b_pad, n_max = sizes(pressure)
        hidden = w.w_hidden.shape[-1]
        k = jnp.asarray(k, jnp.int32)
        nk = jnp.stack([t * k, k])
        gate_in = gate_inputs(w, pressure, b_pad)
        pose0_pad = jnp.pad(pose0, ((0, b_pad - b), (0, _POSE_PAD - POSE_DIM)))
        buf = lambda f: jax.ShapeDtypeStruct((n_max + 1, b_pad, f), jnp.float32)  # noqa: E731
        c_buf, h_buf, pose_buf = pl.pallas_call(
            forward_kernel,
            out_shape=(buf(hidden), buf(hidden), buf(_POSE_PAD)),
            interpret=interpret,
            name="fc_stretched_forward",
            **params,
        )(nk, gate_in, pose0_pad, w.w_pose, w.w_hidden, w.w_fc, w.b_fc, w.w_out, w.b_out)
        rows = (jnp.arange(t) + 1) * k
        poses = jnp.swapaxes(pose_buf[rows, :b, :POSE_DIM], 0, 1)
        return poses, (nk, gate_in, c_buf, h_buf, pose_buf)

    @jax.custom_vjp
    def stretched(w, pressure, pose0, k):
        return run(w, pressure, pose0, k)[0]

    def fwd(w, pressure, pose0, k):
        poses, res = run(w, pressure, pose0, k)
        return poses, (w, pressure.shape, res)

    def bwd(residuals, ct):
        w, shape, (nk, gate_in, c_buf, h_buf, pose_buf) = residuals
        b, t, b_pad, n_max = sizes(jax.ShapeDtypeStruct(shape, jnp.float32))
        n, k = nk[0], nk[1]
        ct_tm = jnp.pad(jnp.swapaxes(ct, 0, 1), ((0, 0), (0, b_pad - b), (0, _POSE_PAD - POSE_DIM)))
        ct_buf = jnp.zeros_like(pose_buf).at[(jnp.arange(t) + 1) * k].set(ct_tm)
        t_last = lambda x: jnp.swapaxes(x, -1, -2)  # noqa: E731
        d_gate, d_pose0 = pl.pallas_call(
            backward_kernel,
            out_shape=(
                jax.ShapeDtypeStruct((_N_GATES, n_max) + c_buf.shape[1:], jnp.float32),
                jax.ShapeDtypeStruct(pose_buf.shape[1:], jnp.float32),
            ),
            interpret=interpret,
            name="fc_stretched_backward",
            **params,
        )(
            nk,
            gate_in,
            c_buf,
            h_buf,
            pose_buf,
            ct_buf,
            w.w_pose,
            w.w_hidden,
            w.w_fc,
            w.b_fc,
            w.w_out,
            w.b_out,
            t_last(w.w_pose),
            t_last(w.w_hidden),
            t_last(w.w_fc),
            t_last(w.w_out),
        )
        # Rows past the n live periods were never written: mask before summing per command.
        period = jnp.arange(n_max)
        live = (period < n)[None, :, None, None]
        d_gate = jnp.where(live, d_gate, 0.0)
        d_cmd = jax.ops.segment_sum(
            jnp.moveaxis(d_gate, 1, 0), jnp.minimum(period // k, t - 1), num_segments=t
        )  # [T, 4, B_pad, H]
        d_pressure = jnp.einsum("tgbh,gph->btp", d_cmd[:, :, :b], w.w_pressure)
        zeros_w = jax.tree.map(jnp.zeros_like, w)
        return zeros_w, d_pressure, d_pose0[:b, :POSE_DIM], None

    stretched.defvjp(fwd, bwd)
    return stretched
