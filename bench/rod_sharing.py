"""Whether several processes running the reference rod at once share a machine: GPU or CPU cores.

The rod is latency-bound: 500 sequential steps per 0.1 s control period, each a handful of small
kernels. The chain's config ran its rod stages (babbling, two trainings that choose k in the rod,
the tables) side by side on one GPU, on the assumption that latency-bound processes overlap.
This measures it. N worker processes start together, each compiles its rollout, waits until all
have compiled, then times one rollout of `--batch` programs of `--seconds`; the table gives each
worker's simulated s per wall s against one worker alone, and the sum over workers.
`--platform cpu` runs the workers on the host's cores instead (JAX_PLATFORMS=cpu), to compare.

    python -m bench.rod_sharing --out bench/results/h200/rod_sharing --processes 1 2 4
    python -m bench.rod_sharing --out bench/results/h200/rod_sharing_cpu --platform cpu \\
        --processes 1 4 16 --batch 1

Writes rod_sharing.md and rod_sharing.json (rewritten after every N).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench import parse_checked, run_header, write_results


def worker(batch: int, seconds: float, ready: Path, go: Path) -> None:
    """One process: compile, say ready, wait for go, time one rollout, print JSON."""
    import mjx_arm  # (sets the XLA CPU flag before jax)
    from mjx_arm.programs import bench_programs

    rod = mjx_arm.load_rod("constrained")
    commands = bench_programs(batch, round(seconds * 10), seed=os.getpid() % 1000)
    rod.rollout(commands)  # compiles
    ready.touch()
    while not go.exists():
        time.sleep(0.01)
    start = time.perf_counter()
    rod.rollout(commands)
    wall = time.perf_counter() - start
    print(json.dumps({"wall_s": wall, "sim_s_per_s": batch * seconds / wall}), flush=True)


def run_together(n: int, batch: int, seconds: float, platform: str) -> list[dict]:
    """Starts n workers, releases them together once all have compiled; their results."""
    env = os.environ.copy()
    if platform == "cpu":
        env["JAX_PLATFORMS"] = "cpu"
    else:
        env["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
    with tempfile.TemporaryDirectory() as tmp:
        go = Path(tmp) / "go"
        procs, readies = [], []
        for i in range(n):
            ready = Path(tmp) / f"ready{i}"
            readies.append(ready)
            cmd = [sys.executable, "-m", "bench.rod_sharing", "--worker", "--batch", str(batch)]
            cmd += ["--seconds", str(seconds), "--ready", str(ready), "--go", str(go)]
            cmd += ["--out", tmp]
            procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env=env))
        while not all(r.exists() for r in readies):
            if any(p.poll() not in (None, 0) for p in procs):
                raise RuntimeError("a worker failed before it was ready")
            time.sleep(0.05)
        go.touch()
        out = []
        for p in procs:
            stdout, _ = p.communicate()
            if p.returncode:
                raise RuntimeError(f"a worker exited with status {p.returncode}")
            out.append(json.loads(stdout.strip().splitlines()[-1]))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.rod_sharing", description=__doc__)
    parser.add_argument("--out", required=True, help="folder for rod_sharing.{md,json}")
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--batch", type=int, default=8, help="programs per worker's rollout")
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated s per program")
    parser.add_argument("--platform", choices=["default", "cpu"], default="default")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--ready", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--go", type=Path, help=argparse.SUPPRESS)
    if argv is None:
        argv = sys.argv[1:]
    if "--worker" in argv:
        args = parser.parse_args(argv)
        worker(args.batch, args.seconds, args.ready, args.go)
        return 0
    args = parse_checked(parser, argv, prefix=False)
    if min(args.processes) < 1 or args.batch < 1 or not args.seconds > 0:
        parser.error("--processes and --batch must be >= 1 and --seconds > 0")
    header = run_header("bench.rod_sharing", argv) | {"workers_on": args.platform}
    rows = []
    for n in args.processes:
        results = run_together(n, args.batch, args.seconds, args.platform)
        each = [r["sim_s_per_s"] for r in results]
        rows.append({"processes": n, "each_sim_s_per_s": each, "sum_sim_s_per_s": sum(each)})
        print(rows[-1], flush=True)
        alone = rows[0]["sum_sim_s_per_s"] / rows[0]["processes"]
        lines = [
            "",
            f"Each worker: the rod in D_c (float64), one rollout of {args.batch} programs of"
            f" {args.seconds:g} s (`bench_programs`), timed after its compile, all workers"
            f" released together; workers on: {args.platform} (cpu: JAX_PLATFORMS=cpu).",
            "",
            "| processes | each, sim s / s (mean) | each / one alone | sum, sim s / s |",
            "|---|---|---|---|",
        ]
        for r in rows:
            mean, total = sum(r["each_sim_s_per_s"]) / r["processes"], r["sum_sim_s_per_s"]
            lines.append(f"| {r['processes']} | {mean:.3g} | {mean / alone:.2f} | {total:.3g} |")
        write_results(
            f"{args.out}/rod_sharing",
            header,
            {"rows": rows},
            "The reference rod in several processes at once",
            lines,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
