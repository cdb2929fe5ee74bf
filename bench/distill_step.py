"""The distillation's optimiser step: seconds per Adam step of G_c over whole programs, with its
LSTM scans unrolled U time steps per loop iteration (`DistillConfig.generator_unroll`).

`ccgan.distill` teaches G_c (two LSTM layers) over whole 60 s programs: 600 sequential steps per
layer forward and as many backward, for every seed at once. The chain runs 5,520 such steps per
distillation (`experiments/paper.json`), so their latency sets the stage's length. This times
`ccgan.distill.init_imitation`'s jitted step on random samples of the chain's shape (the
chain's CCGAN-GP generator, `--seeds` copies, `--batch` programs of `--steps` source steps) for
each `--unrolls` value, after one call that compiles it; the loss must equal the first row's to
float32 rounding.

    python -m bench.distill_step --out bench/results/h100/distill_step       # on a GPU
    python -m bench.distill_step --batch 4 --steps 20 --unrolls 1 5 --out /tmp/d  # CPU smoke

Writes OUT.md and OUT.json, rewritten after every row.
"""

from __future__ import annotations

import time

import jax
import numpy as np

from bench import parse_checked, run_header, write_results
from ccgan import distill, load_translator
from ccgan.cli import cli_parser


def time_step(translators, data, config, unroll: int, repeats: int) -> dict:
    """Compiles and times the imitation step at `unroll`: {"unroll", "compile_s" (first call),
    "step_s" (median of `repeats` steps), "loss" [S] of the first step}."""
    translators = distill.with_generator_unroll(translators, unroll)
    step, params, opt_state = distill.init_imitation(translators, config, data)
    s_batch, c_batch = data.s_train[: config.batch_size], data.c_train[: config.batch_size]
    t0 = time.perf_counter()
    params, opt_state, loss = jax.block_until_ready(step(params, opt_state, s_batch, c_batch))
    compile_s = time.perf_counter() - t0
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        params, opt_state, _ = jax.block_until_ready(step(params, opt_state, s_batch, c_batch))
        walls.append(time.perf_counter() - t0)
    return {
        "unroll": unroll,
        "compile_s": compile_s,
        "step_s": float(np.median(walls)),
        "loss": np.asarray(loss, np.float64).tolist(),
    }


def main(argv=None) -> None:
    p = cli_parser("bench.distill_step", __doc__)
    p.add_argument("--seeds", type=int, default=3, help="G_c copies trained at once")
    p.add_argument("--batch", type=int, default=80, help="programs per step (the chain's 80)")
    p.add_argument("--steps", type=int, default=600, help="source steps per program (60 s)")
    p.add_argument("--unrolls", type=int, nargs="+", default=[1, 5, 10, 25])
    p.add_argument("--repeats", type=int, default=20, help="timed steps per row (median kept)")
    p.add_argument("--out", required=True, help="output prefix (writes .md and .json)")
    a = parse_checked(p, argv)
    if min(a.unrolls + [a.seeds, a.batch, a.steps, a.repeats]) < 1:
        p.error("--unrolls, --seeds, --batch, --steps and --repeats must be >= 1")
    translators = [load_translator()] * a.seeds  # the chain's CCGAN-GP generator
    rng = np.random.default_rng(0)
    samples = rng.uniform(0, 1, (a.batch, a.steps, 9)).astype(np.float32)
    data = distill.ImitationData(
        s_train=samples,
        c_train=rng.uniform(0, 1, (a.batch, a.steps, 3)).astype(np.float32),
        s_val=samples[:1],
        x_val=np.zeros((1, a.steps, 6)),
        p_val=np.zeros((1, a.steps, 3)),
        c_val=np.zeros((1, a.steps, 3)),
        teacher_val_x_err_cm=np.zeros(1),
        window=a.steps,
    )
    config = distill.DistillConfig(n_train=a.batch, batch_size=a.batch, final_lr_factor=0.02)
    header = run_header("bench.distill_step", argv) | {"device_name": str(jax.devices()[0])}
    body = [
        "",
        f"{a.seeds} G_c copies, {a.batch} programs of {a.steps} source steps per step; median of"
        f" {a.repeats} steps after the compiling one.",
        "",
        "| unroll | compile s | ms per step | / first row | loss against the first row |",
        "|---|---|---|---|---|",
    ]
    rows = []
    for unroll in a.unrolls:
        row = time_step(translators, data, config, unroll, a.repeats)
        rows.append(row)
        gap = float(np.max(np.abs(np.subtract(row["loss"], rows[0]["loss"]))))
        row["loss_gap"] = gap
        body.append(
            f"| {unroll} | {row['compile_s']:.1f} | {1e3 * row['step_s']:.2f} |"
            f" {row['step_s'] / rows[0]['step_s']:.2f} | {gap:.2g} |"
        )
        print(body[-1], flush=True)
        write_results(a.out, header, {"rows": rows}, "Distillation step latency", body)


if __name__ == "__main__":
    main()
