"""Where the distillation's teacher plans faster: MuJoCo C on the host's cores or MJX on the
accelerator, on one host.

The teacher is receding-horizon tracking with a one-step horizon (`tracking.mpc.track` in
MuJoCo C, `tracking.mpc_mjx.track` in MJX). For held-out shape-like programs of `--duration`
seconds (split "teacher_bench", full scale), each backend plans N programs and the table gives
its wall time and programs per second; the C tracker's cost grows with N, MJX's with the
latency of its sequential rollouts. Both backends' commands for the first `--c-programs`
programs are then scored in MuJoCo C (X_err, cm), beside stretch only, so that the faster one
is also shown to track as well.

    python -m bench.teacher --c-programs 16 --mjx-programs 256 2048 --out bench/results/h200/teacher
"""

from __future__ import annotations

import time

import mjx_arm  # (before jax: sets the XLA CPU flag)
from bench import parse_checked, run_header, write_results
from ccgan.cli import cli_parser
from mjx_arm.machine import usable_cores
from mjx_arm.programs import shape_like_programs
from tracking import held, metrics, mpc, mpc_mjx


def main(argv=None) -> None:
    p = cli_parser("bench.teacher", __doc__)
    p.add_argument("--model", default="models/softarm.xml", help="the arm's MJCF")
    p.add_argument("--k", type=int, default=15, help="control periods each command is held")
    p.add_argument("--duration", type=float, default=60.0, help="seconds per program")
    p.add_argument("--iterations", type=int, default=1, help="Gauss-Newton iterations per step")
    p.add_argument("--c-programs", type=int, default=4, help="programs the C tracker plans")
    p.add_argument(
        "--mjx-programs", type=int, nargs="+", default=[4], help="batch sizes the MJX tracker plans"
    )
    p.add_argument(
        "--matmul-precisions",
        nargs="+",
        default=["default"],
        choices=["default", "highest"],
        help="matrix-product precision of the MJX tracker (mjx_arm.arm.MJX_MATMUL_PRECISION,"
        " the package's 'highest' otherwise), one row set each: 'default' is JAX's, which lets"
        " XLA use TensorFloat32 for float32 products on NVIDIA GPUs since Ampere, 'highest'"
        " keeps them float32 (no difference on the CPU)",
    )
    p.add_argument(
        "--substeps",
        type=int,
        nargs="+",
        default=[0],
        help="physics steps per control period of the arm the MJX tracker plans in, one row set"
        " each (0: the arm's own; others: `Arm.planning_copy`); every row is scored in the arm",
    )
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked(p, argv)
    if min(a.substeps) < 0:
        p.error("--substeps must be >= 0")
    if a.c_programs < 1 or min(a.mjx_programs) < a.c_programs:
        p.error("--c-programs must be >= 1 and at most every --mjx-programs")
    arm_s = mjx_arm.load(a.model, "source")
    arm_c = mjx_arm.load(a.model, "constrained")
    n_max = max(a.mjx_programs)
    programs = shape_like_programs(
        n_max, a.duration, seed=0, split="teacher_bench", full_scale=True
    )
    targets = arm_s.rollout(programs, backend="c")
    cfg = mpc.MpcConfig(horizon_steps=1, iterations=a.iterations)
    rows, scored = [], {}
    n_c = a.c_programs
    t0 = time.perf_counter()
    scored["C"], _ = mpc.track(arm_c, targets[:n_c], a.k, programs[:n_c], cfg, progress=True)
    wall = time.perf_counter() - t0
    rows.append({"backend": "C", "programs": n_c, "wall_s": wall, "first_chunk_s": None})
    for precision, substeps in [(p_, s_) for p_ in a.matmul_precisions for s_ in a.substeps]:
        name = "MJX" if precision == "default" else f"MJX, matmul precision {precision}"
        name += f", planned in {substeps} steps per period" if substeps else ""
        plan_arm = arm_c.planning_copy(substeps)
        for n in sorted(a.mjx_programs):
            package = mjx_arm.arm.MJX_MATMUL_PRECISION
            mjx_arm.arm.MJX_MATMUL_PRECISION = None if precision == "default" else precision
            try:
                commands, info = mpc_mjx.track(
                    plan_arm, targets[:n], a.k, programs[:n], cfg, progress=True
                )
            finally:
                mjx_arm.arm.MJX_MATMUL_PRECISION = package
            rows.append(
                {
                    "backend": name,
                    "programs": n,
                    "wall_s": info["wall_s"],
                    "first_chunk_s": info["first_chunk_s"],
                    "diverged": int((~info["healthy"]).sum()),
                }
            )
            scored.setdefault(name, commands[:n_c])
    for row in rows:
        row["programs_per_s"] = row["programs"] / row["wall_s"]
    scored["stretch"] = held.stretch(programs[:n_c], a.k)
    x_err = {
        name: float(
            metrics.position_error_cm(held.run_dc(arm_c, c, a.k, "c"), targets[:n_c]).mean()
        )
        for name, c in scored.items()
    }
    header = run_header("bench.teacher", argv)
    c_rate = rows[0]["programs_per_s"]
    result = {
        "model": a.model,
        "k": a.k,
        "duration_s": a.duration,
        "iterations": a.iterations,
        "c_threads": usable_cores(),
        "rows": rows,
        "x_err_cm": x_err,
    }
    body = [
        f"- one-step receding-horizon tracking, {a.iterations} Gauss-Newton iteration(s) per"
        f" step, k = {a.k}, shape-like programs of {a.duration:g} s (split teacher_bench, full"
        f" scale); MuJoCo C on {usable_cores()} threads",
        "",
        "| backend | programs | wall s | of which compile + first chunk s | programs / s | x C |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        first = "" if row["first_chunk_s"] is None else f"{row['first_chunk_s']:.1f}"
        body.append(
            f"| {row['backend']} | {row['programs']} | {row['wall_s']:.1f} | {first} |"
            f" {row['programs_per_s']:.3f} | {row['programs_per_s'] / c_rate:.2f} |"
        )
    body += [
        "",
        f"X_err (cm) in MuJoCo C over the first {n_c} programs, whole length:",
        "",
        "| commands | X_err cm |",
        "|---|---|",
        *[f"| {name} | {value:.4f} |" for name, value in x_err.items()],
    ]
    md = write_results(a.out, header, result, "The teacher's cost: MuJoCo C and MJX", body)
    print(md.read_text())


if __name__ == "__main__":
    main()
