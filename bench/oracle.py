"""Cost of the evaluation oracle: Adam steps through the MJX rollout of the D_c arm.

For each horizon and number of programs optimised together (`tracking.oracle.oracle_commands`
vmaps them), times the first call (compile + one step) and the mean of the next steps, with
the stretch program of the first shapes as start (k = 10, the evaluation's stretch k). The
first step includes compiling the gradient.

    python -m bench.oracle --horizons 1 2 --programs 1 5 --steps 4 --out bench/results/h200

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
from mjx_arm.programs import CONTROL_HZ, SHAPES
from tracking import held
from tracking.oracle import OracleConfig, oracle_commands


def time_oracle(arm_s, arm_c, horizon_s: float, n_programs: int, k: int, steps: int) -> dict:
    names = list(SHAPES)[:n_programs]
    n = int(round(horizon_s * CONTROL_HZ))
    programs = [SHAPES[s](60.0)[:n] for s in names]
    targets = np.stack([arm_s.rollout(p, backend="c") for p in programs])
    inits = np.stack([held.stretch(p, k) for p in programs])
    cfg = OracleConfig(steps=steps)
    _, info = oracle_commands(arm_c, targets, inits, k, cfg)
    first_s, rest = info["step_wall_s"][0], info["step_wall_s"][1:]
    step_s = float(np.mean(rest))
    history = np.asarray(info["loss_history"])
    return {
        "horizon_s": horizon_s,
        "programs": n_programs,
        "k": k,
        "physics_steps": n * k * arm_c.n_substeps,
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
        f"Command: `{command}`; jax {jax.__version__}; D_c arm, {arm_c.n_substeps} physics steps "
        "per control period, k control periods per source step.",
        "",
        "| horizon (s) | programs | physics steps each | first step incl. compile (s) "
        "| s / Adam step |",
        "|---|---|---|---|---|",
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for horizon in args.horizons:
        for n in args.programs:
            row = time_oracle(arm_s, arm_c, horizon, n, args.k, args.steps)
            report["rows"].append(row)
            lines.append(
                f"| {horizon:g} | {n} | {row['physics_steps']} | {row['first_step_s']:.1f} "
                f"| {row['step_s']:.2f} |"
            )
            print(lines[-1], flush=True)
            (out / f"oracle{args.tag}.json").write_text(json.dumps(report, indent=2))
            (out / f"oracle{args.tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
