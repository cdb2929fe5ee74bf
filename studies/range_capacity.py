"""Is G_c's width what holds the conditioned translator back? (issue 51)

`studies.range_fit` found the range translator under-fitting its teacher: as far from it on its
training programs as on held-out ones, with a training loss 4-9x a one-medium distillation's.
This study continues the committed range translator's training (one seed) for `--steps` Adam
steps at one constant step size, at its own width and widened (`ccgan.models.with_hidden`,
which keeps its output), every variant on the same batches in the same order, and reports:

- the training loss (the unweighted MSE of the normalised commands over all training programs)
  along the way;
- at the end, the held-out score per training medium (the training's own validation: X_err,
  cm, MuJoCo C in each medium's 5-step copy at its k, on its held-out programs).

A wider G_c whose training loss falls faster and whose held-out score follows is the GPU run
to make (`tools/device/media_range.sh distill` with `DISTILL_ARGS="--generator-hidden H"`).
Only the teacher's programs are used: no held-out medium and no test shape.

    python -m studies.range_capacity --parts runs/media_range/part{0,1,2,3} \\
        --translator studies/results/h200/media_range/full/range/translator_seed0.ckpt \\
        --hidden 32 96 --steps 600 --learning-rate 5e-5 --loss-every 100 \\
        --out studies/results/cpu/range_capacity/range_capacity
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan import load_translator
from ccgan.cli import cli_parser
from ccgan.distill.imitation import init_imitation, with_generator_unroll
from ccgan.distill_range import cli as range_cli
from ccgan.distill_range import plan_media
from ccgan.distill_range.imitation import make_range_validation, range_data
from ccgan.distill_range.media import medium_arm
from ccgan.models import with_hidden
from studies.checks import parse_checked_args
from studies.range_fit import teacher_from_parts


def main(argv=None) -> None:
    p = cli_parser("studies.range_capacity", __doc__)
    p.add_argument("--parts", nargs="+", required=True, type=Path, help="teacher part folders")
    p.add_argument("--translator", required=True, help="a conditioned file (one seed)")
    p.add_argument("--hidden", type=int, nargs="+", default=[32, 96], help="widths to compare")
    p.add_argument("--steps", type=int, default=300, help="Adam steps per width")
    p.add_argument("--learning-rate", type=float, default=2e-4, help="constant step size")
    p.add_argument("--loss-every", type=int, default=50, help="steps between training losses")
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    if a.steps < 1 or a.loss_every < 1 or a.learning_rate <= 0:
        p.error("--steps and --loss-every must be >= 1 and --learning-rate > 0")
    import jax
    import jax.numpy as jnp

    t0 = time.perf_counter()
    range_config, config = range_cli.preset_configs()  # the range's one-GPU settings
    config = dataclasses.replace(config, learning_rate=a.learning_rate, final_lr_factor=1.0)
    arm_s, arm_c = (mjx_arm.load(domain=d) for d in ("source", "constrained"))
    training, media_range = plan_media(range_config, arm_c)
    teacher = teacher_from_parts(a.parts, config, training, arm_s, arm_c)
    start = load_translator(a.translator, method="distill_range")
    if min(a.hidden) < start.generator.hidden:
        p.error(f"--hidden: at least the translator's {start.generator.hidden}")
    data = range_data(teacher, training, media_range, start.bounds, config.window_s)
    score_arms = [
        medium_arm(arm_c, m.drag_ratio, m.stiffness_scale).planning_copy(config.score_substeps)
        for m in training
    ]
    n = data.s_train.shape[0]
    b = config.batch_size
    passes = -(-a.steps * b // n)
    order = np.concatenate([np.random.default_rng(i).permutation(n) for i in range(passes)])
    batches = order[: a.steps * b].reshape(a.steps, b)
    results = {}
    for hidden in a.hidden:
        generator, params = with_hidden(start.generator, start.g_c_params, hidden)
        wide = dataclasses.replace(start, generator=generator, g_c_params=params)
        (wide,) = with_generator_unroll([wide], config.generator_unroll)
        step, stacked, opt_state = init_imitation([wide], config, data)
        loss_fn = jax.jit(lambda g, wide=wide: jnp.stack([
            jnp.mean((wide.generator.apply(g, data.s_train[i : i + b])[..., :3]
                      - data.c_train[i : i + b]) ** 2) for i in range(0, n, b)
        ]).mean())  # fmt: skip
        losses = {0: float(jax.vmap(loss_fn)(stacked)[0])}
        t_w = time.perf_counter()
        for i, rows in enumerate(batches, 1):
            stacked, opt_state, _ = step(stacked, opt_state, data.s_train[rows], data.c_train[rows])
            if i % a.loss_every == 0 or i == a.steps:
                losses[i] = float(jax.vmap(loss_fn)(stacked)[0])
                print(f"hidden {hidden}: step {i}, training loss {losses[i]:.3e}")
        train_s = time.perf_counter() - t_w
        held_out = make_range_validation(wide, score_arms, training, data)(stacked)
        results[hidden] = {
            "training_loss": losses,
            "held_out_score_cm": float(held_out["score"][0]),
            "held_out_by_medium_cm": held_out["by_medium"][0].tolist(),
            "train_s": train_s,
        }
        print(f"hidden {hidden}: held-out {results[hidden]['held_out_score_cm']:.4f} cm")
    base = results[a.hidden[0]]
    lines = [
        "",
        f"From {a.translator} (width {start.generator.hidden}), {a.steps} Adam steps of"
        f" {config.batch_size} programs at a constant {a.learning_rate:g}, the same batches"
        f" for every width; {n} training programs over {len(training)} media. Training loss:"
        " the MSE of the normalised commands over all of them (unweighted). Held-out: the"
        " training's validation score (cm), the mean over the training media.",
        "",
        "| width | training loss at the start | at the end | end / start | held-out cm |"
        f" held-out / width {a.hidden[0]}'s | media better than width {a.hidden[0]} |"
        " seconds of steps (CPU) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for hidden, r in results.items():
        first, last = r["training_loss"][0], r["training_loss"][a.steps]
        better = np.sum(
            np.array(r["held_out_by_medium_cm"]) < np.array(base["held_out_by_medium_cm"])
        )
        lines.append(
            f"| {hidden} | {first:.3e} | {last:.3e} | {last / first:.3f} |"
            f" {r['held_out_score_cm']:.4f} |"
            f" {r['held_out_score_cm'] / base['held_out_score_cm']:.3f}x |"
            f" {better} of {len(training)} | {r['train_s']:.0f} |"
        )
    result = {"translator": a.translator, "steps": a.steps, "widths": results,
              "wall_s": time.perf_counter() - t0}  # fmt: skip
    print("\n".join(lines))
    title = "The conditioned translator's training continued at its width and wider"
    write_results(a.out, run_header("studies.range_capacity", argv), result, title, lines)


if __name__ == "__main__":
    main()
