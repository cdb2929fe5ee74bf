"""Throughput of batched arm rollouts: MJX on the accelerator beside MuJoCo C on all CPU cores.

Both backends run the same model, domain, timestep and pressure programs (`Arm.rollout`). MJX is
jitted and vmapped over the batch, and the batch is sharded over all local devices; its compile
time is measured separately. MuJoCo C runs `mujoco.rollout` with one thread per CPU core.

    python -m bench.throughput --out bench/results            # on a GPU machine
    python -m bench.throughput --quick                        # CPU smoke run
    python -m bench.throughput --set timestep_s=0.002 ...     # a variant of ArmParams

Writes throughput.md and throughput.json to --out (with the overrides in the name).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

import mjx_arm  # sets the XLA CPU flag; jax reads it when its backend starts
from mjx_arm.machine import cpu_model


def programs(batch: int, periods: int, seed: int = 0) -> np.ndarray:
    """Random targets in [0, 3.5] bar held 0.5-2 s: [batch, periods, 3]."""
    rng = np.random.default_rng(seed)
    out = np.empty((batch, periods, 3))
    for b in range(batch):
        t = 0
        while t < periods:
            hold = int(rng.integers(5, 21))
            out[b, t : t + hold] = rng.uniform(0.0, 3.5, 3)
            t += hold
    return out


def time_mjx(arm: mjx_arm.Arm, batch: int, periods: int) -> dict:
    devices = jax.devices()
    mesh = Mesh(np.array(devices), ("batch",))
    padded = -(-batch // len(devices)) * len(devices)
    commands = jnp.asarray(programs(padded, periods), dtype=jnp.float32)
    commands = jax.device_put(commands, NamedSharding(mesh, PartitionSpec("batch")))
    fn = jax.jit(jax.vmap(arm.rollout_fn(), in_axes=(None, 0)))
    start = time.perf_counter()
    compiled = fn.lower(arm.mjx_model, commands).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(arm.mjx_model, commands))  # warm-up
    start = time.perf_counter()
    poses, ok = jax.block_until_ready(compiled(arm.mjx_model, commands))
    wall = time.perf_counter() - start
    assert bool(np.asarray(ok).all()), "MJX rollout diverged"
    return {"compile_s": compile_s, "wall_s": wall, "batch": padded}


def time_c(arm: mjx_arm.Arm, batch: int, periods: int) -> dict:
    commands = programs(batch, periods)
    arm.rollout(commands[:2, :2], backend="c")  # warm-up thread pool
    start = time.perf_counter()
    arm.rollout(commands, backend="c")
    return {"wall_s": time.perf_counter() - start, "batch": batch}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domains", nargs="+", default=["source", "constrained"])
    parser.add_argument("--batches", type=int, nargs="+", default=[1024, 4096, 16384, 65536])
    parser.add_argument("--c-batch", type=int, default=None, help="C batch (default 16/core)")
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated s per rollout")
    parser.add_argument("--quick", action="store_true", help="tiny CPU smoke run")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="generate the model from ArmParams with this field changed (repeatable)",
    )
    parser.add_argument("--label", default="committed model", help="name of the model variant")
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    args = parser.parse_args(argv)
    if args.quick:
        args.batches, args.seconds = [8], 1.0
    periods = int(round(args.seconds * 10))
    cores = os.cpu_count() or 1
    c_batch = args.c_batch or 16 * cores

    device = jax.devices()[0]
    machine = {
        "accelerator": f"{len(jax.devices())} x {device.device_kind}",
        "backend": jax.default_backend(),
        "cpu": cpu_model(),
        "cpu_cores": cores,
        "jax": jax.__version__,
    }
    rows = []
    overrides = {}
    for item in args.set:
        field, value = item.split("=", 1)
        default = getattr(mjx_arm.ArmParams(), field)
        overrides[field] = (
            value.lower() in ("1", "true") if isinstance(default, bool) else type(default)(value)
        )
    xml = mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), **overrides))
    for domain in args.domains:
        arm = mjx_arm.load(xml=xml, domain=domain)
        steps = periods * arm.n_substeps
        c = time_c(arm, c_batch, periods)
        c_sim_rate = c["batch"] * args.seconds / c["wall_s"]
        for batch in args.batches:
            r = time_mjx(arm, batch, periods)
            sim_rate = r["batch"] * args.seconds / r["wall_s"]
            rows.append(
                {
                    "model": args.label,
                    "overrides": overrides,
                    "domain": domain,
                    "segments": arm.mj_model.nbody - 1,
                    "timestep_s": arm.timestep_s,
                    "batch": r["batch"],
                    "sim_seconds": args.seconds,
                    "mjx_compile_s": round(r["compile_s"], 2),
                    "mjx_wall_s": round(r["wall_s"], 3),
                    "mjx_sim_s_per_s": round(sim_rate, 1),
                    "mjx_steps_per_s": round(r["batch"] * steps / r["wall_s"]),
                    "c_batch": c["batch"],
                    "c_sim_s_per_s": round(c_sim_rate, 1),
                    "c_steps_per_s": round(c["batch"] * steps / c["wall_s"]),
                    "mjx_over_c": round(sim_rate / c_sim_rate, 2),
                }
            )
            print(rows[-1], flush=True)

    args.out.mkdir(parents=True, exist_ok=True)
    tag = "" if not overrides else "_" + "_".join(f"{k}-{v}" for k, v in overrides.items())
    (args.out / f"throughput{tag}.json").write_text(
        json.dumps({"machine": machine, "rows": rows}, indent=1)
    )
    header = "| domain | batch | MJX compile s | MJX sim s/s | MJX steps/s | C sim s/s | MJX / C |"
    lines = [
        "# Rollout throughput",
        "",
        f"Machine: {machine['accelerator']} ({machine['backend']}), CPU {machine['cpu']} x"
        f" {cores} cores, jax {machine['jax']}. Model: models/softarm.xml, "
        f"{args.seconds:g} simulated s per rollout, physics steps at the model's timestep.",
        f"Model variant: {args.label} {overrides or ''}",
        f"MuJoCo C: `mujoco.rollout`, {cores} threads, batch {c_batch}.",
        "Command: `python -m bench.throughput "
        + " ".join(argv or __import__("sys").argv[1:])
        + "`",
        "",
        header,
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['domain']} | {r['batch']} | {r['mjx_compile_s']} | {r['mjx_sim_s_per_s']:.0f} |"
            f" {r['mjx_steps_per_s']:.3g} | {r['c_sim_s_per_s']:.0f} | {r['mjx_over_c']} |"
        )
    (args.out / f"throughput{tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
