"""Latency of the MJX physics loop: milliseconds per physics step of a batch of arms, with the
loop over a control period's steps unrolled U steps per iteration.

The chain's longest GPU stages are long sequences of small kernels: the teacher
(`tracking.mpc_mjx`, two passes of k control periods per source step), the oracle's Adam steps
and the distillation's held-out scoring (`docs/chain.md`, "The 30-minute chain"). Their wall time
is the latency of one physics step times the steps in sequence, whatever the batch. This times
`mjx_arm.arm.rollout_program` (jitted, vmapped over `--batch` programs of `--periods` control
periods, every command random) for each `--unrolls` value, after one call that compiles it; the
poses must equal those of the first row to float32 rounding (the same arithmetic in another
loop, which XLA may fuse otherwise). XLA_FLAGS set before
the run (e.g. command buffers for the loop) apply to every row and are recorded.

    python -m bench.step_latency --out bench/results/h100/step_latency          # on a GPU
    python -m bench.step_latency --batch 4 --periods 2 --unrolls 1 5 --out /tmp/l  # CPU smoke

Writes OUT.md and OUT.json, rewritten after every row.
"""

from __future__ import annotations

import functools
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import mjx_arm
from bench import parse_checked, run_header, write_results
from ccgan.cli import cli_parser


def time_rollout(arm, commands: np.ndarray, unroll: int, repeats: int) -> dict:
    """Compiles and times the vmapped rollout of `commands` [B, T, 3] (bar) at `unroll`.

    Returns {"unroll", "compile_s" (first call), "wall_s" (best of `repeats` calls),
    "ms_per_step" (wall over T x substeps sequential physics steps), "poses" [B, T, 6]}.
    """
    fn = functools.partial(arm.rollout_fn(), unroll=unroll)  # rollout_program, bound to the arm
    run = jax.jit(jax.vmap(fn, in_axes=(None, 0)))
    batch = jnp.asarray(commands, dtype=jnp.float32)
    t0 = time.perf_counter()
    poses, _ = jax.block_until_ready(run(arm.mjx_model, batch))
    compile_s = time.perf_counter() - t0
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(run(arm.mjx_model, batch))
        walls.append(time.perf_counter() - t0)
    steps = commands.shape[1] * arm.n_substeps
    return {
        "unroll": unroll,
        "compile_s": compile_s,
        "wall_s": min(walls),
        "ms_per_step": 1e3 * min(walls) / steps,
        "poses": np.asarray(poses, dtype=np.float64),
    }


def main(argv=None) -> None:
    p = cli_parser("bench.step_latency", __doc__)
    p.add_argument("--model", default="models/softarm.xml", help="the arm's MJCF")
    p.add_argument("--domain", default="constrained", help="the arm's domain")
    p.add_argument("--batch", type=int, default=256, help="programs at once (the teacher's 256)")
    p.add_argument("--periods", type=int, default=15, help="control periods per program (k)")
    p.add_argument("--unrolls", type=int, nargs="+", default=[1, 5, 25], help="steps per loop")
    p.add_argument("--repeats", type=int, default=3, help="timed calls per row (best kept)")
    p.add_argument("--out", required=True, help="output prefix (writes .md and .json)")
    a = parse_checked(p, argv)
    if min(a.unrolls) < 1 or a.batch < 1 or a.periods < 1 or a.repeats < 1:
        p.error("--unrolls, --batch, --periods and --repeats must be >= 1")
    arm = mjx_arm.load(a.model, a.domain)
    rng = np.random.default_rng(0)
    commands = rng.uniform(0.2, 3.5, (a.batch, a.periods, 3))
    header = run_header("bench.step_latency", argv) | {
        "device_name": str(jax.devices()[0]),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }
    rows, reference = [], None
    body = [
        "",
        f"{a.batch} programs of {a.periods} control periods ({arm.n_substeps} physics steps of"
        f" {arm.timestep_s * 1e3:g} ms each), {a.domain} domain; best of {a.repeats} calls.",
        "",
        "| unroll | compile s | wall s | ms per physics step | / first row"
        " | tip against the first row, mm |",
        "|---|---|---|---|---|---|",
    ]
    for unroll in a.unrolls:
        row = time_rollout(arm, commands, unroll, a.repeats)
        poses = row.pop("poses")
        reference = poses if reference is None else reference
        row["tip_diff_mm"] = float(1e3 * np.abs(poses[..., :3] - reference[..., :3]).max())
        rows.append(row)
        first = rows[0]["ms_per_step"]
        body.append(
            f"| {unroll} | {row['compile_s']:.1f} | {row['wall_s']:.3f} |"
            f" {row['ms_per_step']:.4f} | {row['ms_per_step'] / first:.2f} |"
            f" {row['tip_diff_mm']:.2g} |"
        )
        result = {"batch": a.batch, "periods": a.periods, "rows": rows}
        write_results(a.out, header, result, "MJX physics-step latency", body)
        print(body[-1], flush=True)


if __name__ == "__main__":
    main()
