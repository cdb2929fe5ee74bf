"""Why the receding-horizon tracker saturates its commands on an arm, and whether its settings or
the stretch factor k change that, on held-out programs (never a test shape).

For each (k, horizon_steps, iterations) it tracks shape-like programs (`shape_like_programs`,
full scale, their own split "mpc_study") in the D_c simulator with `tracking.mpc.track`, and
reports the X_err (cm, mean over programs and time) of its commands and of the stretch program
in MuJoCo C, the share of its commands at a valve limit, and its wall time. If the share falls
as k grows, the D_c arm is too slow for the targets (dynamics); if it stays, the tracker pushes
the commands there to reach poses the valve range cannot hold (statics).

    python -m studies.mpc_saturation --runs 7:1:2 7:3:2 14:1:2 \\
        --out studies/results/cpu/mpc_saturation
"""

from __future__ import annotations

import time

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan.cli import cli_parser
from mjx_arm.programs import shape_like_programs
from studies.checks import parse_checked_args
from tracking import held, metrics, mpc


def saturated_share(commands: np.ndarray, lo: float, hi: float, tol: float = 1e-6) -> float:
    """Share of commands [..., 3] (bar) at a valve limit (within tol bar)."""
    return float(((commands <= lo + tol) | (commands >= hi - tol)).mean())


def main(argv=None) -> None:
    p = cli_parser("studies.mpc_saturation", __doc__)
    p.add_argument("--model", default="models/softarm.xml", help="the arm's MJCF")
    p.add_argument("--n", type=int, default=4, help="held-out programs")
    p.add_argument("--duration", type=float, default=4.0, help="seconds per program")
    p.add_argument(
        "--runs", nargs="+", default=["7:1:2"], help="k:horizon_steps:iterations triples"
    )
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    arm_s, arm_c = mjx_arm.load(a.model, "source"), mjx_arm.load(a.model, "constrained")
    lo, hi = arm_c.valve.p_min_bar, arm_c.valve.p_max_bar
    programs = shape_like_programs(a.n, a.duration, seed=0, split="mpc_study", full_scale=True)
    targets = arm_s.rollout(programs.astype(np.float64), backend="c")
    rows = []
    for run in a.runs:
        k, horizon, iterations = (int(v) for v in run.split(":"))
        cfg = mpc.MpcConfig(horizon_steps=horizon, iterations=iterations)
        t0 = time.perf_counter()
        commands, _ = mpc.track(arm_c, targets, k, programs, cfg)
        wall_s = time.perf_counter() - t0
        stretch = held.stretch(programs, k)
        x_mpc = metrics.position_error_cm(held.run_dc(arm_c, commands, k, "c"), targets)
        x_stretch = metrics.position_error_cm(held.run_dc(arm_c, stretch, k, "c"), targets)
        rows.append(
            {
                "k": k,
                "horizon_steps": horizon,
                "iterations": iterations,
                "x_err_cm_mpc": x_mpc.mean(-1).tolist(),
                "x_err_cm_stretch": x_stretch.mean(-1).tolist(),
                "saturated_mpc": saturated_share(commands, lo, hi),
                "saturated_stretch": saturated_share(stretch, lo, hi),
                "wall_s": wall_s,
            }
        )
        r = rows[-1]
        print(
            f"{run}: X_err mpc {x_mpc.mean():.3f} cm, stretch {x_stretch.mean():.3f} cm;"
            f" at a limit {r['saturated_mpc']:.0%} (stretch {r['saturated_stretch']:.0%});"
            f" {wall_s:.0f} s"
        )
    header = run_header("studies.mpc_saturation", argv)
    rest = arm_s.rest_pose()
    excursion = [metrics.tip_excursion_cm(target, rest) for target in targets]
    result = {
        "model": a.model,
        "n": a.n,
        "duration_s": a.duration,
        "tip_excursion_cm": excursion,
        "rows": rows,
    }
    lines = [
        f"- {a.n} held-out shape-like programs of {a.duration:g} s (split mpc_study, full"
        f" scale); tip excursion of the targets {np.mean(excursion):.2f} cm (mean)",
        "",
        "X_err (cm), mean over programs and time, in MuJoCo C; 'at a limit': share of commands"
        f" at {lo:g} or {hi:g} bar.",
        "",
        "| k | horizon | iterations | X_err mpc | X_err stretch | mpc / stretch | at a limit,"
        " mpc | at a limit, stretch | wall s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        xm, xs = np.mean(r["x_err_cm_mpc"]), np.mean(r["x_err_cm_stretch"])
        lines.append(
            f"| {r['k']} | {r['horizon_steps']} | {r['iterations']} | {xm:.3f} | {xs:.3f} |"
            f" {xm / xs:.2f} | {r['saturated_mpc']:.0%} | {r['saturated_stretch']:.0%} |"
            f" {r['wall_s']:.0f} |"
        )
    write_results(
        a.out,
        header,
        result,
        f"Receding-horizon tracking on {a.model}: saturation against k and settings",
        lines,
    )


if __name__ == "__main__":
    main()
