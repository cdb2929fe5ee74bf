"""Does the conditioned translator over media under- or over-fit its teacher? (issue 51)

The range translator is 1.5-7.5x its teacher on the held-out programs of its own training media
(`studies/results/h200/media_range/full/range/distill_range.json`). This study tells which:

- per training medium, the imitation error (MSE of G_c's commands against the teacher's, both
  normalised to [0, 1] as the training loss is) on the medium's training programs and on its
  held-out programs;
- per training medium, X_err (cm, MuJoCo C, in the medium's `planning_copy(5)` arm as the
  training's validation scores, each held the medium's k) of the teacher and of the translator
  on `--n-train-scored` training programs and on the held-out programs.

A student near its teacher on training programs and far from it on held-out ones is short of
programs (over-fit: more programs per medium is the lever); one far from it on both is short of
fit (capacity, the loss's weighting, the schedule). Only the teacher's programs are used: no
test shape and no held-out medium.

It reads the teacher's commands from parts planned by `tools/device/media_range.sh teacher`
(the one-GPU settings, `ccgan.distill_range.cli.PAPER_SETTINGS`) and plans nothing: a part
planned under other settings stops it.

    python -m studies.range_fit --parts runs/media_range/part{0,1,2,3} \\
        --translators studies/results/h200/media_range/full/range/translator_seed{0,1,2}.ckpt \\
        --out studies/results/cpu/range_fit/range_fit
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan import load_translator
from ccgan.cli import cli_parser
from ccgan.data import normalise_pressure
from ccgan.distill.imitation import window_and_whole_x_err_cm
from ccgan.distill_range import cli as range_cli
from ccgan.distill_range import plan_media
from ccgan.distill_range.imitation import range_data
from ccgan.distill_range.media import medium_arm
from ccgan.distill_range.teacher import teacher_over_media
from ccgan.stage import generator_commands
from studies.checks import parse_checked_args


def teacher_from_parts(parts: list[Path], config, training, arm_s, arm_c) -> dict:
    """The teacher over media (`teacher_over_media`) from `parts` alone; ValueError if any of
    its commands would have to be planned here."""

    def refuse() -> bool:
        raise ValueError(
            f"the parts {[str(p) for p in parts]} do not hold every medium's commands under"
            " these settings (see the lines above): plan them with media_range.sh teacher"
        )

    return teacher_over_media(
        config,
        training,
        arm_s,
        arm_c,
        None,
        should_stop=refuse,
        teacher_from=tuple(part / "teacher.npz" for part in parts),
    )


def main(argv=None) -> None:
    p = cli_parser("studies.range_fit", __doc__)
    p.add_argument("--parts", nargs="+", required=True, type=Path, help="teacher part folders")
    p.add_argument("--translators", nargs="+", required=True, help="conditioned files, a seed each")
    p.add_argument("--n-train-scored", type=int, default=2, help="training programs per medium")
    p.add_argument("--score-substeps", type=int, default=5)
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    if a.n_train_scored < 1:
        p.error("--n-train-scored must be >= 1")
    t0 = time.perf_counter()
    range_config, config = range_cli.preset_configs()  # the range's one-GPU settings
    arm_s, arm_c = (mjx_arm.load(domain=d) for d in ("source", "constrained"))
    training, media_range = plan_media(range_config, arm_c)
    teacher = teacher_from_parts(a.parts, config, training, arm_s, arm_c)
    translators = [load_translator(f, method="distill_range") for f in a.translators]
    data = range_data(teacher, training, media_range, translators[0].bounds, config.window_s)
    medium_train = teacher["medium"][~teacher["is_val"]]
    c_train_bar = teacher["c"][~teacher["is_val"]]
    x_train = teacher["x"][~teacher["is_val"]]
    print(f"teacher read: {len(medium_train)} training, {len(data.medium_val)} held-out programs")

    def commands(samples):  # [S, N, T, 3] bar
        return np.stack(
            [np.asarray(generator_commands(t, t.g_c_params, samples)) for t in translators]
        )

    def mse(student_bar, teacher_normalised):  # [S, N]
        return ((normalise_pressure(student_bar) - teacher_normalised[None]) ** 2).mean((-2, -1))

    g_train, g_val = commands(data.s_train), commands(data.s_val)
    mse_train = mse(g_train, np.asarray(data.c_train))
    mse_val = mse(g_val, normalise_pressure(data.c_val))
    rows = []
    for m, medium in enumerate(training):
        arm = medium_arm(arm_c, medium.drag_ratio, medium.stiffness_scale).planning_copy(
            a.score_substeps
        )
        tr_rows = np.flatnonzero(medium_train == m)[: a.n_train_scored]
        val_rows = np.flatnonzero(data.medium_val == m)

        def score(cmds, x, arm=arm, k=medium.k):  # mean of (window, whole) X_err cm per index
            head, whole = window_and_whole_x_err_cm(arm, cmds, k, x, data.window)
            return 0.5 * (head + whole)

        teacher_train = score(c_train_bar[tr_rows][None], x_train[tr_rows]).mean()
        teacher_val = score(data.c_val[val_rows][None], data.x_val[val_rows]).mean()
        student_train = score(g_train[:, tr_rows], x_train[tr_rows])  # [S]
        student_val = score(g_val[:, val_rows], data.x_val[val_rows])
        rows.append(
            {
                "r": medium.drag_ratio,
                "s": medium.stiffness_scale,
                "k": medium.k,
                "mse_train": float(mse_train[:, medium_train == m].mean()),
                "mse_val": float(mse_val[:, data.medium_val == m].mean()),
                "teacher_train_cm": float(teacher_train),
                "teacher_val_cm": float(teacher_val),
                "student_train_cm": float(student_train.mean()),
                "student_val_cm": float(student_val.mean()),
            }
        )
        print(f"medium {m + 1}/{len(training)} scored ({time.perf_counter() - t0:.0f} s)")
    rows.sort(key=lambda row: (row["k"], row["r"]))
    lines = [
        "",
        f"{len(training)} training media; imitation MSE (normalised commands, the training loss's"
        f" measure; mean of {len(translators)} seeds) and X_err (cm, mean of the first"
        f" {config.window_s:g} s and the whole {config.duration_s:g} s program, MuJoCo C in a"
        f" {a.score_substeps}-step copy of each medium's arm at its k) on {a.n_train_scored}"
        " training and every held-out program of each medium.",
        "",
        "| r | s | k | MSE train | MSE held-out | held-out / train MSE | teacher train cm |"
        " student train cm | student / teacher, train | teacher held-out cm | student held-out"
        " cm | student / teacher, held-out |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['r']:.2f} | {row['s']:.3f} | {row['k']} | {row['mse_train']:.2e} |"
            f" {row['mse_val']:.2e} | {row['mse_val'] / row['mse_train']:.1f}x |"
            f" {row['teacher_train_cm']:.3f} | {row['student_train_cm']:.3f} |"
            f" {row['student_train_cm'] / row['teacher_train_cm']:.2f}x |"
            f" {row['teacher_val_cm']:.3f} | {row['student_val_cm']:.3f} |"
            f" {row['student_val_cm'] / row['teacher_val_cm']:.2f}x |"
        )
    ratio = np.array([[r["student_train_cm"] / r["teacher_train_cm"] for r in rows],
                      [r["student_val_cm"] / r["teacher_val_cm"] for r in rows]])  # fmt: skip
    lines += [
        "",
        f"Student / teacher X_err, median over media: {np.median(ratio[0]):.2f}x on training"
        f" programs, {np.median(ratio[1]):.2f}x on held-out programs; imitation MSE held-out /"
        f" train, median {np.median([r['mse_val'] / r['mse_train'] for r in rows]):.1f}x.",
    ]
    result = {
        "translators": a.translators,
        "parts": [str(x) for x in a.parts],
        "rows": rows,
        "wall_s": time.perf_counter() - t0,
    }
    print("\n".join(lines))
    title = "The conditioned translator against its teacher, per training medium"
    write_results(a.out, run_header("studies.range_fit", argv), result, title, lines)


if __name__ == "__main__":
    main()
