"""Cost of the evaluation oracle: Adam steps through the MJX rollout of the D_c arm.

For each horizon, number of programs optimised together (`tracking.oracle.oracle_commands`
vmaps them) and planning copy (`--substeps`: physics steps per control period of the arm Adam
differentiates through, 0 for the arm's own), times the first call (compile + one step) and the
mean of the next steps, with the stretch program as start. The programs are held-out
shape-like ones (split "oracle_bench"; the committed `bench/results/h200/oracle.md` was timed on
the first test shapes, before X_err was reported). The first step includes compiling the
gradient. X_err is that of the best commands in the arm itself (MuJoCo C), over the horizon.

    python -m bench.oracle --horizons 1 2 --programs 1 5 --steps 4 --out bench/results/h200
    python -m bench.oracle --horizons 2 --programs 5 --k 15 --substeps 0 5 --steps 6 --out OUT

Writes oracle{tag}.md and .json to --out.
"""

from __future__ import annotations

import json
from pathlib import Path

import jax
import numpy as np

import mjx_arm  # (sets the XLA CPU flag before the first JAX computation)
from bench import run_header
from ccgan.cli import cli_parser
from mjx_arm.programs import CONTROL_HZ, shape_like_programs
from tracking import held, metrics
from tracking.oracle import OracleConfig, oracle_commands


def time_oracle(
    arm_s, arm_c, horizon_s: float, n_programs: int, k: int, steps: int, substeps: int = 0
) -> dict:
    n = int(round(horizon_s * CONTROL_HZ))
    programs = shape_like_programs(n_programs, 60.0, split="oracle_bench")[:, :n]
    targets = arm_s.rollout(programs, backend="c")
    inits = held.stretch(programs, k)
    cfg = OracleConfig(steps=steps, substeps=substeps)
    commands, info = oracle_commands(arm_c, targets, inits, k, cfg, held=True)
    first_s, rest = info["step_wall_s"][0], info["step_wall_s"][1:]
    step_s = float(np.mean(rest))
    history = np.asarray(info["loss_history"])
    x_err = metrics.position_error_cm(held.run_dc(arm_c, commands, k, "c"), targets).mean()
    return {
        "horizon_s": horizon_s,
        "programs": n_programs,
        "k": k,
        "substeps": substeps,
        "x_err_cm": float(x_err),
        "physics_steps": n * k * (substeps or arm_c.n_substeps),
        "first_step_s": first_s,
        "step_s": step_s,
        "loss_first": history[0].tolist(),
        "loss_last": history[-1].tolist(),
    }


def main(argv=None) -> None:
    parser = cli_parser("bench.oracle", __doc__)
    parser.add_argument("--horizons", type=float, nargs="+", default=[1.0])
    parser.add_argument("--programs", type=int, nargs="+", default=[1])
    parser.add_argument("--k", type=int, default=10)
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--substeps", type=int, nargs="+", default=[0])
    parser.add_argument(
        "--out", default="runs/bench", help="output folder (committed results: bench/results)"
    )
    parser.add_argument("--tag", default="")
    args = parser.parse_args(argv)
    if args.steps < 2:
        parser.error("--steps must be at least 2")
    arm_s, arm_c = mjx_arm.load(domain="source"), mjx_arm.load(domain="constrained")
    report = run_header("bench.oracle", argv) | {"rows": []}
    command = report["command"]
    lines = [
        f"# Oracle cost: Adam steps through the MJX rollout ({report['device']}, {report['cpu']})",
        "",
        f"Command: `{command}`; jax {jax.__version__}; D_c arm, {arm_c.n_substeps} physics steps"
        " per control period (a planning copy's where the row says fewer), k control periods per"
        " source step.",
        "",
        "| horizon (s) | programs | steps per period | physics steps each"
        " | first step incl. compile (s) | s / Adam step | X_err in the arm, cm |",
        "|---|---|---|---|---|---|---|",
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    grid = [(h, n, s) for h in args.horizons for n in args.programs for s in args.substeps]
    for horizon, n, substeps in grid:
        row = time_oracle(arm_s, arm_c, horizon, n, args.k, args.steps, substeps)
        report["rows"].append(row)
        lines.append(
            f"| {horizon:g} | {n} | {substeps or arm_c.n_substeps} | {row['physics_steps']} |"
            f" {row['first_step_s']:.1f} | {row['step_s']:.2f} | {row['x_err_cm']:.4f} |"
        )
        print(lines[-1], flush=True)
        (out / f"oracle{args.tag}.json").write_text(json.dumps(report, indent=2))
        (out / f"oracle{args.tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
