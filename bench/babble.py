"""Babbling throughput: MJX (jit + vmap, sharded over devices) beside MuJoCo C, in one run.

For each batch size B, one jitted rollout of B babbling programs of `--seconds` simulated seconds
each is compiled (timed apart), then run `--repeats` times; the best run gives simulated seconds
per wall second (B x seconds / wall) and physics steps per second (B x seconds / timestep / wall).
MuJoCo C (`mujoco.rollout`, all CPU cores, through `Arm.rollout(..., backend="c")`) runs the
same programs on the same model and timestep; its batch is capped at `--c-max-batch` because its
throughput saturates once every core is busy. With several local devices, MJX is timed on one
device and on all of them. `--paper` also times the paper's data generation end to end (50 + 3
trajectories x 60 s x both domains, compilation included) with MJX and with MuJoCo C.

Writes ``babble.md`` and ``babble.json`` to `--out`.

    python bench/babble.py --quick --paper --out results/bench_babble_cpu   # CPU smoke run
    python bench/babble.py --paper --cache-dir /tmp/jax_cache --out results/bench_babble_gpu

On the GPU machines (Python 3.12, jax with CUDA, no mujoco, no network), download the wheels here
first and carry ``.whl/`` along (it is git-ignored)::

    python -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
      --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 \
      --platform manylinux_2_17_x86_64 --platform any -d .whl mujoco==3.17.0 mujoco-mjx==3.17.0 \
      glfw pyopengl trimesh etils absl-py websockets tqdm
    # there:
    python3 -m pip install -q --no-index --no-deps --target /tmp/site .whl/*.whl \
      && export PYTHONPATH=/tmp/site:$PWD \
      && python3 bench/babble.py --paper --cache-dir /tmp/jax_cache --out $OUT/bench_babble

Each compilation (one per batch size and device set, one for the paper preset) can take a minute
on a GPU; `--cache-dir` keeps them for the next run, and results are written after every row.
`--sizes ""` with `--paper` times only the paper preset.
"""

# ruff: noqa: I001  (mjx_arm is imported before jax: it sets an XLA CPU flag)
from __future__ import annotations

from ccgan.cli import cli_parser
import mjx_arm

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
import traceback
from pathlib import Path

import jax
import mujoco
import numpy as np

from mjx_arm import babble
from mjx_arm.machine import cpu_model, usable_cores
from mjx_arm.programs import babble_programs


def load_arm(args, domain: str) -> mjx_arm.Arm:
    if args.segments:
        params = dataclasses.replace(mjx_arm.ArmParams(), n_segments=args.segments)
        return mjx_arm.load(xml=mjx_arm.generate_xml(params), domain=domain)
    return mjx_arm.load(args.model, domain=domain)


def rates(batch: int, seconds: float, timestep_s: float, wall_s: float) -> dict:
    sim_s = batch * seconds
    return {
        "wall_s": wall_s,
        "sim_s_per_wall_s": sim_s / wall_s,
        "steps_per_s": sim_s / timestep_s / wall_s,
    }


def time_mjx(arm, programs: np.ndarray, devices, repeats: int, budget_s: float) -> dict:
    """Compile then run a sharded MJX rollout of programs [B, T, 3] on `devices`.

    Runs up to `repeats` times, stopping once the runs took `budget_s` in all.
    """
    sharded = babble.ShardedRollout(arm, devices)
    size = babble.padded_size(programs.shape[0], sharded.n_devices)
    start = time.perf_counter()
    compiled = sharded.compile(size, programs.shape[1])
    compile_s = time.perf_counter() - start
    commands = sharded.shard(sharded.pad(programs, size))
    walls = []
    while len(walls) < repeats and sum(walls) < budget_s:
        start = time.perf_counter()
        poses, ok = compiled(sharded.mjx_model, sharded.rest, commands)
        jax.block_until_ready((poses, ok))
        walls.append(time.perf_counter() - start)
    n_ok = int(np.asarray(ok)[: programs.shape[0], -1].sum())
    return {"compile_s": compile_s, "walls_s": walls, "wall_s": min(walls), "n_ok": n_ok}


