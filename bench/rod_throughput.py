"""The reference rod's rollout throughput beside the chain's, and what float32 costs the rod.

One run, one machine: for each batch size, the same pressure programs (`bench_programs`: targets
held 0.5-2 s) run through

  * the rod arm (`mjx_arm.load_rod`: 20 Cosserat elements, 500 position-Verlet steps of 2e-4 s
    per 0.1 s period, jitted and vmapped) in float64 and in float32;
  * the chain (`mjx_arm.load`, the committed 10-segment model, 25 steps of 4 ms per period) on
    MJX (float32, jitted and vmapped) and on MuJoCo C (`mujoco.rollout`, one thread per core);

each timed through its public `rollout` (input checks and transfers included, as a user calls
it), after a first call that compiles (its time is reported apart). Throughput is simulated
seconds per wall second: batch x program length / wall time.

Accuracy of float32: the rod arm in float32 against float64 on the fidelity report's held-out
programs (`mjx_arm.fidelity`: seeds 0-2, 60 s of targets held 0.5-3 s) in each domain: the
largest and RMS tip difference as a fraction of the arm's length L, and the largest d3 angle.

    python -m bench.rod_throughput --out bench/results/h100          # GPU defaults
    python -m bench.rod_throughput --out bench/results/cpu --batch 1 8 --seconds 2 \\
        --accuracy-seconds 20                                        # a few minutes on a CPU

Writes rod_throughput.md and rod_throughput.json to --out, rewritten after every measurement so
a run stopped part-way keeps what it measured. One progress line per measurement.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from importlib import metadata
from pathlib import Path

import jax
import mujoco
import numpy as np

import mjx_arm
from bench import parse_checked, run_header, write_results
from mjx_arm import constants, fidelity
from mjx_arm.machine import usable_cores
from mjx_arm.programs import bench_programs, held_program
from mjx_arm.rod_arm import DTYPES

#: Backends timed per batch size, in table order.
BACKENDS = ("rod float64", "rod float32", "chain MJX", "chain MuJoCo C")


def timed_rollout(rollout, commands: np.ndarray, jitted: bool, repeats: int) -> dict:
    """A first call, then the best of `repeats` timed calls of `rollout` (the best: on a shared
    machine other work only ever slows a call down). A jitted backend's first call runs the same
    batch (it compiles for that shape; its time is reported); MuJoCo C's only warms its thread
    pool on one period of one program, so a large batch is not run once more than timed."""
    start = time.perf_counter()
    rollout(commands if jitted else commands[:1, :1])
    first = time.perf_counter() - start
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        poses = rollout(commands)
        walls.append(time.perf_counter() - start)
    wall = min(walls)
    batch, periods = commands.shape[:2]
    return {
        "first_call_s": first if jitted else None,
        "wall_s": wall,
        "wall_s_each": walls,
        "sim_s_per_wall_s": batch * periods / constants.CONTROL_HZ / wall,
        "finite": bool(np.isfinite(poses).all()),
    }


def float32_accuracy(domain: str, seconds: float, seeds: tuple[int, ...]) -> dict:
    """The rod arm's float32 poses against its float64 ones on held-out programs."""
    programs = np.stack([held_program(s, seconds, fidelity.BABBLE_HOLD_PERIODS) for s in seeds])
    rod64 = mjx_arm.load_rod(domain)
    poses64 = rod64.rollout(programs)
    poses32 = mjx_arm.load_rod(domain, dtype="float32").rollout(programs)
    tip = np.linalg.norm(poses32[..., :3] - poses64[..., :3], axis=-1)
    angle = fidelity.angle_between(poses32[..., 3:], poses64[..., 3:])
    length = rod64.length_m
    excursion = np.linalg.norm(poses64[..., :3] - rod64.rest_pose()[:3], axis=-1)
    return {
        "domain": domain,
        "programs": len(seeds),
        "seconds": seconds,
        "max_tip_fraction_of_L": float(tip.max() / length),
        "rms_tip_fraction_of_L": float(np.sqrt(np.mean(tip**2)) / length),
        "max_d3_angle_rad": float(angle.max()),
        "rod_rms_tip_excursion_fraction_of_L": float(np.sqrt(np.mean(excursion**2)) / length),
    }


