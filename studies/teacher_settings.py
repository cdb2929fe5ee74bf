"""Which horizon and how many Gauss-Newton iterations the distillation's teacher needs: the
receding-horizon tracker (`tracking.mpc.track`, MuJoCo C) at several settings on held-out
shape-like programs (split "teacher_settings", full scale; never a test shape), its X_err in
the D_c simulator beside stretch only, and its wall time.

The teacher's cost grows with horizon^2 x iterations, and only the one-step horizon runs in MJX
(`tracking.mpc_mjx`), where thousands of programs plan at once. This study says what the cheap
setting gives up.

    python -m studies.teacher_settings --n 4 --duration 20 \\
        --out studies/results/cpu/issue30/teacher_settings
"""

from __future__ import annotations

import time

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from bench import run_header, write_results
from ccgan.cli import cli_parser
from mjx_arm.programs import shape_like_programs
from studies.checks import parse_checked_args
from tracking import held, metrics, mpc


def parse_setting(text: str) -> tuple[int, int]:
    """'H:I' -> (horizon_steps, iterations), both >= 1."""
    try:
        horizon, iterations = (int(part) for part in text.split(":"))
    except ValueError:
        raise ValueError(f"a setting is HORIZON:ITERATIONS, got {text!r}") from None
    if horizon < 1 or iterations < 1:
        raise ValueError(f"horizon and iterations must be >= 1, got {text!r}")
    return horizon, iterations


def main(argv=None) -> None:
    p = cli_parser("studies.teacher_settings", __doc__)
    p.add_argument("--model", default="models/softarm.xml", help="the arm's MJCF")
    p.add_argument("--k", type=int, default=15, help="control periods each command is held")
    p.add_argument("--n", type=int, default=4, help="held-out programs")
    p.add_argument("--duration", type=float, default=20.0, help="seconds per program")
    p.add_argument(
        "--settings",
        nargs="+",
        default=["1:1", "1:2", "2:1", "3:1"],
        help="HORIZON:ITERATIONS pairs to compare",
    )
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    try:
        settings = [parse_setting(text) for text in a.settings]
    except ValueError as err:
        p.error(str(err))
    arm_s = mjx_arm.load(a.model, "source")
    arm_c = mjx_arm.load(a.model, "constrained")
    programs = shape_like_programs(
        a.n, a.duration, seed=0, split="teacher_settings", full_scale=True
    )
    targets = arm_s.rollout(programs, backend="c")

    def x_err(commands) -> float:
        poses = held.run_dc(arm_c, commands, a.k, "c")
        return float(metrics.position_error_cm(poses, targets).mean())

    stretch_cm = x_err(held.stretch(programs, a.k))
    rows = []
    for horizon, iterations in settings:
        cfg = mpc.MpcConfig(horizon_steps=horizon, iterations=iterations)
        t0 = time.perf_counter()
        commands, _ = mpc.track(arm_c, targets, a.k, programs, cfg, progress=True)
        wall_s = time.perf_counter() - t0
        rows.append(
            {
                "horizon_steps": horizon,
                "iterations": iterations,
                "x_err_cm": x_err(commands),
                "wall_s": wall_s,
            }
        )
    cheapest = rows[0]
    body = [
        f"- {a.n} held-out shape-like programs of {a.duration:g} s (split teacher_settings, full"
        f" scale), k = {a.k}; X_err in the D_c simulator (MuJoCo C), mean over programs and"
        f" time; stretch only: {stretch_cm:.3f} cm",
        "",
        "| horizon | iterations | X_err cm | / stretch | wall s | wall / first row |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        body.append(
            f"| {row['horizon_steps']} | {row['iterations']} | {row['x_err_cm']:.3f} |"
            f" {row['x_err_cm'] / stretch_cm:.2f} | {row['wall_s']:.1f} |"
            f" {row['wall_s'] / cheapest['wall_s']:.1f} |"
        )
    result = {
        "model": a.model,
        "k": a.k,
        "n": a.n,
        "duration_s": a.duration,
        "stretch_x_err_cm": stretch_cm,
        "rows": rows,
    }
    header = run_header("studies.teacher_settings", argv)
    md = write_results(a.out, header, result, "The teacher's horizon and iterations", body)
    print(md.read_text())


if __name__ == "__main__":
    main()