def time_c(arm, programs: np.ndarray, repeats: int) -> dict:
    """MuJoCo C on all cores, as babbling runs it (`Arm.rollout` in chunks of C_MAX_CHUNK)."""
    arm.rollout(programs[:1, :1], backend="c")  # warm-up: first-call setup is not throughput
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        babble.simulate(arm, programs, backend="c", chunk=babble.C_MAX_CHUNK)
        walls.append(time.perf_counter() - start)
    return {"walls_s": walls, "wall_s": min(walls)}


def time_paper(args, backend: str) -> dict:
    """Wall time of the paper's data generation (compile and file writing included)."""
    config = dataclasses.replace(babble.PAPER, backend=backend)
    if args.quick:
        config = dataclasses.replace(config, n_train=2, n_val=1, duration_s=2.0)
    xml = None
    if args.segments:
        xml = mjx_arm.generate_xml(
            dataclasses.replace(mjx_arm.ArmParams(), n_segments=args.segments)
        )
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        babble.run(config, out, model_path=args.model, xml=xml, progress=False)
        wall = time.perf_counter() - start
    n_traj = len(config.domains) * (config.n_train + config.n_val)
    return {
        "backend": backend,
        "trajectories": n_traj,
        "duration_s": config.duration_s,
        "wall_s": wall,
    }


def run_bench(args) -> dict:
    arm = load_arm(args, args.domain)
    n_steps = int(round(args.seconds * mjx_arm.CONTROL_HZ))
    config = dataclasses.replace(babble.PAPER, duration_s=args.seconds)
    local = jax.local_devices()
    device_sets = {"1 device": local[:1]}
    if len(local) > 1 and not args.single_device:
        device_sets[f"{len(local)} devices"] = local
    result = {
        "device": local[0].device_kind,
        "platform": jax.default_backend(),
        "n_local_devices": len(local),
        "cpu": cpu_model(),
        "cpu_cores": os.cpu_count(),
        "jax": jax.__version__,
        "mujoco": mujoco.__version__,
        "domain": arm.domain.name,
        "model_hash": arm.model_hash,
        "nv": int(arm.mj_model.nv),
        "timestep_s": arm.timestep_s,
        "seconds_per_trajectory": args.seconds,
        "physics_steps_per_trajectory": n_steps * arm.n_substeps,
        "compilation_cache": args.cache_dir,
        "mjx": [],
        "c": [],
        "paper": [],
    }
    print(f"device {result['device']} x{len(local)}, cpu {result['cpu']} ({os.cpu_count()} cores)")
    for batch in args.sizes:
        programs = babble_programs(config, np.arange(batch), domain=arm.domain.name)
        for label, devices in device_sets.items():
            row = {"batch": batch, "devices": len(devices)}
            try:
                row.update(time_mjx(arm, programs, devices, args.repeats, args.budget))
                row.update(rates(batch, args.seconds, arm.timestep_s, row["wall_s"]))
            except Exception as err:  # e.g. out of device memory: record it and go on
                row["error"] = f"{type(err).__name__}: {str(err)[:300]}"
                traceback.print_exc()
            result["mjx"].append(row)
            print(f"mjx {label} B={batch}: " + _fmt(row), flush=True)
            write(result, args.out)
        if batch <= args.c_max_batch or batch == min(args.sizes):
            threads = min(usable_cores(), batch, babble.C_MAX_CHUNK)
            row = {"batch": batch, "threads": threads}
            row.update(time_c(arm, programs, args.c_repeats))
            row.update(rates(batch, args.seconds, arm.timestep_s, row["wall_s"]))
            result["c"].append(row)
            print(f"C   B={batch}: " + _fmt(row), flush=True)
            write(result, args.out)
    if args.paper:
        backends = ["c"] if args.skip_mjx_paper else ["mjx", "c"]
        for backend in backends:
            row = time_paper(args, backend)
            result["paper"].append(row)
            print(f"paper preset ({backend}): {row['wall_s']:.1f} s", flush=True)
            write(result, args.out)
    return result


