"""How far unrolling the rod's physics-step loop speeds its rollouts, and that it changes nothing.

The reference rod takes 500 position-Verlet steps of 2e-4 s per 0.1 s control period, a
`jax.lax.scan` over a handful of small array operations on 20 elements. At the batch sizes that
scoring needs (tens of trajectories) a GPU spends most of each step in the loop's own overhead,
so the rollout is latency-bound: a 60 s shape held k = 20 periods is 12,000 periods, in sequence.
`unroll` (physics steps per loop iteration, `mjx_arm.rod_dynamics.rollout_single`) trades compile
time for fewer iterations. For each unroll and batch size this times `RodArm.rollout` (the best
of `--repeats` calls after a first, compiling one) and checks the poses against unroll 1.

    python -m bench.rod_unroll --out bench/results/h200/rod_unroll

Writes rod_unroll.md and rod_unroll.json, rewritten after every measurement.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

import mjx_arm  # (before jax: sets the XLA CPU flag)
from bench import parse_checked, run_header, write_results
from mjx_arm.programs import bench_programs


def measure(domain: str, dtype: str, unroll: int, commands: np.ndarray, repeats: int) -> dict:
    """First-call and best timed wall time (s) of one rod rollout of `commands` [B, T, 3]."""
    rod = dataclasses.replace(mjx_arm.load_rod(domain, dtype=dtype), unroll=unroll)
    start = time.perf_counter()
    poses = rod.rollout(commands)
    first = time.perf_counter() - start
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        rod.rollout(commands)
        walls.append(time.perf_counter() - start)
    return {"first_s": first, "best_s": min(walls), "poses": poses}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.rod_unroll", description=__doc__)
    parser.add_argument("--out", required=True, help="prefix of rod_unroll.{md,json} (a folder)")
    parser.add_argument("--batch", type=int, nargs="+", default=[1, 64, 512])
    parser.add_argument("--unroll", type=int, nargs="+", default=[1, 5, 10, 25, 50, 100])
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated s per program")
    parser.add_argument("--dtype", default="float64", choices=["float64", "float32"])
    parser.add_argument("--domain", default="constrained")
    parser.add_argument("--repeats", type=int, default=2)
    args = parse_checked(parser, argv, prefix=False)
    out = f"{args.out}/rod_unroll"
    header = run_header("bench.rod_unroll", argv)
    length = mjx_arm.load_rod(args.domain).length_m
    rows = []
    for batch in args.batch:
        commands = bench_programs(batch, round(args.seconds * 10), seed=0)
        reference = None
        for unroll in args.unroll:
            m = measure(args.domain, args.dtype, unroll, commands, args.repeats)
            if reference is None:
                reference = m["poses"]
            diff = float(np.abs(m["poses"][..., :3] - reference[..., :3]).max() / length)
            row = {
                "batch": batch,
                "unroll": unroll,
                "first_s": m["first_s"],
                "best_s": m["best_s"],
                "sim_s_per_s": batch * args.seconds / m["best_s"],
                "largest_tip_difference_of_L": diff,
            }
            rows.append(row)
            print(row, flush=True)
            lines = [
                "",
                f"{args.dtype}, domain {args.domain}, programs of {args.seconds:g} s"
                " (`bench_programs`); sim s per wall s from the best timed call; first call"
                " (compiles) in s; tip difference against unroll 1 at the same batch, of L.",
                "",
                "| batch | unroll | sim s / s | first call s | x unroll 1 | tip difference of L |",
                "|---|---|---|---|---|---|",
            ]
            for r in rows:
                base = next(b for b in rows if b["batch"] == r["batch"])
                lines.append(
                    f"| {r['batch']} | {r['unroll']} | {r['sim_s_per_s']:.3g} | {r['first_s']:.1f}"
                    f" | {r['sim_s_per_s'] / base['sim_s_per_s']:.2f}"
                    f" | {r['largest_tip_difference_of_L']:.1e} |"
                )
            write_results(out, header, {"rows": rows}, "Unrolling the rod's step loop", lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
