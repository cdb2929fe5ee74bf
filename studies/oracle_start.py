"""Where the oracle starts and how fast it steps: stretch or mpc start, Adam step sizes.

For each (start, learning rate), runs `tracking.oracle.oracle_commands` on the first `--horizon`
seconds of the chosen shapes (held commands, k = 10) and reports the loss of every iterate,
the best loss and the X_err (cm) of the returned commands in MuJoCo C. The mpc start is
`tracking.mpc.track`'s commands (the oracle's default start).

    python -m studies.oracle_start --shapes circle --steps 10 \\
        --runs stretch:0.3 mpc:0.3 mpc:0.03 --out studies/results/cpu/oracle_start
"""

from __future__ import annotations

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan.cli import cli_parser
from mjx_arm.programs import CONTROL_HZ, SHAPES
from studies.checks import parse_checked_args
from tracking import held, metrics, mpc
from tracking.oracle import OracleConfig, oracle_commands


def main(argv=None) -> None:
    p = cli_parser("studies.oracle_start", __doc__)
    p.add_argument("--shapes", nargs="+", default=["circle"], choices=list(SHAPES))
    p.add_argument("--horizon", type=float, default=2.0, help="seconds optimised")
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--runs", nargs="+", default=["mpc:0.3", "mpc:0.03"], help="start:lr pairs")
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    k = 10
    arm_s, arm_c = mjx_arm.load(domain="source"), mjx_arm.load(domain="constrained")
    n = int(round(a.horizon * CONTROL_HZ))
    programs = np.stack([SHAPES[s](60.0)[:n] for s in a.shapes])
    targets = arm_s.rollout(programs, backend="c")
    starts = {"stretch": held.stretch(programs, k)}
    if any(run.startswith("mpc:") for run in a.runs):
        starts["mpc"], _ = mpc.track(arm_c, targets, k, programs)
    rows = []
    for run in a.runs:
        start, lr = run.split(":")
        cfg = OracleConfig(steps=a.steps, learning_rate=float(lr), init=start)
        cmds, info = oracle_commands(arm_c, targets, starts[start], k, cfg, held=True)
        x_start = metrics.position_error_cm(held.run_dc(arm_c, starts[start], k, "c"), targets)
        x_best = metrics.position_error_cm(held.run_dc(arm_c, cmds, k, "c"), targets)
        rows.append(
            {
                "start": start,
                "learning_rate": float(lr),
                "loss_history": np.asarray(info["loss_history"]).tolist(),
                "best_loss": info["best_loss"],
                "x_err_cm_start": x_start.mean(-1).tolist(),
                "x_err_cm_best": x_best.mean(-1).tolist(),
                "wall_s": info["wall_s"],
            }
        )
        print(f"{run}: best loss {np.round(info['best_loss'], 5)}; {info['wall_s']:.0f} s")
    header = run_header("studies.oracle_start", argv)
    result = {"shapes": a.shapes, "horizon_s": a.horizon, "steps": a.steps, "rows": rows}
    lines = [
        "",
        "Loss (cm^2) of the first and last iterates and the best; X_err (cm) of the start and of"
        " the returned (best) commands in MuJoCo C, mean over the shapes.",
        "",
        "| start | lr | loss first | loss last | loss best | X_err start | X_err best | wall s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        h = np.asarray(r["loss_history"])
        lines.append(
            f"| {r['start']} | {r['learning_rate']:g} | {h[0].mean():.5f} | {h[-1].mean():.5f} |"
            f" {np.mean(r['best_loss']):.5f} | {np.mean(r['x_err_cm_start']):.4f} |"
            f" {np.mean(r['x_err_cm_best']):.4f} | {r['wall_s']:.0f} |"
        )
    write_results(
        a.out,
        header,
        result,
        f"Oracle start and step size: {', '.join(a.shapes)}, first {a.horizon:g} s",
        lines,
    )


if __name__ == "__main__":
    main()
