"""The reference rod split over the host's cores in one process, beside JAX's default device.

`mjx_arm.rod_arm.host_devices`: when JAX has several CPU devices (XLA_FLAGS
--xla_force_host_platform_device_count=N before it starts, which `experiments.paper` sets on an
accelerator), `RodArm.rollout` shards its batch over them, one thread each. This measures what
that gives: for each device count N, a fresh process times one rollout (after its compile) of
N x b programs of `--seconds` for each per-device batch b; a last process does the same batches
on JAX's default device (the GPU on a GPU machine; one CPU device otherwise). Simulated s per
wall s, and per core. `RodArm.call_size` uses b = `HOST_BATCH_PER_DEVICE`.

    python -m bench.rod_host --out bench/results/cpu/rod_host --devices 1 2 --per-device 1 2 4 8
    python -m bench.rod_host --out bench/results/h200/rod_host --devices 1 4 16

Writes rod_host.md and rod_host.json (rewritten after every process).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

from bench import parse_checked, run_header, write_results

FLAG = "--xla_force_host_platform_device_count"


def worker(batches: list[int], seconds: float) -> None:
    """One process: for each total batch, compile, then time one rollout; prints JSON lines."""
    import mjx_arm  # (sets the XLA CPU flag before jax)
    from mjx_arm.programs import bench_programs

    rod = mjx_arm.load_rod("constrained")
    for batch in batches:
        commands = bench_programs(batch, round(seconds * 10), seed=batch)
        rod.rollout(commands)  # compiles
        start = time.perf_counter()
        rod.rollout(commands)
        wall = time.perf_counter() - start
        row = {"batch": batch, "placement": rod.placement(), "wall_s": wall}
        print(json.dumps(row | {"sim_s_per_s": batch * seconds / wall}), flush=True)


def run_worker(devices: int | None, batches: list[int], seconds: float) -> list[dict]:
    """A fresh process with `devices` host CPU devices (None: JAX's defaults, no forced count)."""
    env = os.environ.copy()
    flags = [f for f in env.get("XLA_FLAGS", "").split() if not f.startswith(FLAG)]
    if devices is not None:
        flags.append(f"{FLAG}={devices}")
    env["XLA_FLAGS"] = " ".join(flags)
    env["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
    cmd = [sys.executable, "-m", "bench.rod_host", "--worker", "--seconds", str(seconds)]
    cmd += ["--batches", *map(str, batches), "--out", "unused"]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode:
        raise RuntimeError(f"worker ({devices} devices) failed:\n{out.stderr[-3000:]}")
    return [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.rod_host", description=__doc__)
    parser.add_argument("--out", required=True, help="folder for rod_host.{md,json}")
    parser.add_argument("--devices", type=int, nargs="+", default=[1, 2], help="host devices N")
    parser.add_argument("--per-device", type=int, nargs="+", default=[1, 4, 8], help="b")
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated s per program")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--batches", type=int, nargs="+", help=argparse.SUPPRESS)
    if argv is None:
        argv = sys.argv[1:]
    if "--worker" in argv:
        args = parser.parse_args(argv)
        worker(args.batches, args.seconds)
        return 0
    args = parse_checked(parser, argv, prefix=False)
    if min(args.devices) < 1 or min(args.per_device) < 1 or not args.seconds > 0:
        parser.error("--devices and --per-device must be >= 1 and --seconds > 0")
    header = run_header("bench.rod_host", argv)
    rows = []
    runs = [(n, [n * b for b in args.per_device]) for n in args.devices]
    largest = sorted({n * b for n in args.devices for b in args.per_device})
    runs.append((None, largest))
    for n, batches in runs:
        for r in run_worker(n, batches, args.seconds):
            cores = n if n is not None else 1
            rows.append(r | {"devices": n, "sim_s_per_s_per_core": r["sim_s_per_s"] / cores})
            print(rows[-1], flush=True)
        lines = [
            "",
            f"The rod in D_c (float64), programs of {args.seconds:g} s (`bench_programs`), one"
            " rollout timed after its compile, in a fresh process per row group. devices: host"
            f" CPU devices ({FLAG}), the batch split over them (`RodArm.rollout`); 'default':"
            " JAX's default device, no forced count.",
            "",
            "| devices | placement | batch | per device | sim s / s | per device, sim s / s |",
            "|---|---|---|---|---|---|",
        ]
        for r in rows:
            n = r["devices"]
            per = r["batch"] // n if n else r["batch"]
            lines.append(
                f"| {n or 'default'} | {r['placement']} | {r['batch']} | {per} |"
                f" {r['sim_s_per_s']:.4g} | {r['sim_s_per_s_per_core']:.3g} |"
            )
        write_results(
            f"{args.out}/rod_host", header, {"rows": rows}, "The rod on the host's cores", lines
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