def machine() -> dict:
    """The accelerator, the cores MuJoCo C uses and the package versions of this run."""
    device = jax.devices()[0]
    return {
        "accelerator": f"{len(jax.devices())} x {device.device_kind}",
        "cpu_cores_used": usable_cores(),
        "cpu_count": os.cpu_count(),
        "mujoco": mujoco.__version__,
        "mujoco_mjx": metadata.version("mujoco-mjx"),
        # A persistent compilation cache turns the jitted backends' first calls into reads.
        "compilation_cache": mjx_arm.COMPILATION_CACHE_DIR,
    }


def _cell(rows: dict, name: str) -> str:
    """Throughput (first call s) of one backend's row, or "-" if it did not run."""
    r = rows.get(name)
    if r is None:
        return "-"
    first = "" if r["first_call_s"] is None else f" ({r['first_call_s']:.3g})"
    return f"{r['sim_s_per_wall_s']:.3g}{first}"


def _ratio(rows: dict, a: str, b: str) -> str:
    """Throughput of backend a over backend b, or "-"."""
    if a not in rows or b not in rows:
        return "-"
    return f"{rows[a]['sim_s_per_wall_s'] / rows[b]['sim_s_per_wall_s']:.2f}"


def fmt_s(seconds: float | None) -> str:
    return "-" if seconds is None else f"{seconds:.3g} s"