def write(result: dict, out: str | Path) -> Path:
    """Writes babble.json and babble.md to `out` (after every measurement: a run cut short by a
    time limit still leaves what it measured)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "babble.json").write_text(json.dumps(result, indent=2) + "\n")
    (out / "babble.md").write_text(markdown(result))
    return out


def _fmt(row: dict) -> str:
    if "error" in row:
        return row["error"]
    compile_s = f"compile {row['compile_s']:.1f} s, " if "compile_s" in row else ""
    return (
        f"{compile_s}run {row['wall_s']:.3f} s, {row['sim_s_per_wall_s']:.3g} sim s/s,"
        f" {row['steps_per_s']:.3g} steps/s"
    )


def markdown(result: dict) -> str:
    r = result
    lines = [
        "# Babbling throughput",
        "",
        f"- accelerator: {r['device']} x{r['n_local_devices']} ({r['platform']})",
        f"- CPU: {r['cpu']}, {r['cpu_cores']} cores (MuJoCo C uses all of them)",
        f"- jax {r['jax']}, mujoco {r['mujoco']}; domain {r['domain']}, model {r['model_hash']},"
        f" nv {r['nv']}, timestep {r['timestep_s']} s",
        f"- each trajectory: {r['seconds_per_trajectory']} s simulated ="
        f" {r['physics_steps_per_trajectory']} physics steps; best of the repeats; compile apart"
        + (f" (cache {r['compilation_cache']})" if r["compilation_cache"] else ""),
        "",
        "| engine | devices / threads | batch | compile s | run s | sim s per wall s | steps/s |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in r["mjx"]:
        if "error" in row:
            lines.append(f"| MJX | {row['devices']} | {row['batch']} | | {row['error']} | | |")
            continue
        lines.append(
            f"| MJX | {row['devices']} | {row['batch']} | {row['compile_s']:.1f} |"
            f" {row['wall_s']:.3f} | {row['sim_s_per_wall_s']:.3g} | {row['steps_per_s']:.3g} |"
        )
    for row in r["c"]:
        lines.append(
            f"| MuJoCo C | {row['threads']} | {row['batch']} | - | {row['wall_s']:.3f} |"
            f" {row['sim_s_per_wall_s']:.3g} | {row['steps_per_s']:.3g} |"
        )
    if r["paper"]:
        lines += [
            "",
            "## Paper preset, end to end (compile and file writing included)",
            "",
            "| backend | trajectories | s each | wall s |",
            "|---|---|---|---|",
        ]
        for row in r["paper"]:
            lines.append(
                f"| {row['backend']} | {row['trajectories']} | {row['duration_s']} |"
                f" {row['wall_s']:.1f} |"
            )
    return "\n".join(lines) + "\n"


def parse_args(argv=None) -> argparse.Namespace:
    p = cli_parser("bench.babble", __doc__)
    p.add_argument("--sizes", default="1024,4096,16384,65536", help="comma-separated batch sizes")
    p.add_argument("--seconds", type=float, default=1.0, help="simulated seconds per trajectory")
    p.add_argument(
        "--repeats", type=int, default=3, help="most timed MJX runs per size (best kept)"
    )
    p.add_argument("--budget", type=float, default=20.0, help="stop repeating after this many s")
    p.add_argument("--c-repeats", type=int, default=1, help="timed MuJoCo C runs per size")
    p.add_argument("--c-max-batch", type=int, default=4096, help="largest MuJoCo C batch")
    p.add_argument("--domain", default="source")
    p.add_argument("--model", help="MJCF path (default: models/softarm.xml)")
    p.add_argument("--segments", type=int, help="use a generated model with this many segments")
    p.add_argument("--single-device", action="store_true", help="skip the all-devices timing")
    p.add_argument("--paper", action="store_true", help="also time the paper preset end to end")
    p.add_argument("--skip-mjx-paper", action="store_true", help="paper preset with C only")
    p.add_argument("--cache-dir", help="JAX persistent compilation cache folder")
    p.add_argument("--quick", action="store_true", help="CPU smoke run: tiny sizes and model")
    p.add_argument(
        "--out", default="runs/bench", help="output folder (committed results: bench/results)"
    )
    args = p.parse_args(argv)
    if args.quick:
        args.sizes = "2,8" if args.sizes == p.get_default("sizes") else args.sizes
        args.seconds = min(args.seconds, 1.0)
        args.repeats = min(args.repeats, 2)
        args.segments = args.segments or 3
    args.sizes = [int(s) for s in str(args.sizes).split(",") if s]
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.cache_dir:
        jax.config.update("jax_compilation_cache_dir", args.cache_dir)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    result = run_bench(args)
    out = write(result, args.out)
    print(markdown(result))
    print(f"wrote {out / 'babble.md'} and {out / 'babble.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
