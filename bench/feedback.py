"""The feedback rollout alone: XLA loop against the fused Pallas kernels, forward + backward.

Times `jax.grad` of a loss through F_c's time-stretched open-loop rollout (the feedback term of
one CCGAN-GP train step: batch 10, window 10, F_c 64/50) for several hold factors k, one seed and
vmapped seeds, and checks that both implementations agree (poses and gradients).

    python -m bench.feedback --out bench/results/h200     # GPU (pallas needs one)
    python -m bench.feedback --interpret --k 2 --reps 1   # CPU: the Pallas interpreter

Writes feedback.md and feedback.json to --out.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

from ccgan import models
from ccgan.fused_feedback import fused_weights, make_forward_stretched_fused
from mjx_arm.machine import cpu_model


def _timed(fn, args, reps: int) -> tuple[float, float]:
    """(compile s, mean s per call) of jitted fn(*args)."""
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - t0
    jax.block_until_ready(compiled(*args))
    t0 = time.perf_counter()
    for _ in range(reps):
        jax.block_until_ready(compiled(*args))
    return compile_s, (time.perf_counter() - t0) / reps


def make_rollout(spec: str, fwd, params, pose0, k_max: int, interpret: bool):
    """A rollout `(pressure [B, T, 3], k) -> poses` from a spec.

    Specs: "cell:UNROLL" / "lean:UNROLL" (`models.forward_stretched` with that impl and unroll),
    "pallas:WARPS:HOIST" (`ccgan.fused_feedback`; HOIST 1 reads the weights once, before the loop).
    """
    kind, *opts = spec.split(":")
    if kind in ("cell", "lean"):
        unroll = int(opts[0])
        return lambda p, k: models.forward_stretched(
            fwd, params, p, pose0, k, k_max, unroll=unroll, impl=kind
        )
    if kind == "pallas":
        warps, hoist = (int(v) for v in opts)
        fused = make_forward_stretched_fused(
            k_max, interpret=interpret, num_warps=warps, hoist_weights=bool(hoist)
        )
        weights = fused_weights(params)
        return lambda p, k: fused(weights, p, pose0, k)
    raise ValueError(f"unknown rollout spec {spec!r}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="bench/results")
    parser.add_argument("--k", type=int, nargs="+", default=[5, 10, 30])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 3])
    parser.add_argument("--batch", type=int, default=10)
    parser.add_argument("--window", type=int, default=10)
    parser.add_argument("--k-max", type=int, default=30)
    parser.add_argument("--reps", type=int, default=50)
    parser.add_argument("--interpret", action="store_true", help="Pallas interpreter (CPU)")
    parser.add_argument(
        "--impls",
        nargs="+",
        default=["cell:10", "lean:10", "pallas:4:1"],
        help="rollouts timed (see make_rollout); the first is the reference of the ratios",
    )
    parser.add_argument("--tag", default="", help="suffix of the output file names")
    args = parser.parse_args(argv)

    fwd = models.ForwardModel()
    keys = jax.random.split(jax.random.PRNGKey(0), 4)
    pressure = jax.random.uniform(keys[0], (max(args.seeds), args.batch, args.window, 3))
    pose0 = jax.random.uniform(keys[1], (args.batch, 6))
    target = jax.random.uniform(keys[2], (args.batch, args.window, 6))
    params = fwd.init(keys[3], pose0[:, None], pressure[0, :, :1])
    rollouts = {
        spec: make_rollout(spec, fwd, params, pose0, args.k_max, args.interpret)
        for spec in args.impls
    }
    ref_name = args.impls[0]

    def loss_and_grad(name):
        def loss(p, k):
            return jnp.mean((rollouts[name](p, k) - target) ** 2)

        return jax.vmap(jax.value_and_grad(loss), in_axes=(0, None))

    rows = []
    for k in args.k:
        kk = jnp.int32(k)
        _, ref_grad = jax.jit(loss_and_grad(ref_name))(pressure[:1], kk)
        ref_pose = rollouts[ref_name](pressure[0], kk)
        ref_ms = {}
        for name in rollouts:
            _, grad = jax.jit(loss_and_grad(name))(pressure[:1], kk)
            pose_err = float(jnp.abs(rollouts[name](pressure[0], kk) - ref_pose).max())
            grad_err = float(jnp.abs(grad - ref_grad).max() / jnp.abs(ref_grad).max())
            for n_seeds in args.seeds:
                compile_s, call_s = _timed(loss_and_grad(name), (pressure[:n_seeds], kk), args.reps)
                ref_ms.setdefault(n_seeds, 1e3 * call_s)
                row = {"k": k, "seeds": n_seeds, "impl": name, "compile_s": compile_s}
                row.update(ms=1e3 * call_s, speedup=ref_ms[n_seeds] / (1e3 * call_s))
                row.update(pose_max_abs_diff=pose_err, grad_max_rel_diff=grad_err)
                rows.append(row)
                print(json.dumps(row), flush=True)

    device = jax.devices()[0]
    report = {
        "device": f"{device.platform}: {device.device_kind}",
        "cpu": cpu_model(),
        "jax": jax.__version__,
        "interpret": args.interpret,
        "batch": args.batch,
        "window": args.window,
        "k_max": args.k_max,
        "rows": rows,
    }
    lines = [
        f"# Feedback rollout, forward + backward ({report['device']}, {report['cpu']})",
        "",
        f"F_c 64/50, batch {args.batch}, window {args.window}, k_max {args.k_max}; mean of "
        f"{args.reps} calls of value_and_grad; jax {jax.__version__}. Command: `python -m "
        f"bench.feedback {' '.join(sys.argv[1:] if argv is None else argv)}`. Implementations: "
        "cell:U = Flax cell, jax.vjp per period, U periods per loop iteration; lean:U = gates "
        "fused, activations stored, hand-written backward; pallas:W:H = two fused Triton kernels "
        f"(W warps, H = weights hoisted). Speed-up and differences against {ref_name}.",
        "",
        "| k | seeds | implementation | ms | speed-up | max pose diff | max grad diff (rel) |",
        "|---|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {r['k']} | {r['seeds']} | {r['impl']} | {r['ms']:.3f} | {r['speedup']:.2f}x "
        f"| {r['pose_max_abs_diff']:.1e} | {r['grad_max_rel_diff']:.1e} |"
        for r in rows
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"feedback{args.tag}.json").write_text(json.dumps(report, indent=2))
    (out / f"feedback{args.tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