def markdown(result: dict) -> list[str]:
    """The body of rod_throughput.md: throughput table, then float32's accuracy."""
    p = result["protocol"]
    m = result["machine"]
    lines = [
        f"- accelerator: {m['accelerator']}; MuJoCo C on {m['cpu_cores_used']} of"
        f" {m['cpu_count']} cores; mujoco {m['mujoco']}, mujoco-mjx {m['mujoco_mjx']};"
        f" JAX compilation cache {m.get('compilation_cache') or 'off'}",
        "",
        f"Programs of {p['seconds']:g} s at 10 Hz (`bench_programs`), domain {p['domain']}."
        f" Simulated s per wall s (batch x program length / wall time of the best of"
        f" {p.get('repeats', 1)} timed calls); in"
        " brackets the first call's time, which compiles the jitted backends (s); MuJoCo C runs"
        f" batches up to {p.get('c_max_batch', '-')}. Rod: 20"
        " elements, 500 steps of 2e-4 s per period; chain: 10 segments, 25 steps of 4 ms.",
        "",
        "| batch | "
        + " | ".join(BACKENDS)
        + " | rod float32 / float64 | chain MJX / rod float64 |",
        "|---|" + "---|" * (len(BACKENDS) + 2),
    ]
    for batch in p["batches"]:
        rows = {r["backend"]: r for r in result["rows"] if r["batch"] == batch}
        if not rows:
            continue

        lines.append(
            f"| {batch} | "
            + " | ".join(_cell(rows, name) for name in BACKENDS)
            + f" | {_ratio(rows, 'rod float32', 'rod float64')}"
            + f" | {_ratio(rows, 'chain MJX', 'rod float64')} |"
        )
    if result["float32_accuracy"]:
        lines += [
            "",
            "## float32 against float64 (the rod arm)",
            "",
            "Held-out programs of the fidelity report (seeds"
            f" {', '.join(map(str, p['accuracy_seeds']))}, targets held 0.5-3 s), both dtypes"
            " from the same float64 rest state.",
            "",
            "| domain | programs x s | largest tip difference (of L) | RMS (of L) | largest d3"
            " angle (rad) | rod RMS tip excursion (of L) |",
            "|---|---|---|---|---|---|",
        ]
        for a in result["float32_accuracy"]:
            lines.append(
                f"| {a['domain']} | {a['programs']} x {a['seconds']:g} |"
                f" {a['max_tip_fraction_of_L']:.2e} | {a['rms_tip_fraction_of_L']:.2e} |"
                f" {a['max_d3_angle_rad']:.2e} | {a['rod_rms_tip_excursion_fraction_of_L']:.3f} |"
            )
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.rod_throughput",
        description=__doc__.splitlines()[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--out", type=Path, required=True, help="folder for the results")
    parser.add_argument("--batch", type=int, nargs="+", default=[1, 64, 1024, 8192])
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated s per program")
    parser.add_argument("--domain", default="source", choices=sorted(mjx_arm.DOMAINS))
    parser.add_argument("--dtypes", nargs="+", default=list(DTYPES), choices=DTYPES)
    parser.add_argument("--repeats", type=int, default=3, help="timed calls; the best counts")
    parser.add_argument("--no-chain", action="store_true", help="time the rod only")
    parser.add_argument(
        "--c-max-batch",
        type=int,
        default=1024,
        help="largest batch MuJoCo C runs (its throughput is flat once every core is busy)",
    )
    parser.add_argument(
        "--accuracy-seconds", type=float, default=fidelity.BABBLE_SECONDS, help="0 skips it"
    )
    parser.add_argument("--accuracy-domains", nargs="+", default=list(fidelity.DOMAINS))
    args = parse_checked(parser, argv, prefix=False)
    if (
        min(args.batch + [args.c_max_batch, args.repeats]) < 1
        or args.seconds * constants.CONTROL_HZ < 1
    ):
        parser.error("--batch, --c-max-batch, --repeats must be >= 1 and --seconds at least 0.1 s")
    if args.out.exists() and not args.out.is_dir():
        parser.error(f"--out {args.out} is a file, not a folder")

    header = run_header("bench.rod_throughput", argv)
    periods = int(round(args.seconds * constants.CONTROL_HZ))
    result = {
        "machine": machine(),
        "protocol": {
            "batches": args.batch,
            "seconds": periods / constants.CONTROL_HZ,
            "domain": args.domain,
            "c_max_batch": args.c_max_batch,
            "repeats": args.repeats,
            "accuracy_seeds": list(fidelity.BABBLE_SEEDS),
        },
        "rows": [],
        "float32_accuracy": [],
    }
    out = args.out / "rod_throughput"
    title = "Rollout throughput: the reference rod beside the chain"

    def save() -> None:
        write_results(out, header, result, title, markdown(result))

    backends = {f"rod {d}": mjx_arm.load_rod(args.domain, dtype=d).rollout for d in args.dtypes}
    if not args.no_chain:
        chain = mjx_arm.load(domain=args.domain)
        backends["chain MJX"] = lambda c: chain.rollout(c, backend="mjx")
        backends["chain MuJoCo C"] = lambda c: chain.rollout(c, backend="c")
    for batch in args.batch:
        commands = bench_programs(batch, periods)
        for name, rollout in backends.items():
            if name == "chain MuJoCo C" and batch > args.c_max_batch:
                continue
            jitted = name != "chain MuJoCo C"
            timing = timed_rollout(rollout, commands, jitted, args.repeats)
            row = {"backend": name, "batch": batch, **timing}
            result["rows"].append(row)
            print(
                f"{name:>15} batch {batch:>6}: {row['sim_s_per_wall_s']:10.4g} sim s / wall s"
                f" (first call {fmt_s(row['first_call_s'])}, timed {row['wall_s']:.3g} s)",
                flush=True,
            )
            save()
    if args.accuracy_seconds > 0 and "float32" in args.dtypes:
        for domain in args.accuracy_domains:
            a = float32_accuracy(domain, args.accuracy_seconds, fidelity.BABBLE_SEEDS)
            result["float32_accuracy"].append(a)
            print(
                f"float32 vs float64, {domain}: largest tip difference"
                f" {a['max_tip_fraction_of_L']:.3g} of L, RMS {a['rms_tip_fraction_of_L']:.3g}",
                flush=True,
            )
            save()
    save()
    print(f"wrote {out}.md and .json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
