"""Batched arm rollouts per second: MJX (JAX or Warp) on the accelerator, MuJoCo C on all cores.

Every backend runs the same model, domain, timestep and pressure programs (`Arm.rollout`'s
program: valves, substeps, the tip pose read once per control period). MJX is jitted and vmapped
over the batch, and the batch is sharded over all local devices; its compile time and the extra
time of its first call (Warp builds its CUDA kernels then) are measured apart from the timed
call. MuJoCo C runs `mujoco.rollout` with one thread per CPU core.

Implementations (`--impl`, each listed one is run):
  jax   MJX-JAX: `mjx_arm.arm.rollout_program`, the function behind `Arm.rollout_fn()`.
  warp  MJX-Warp (`mjx.put_model(m, impl="warp")`, needs warp-lang==1.18.0, NVIDIA GPU or CPU):
        the same program, except that `mjx.make_data` is given the host `mujoco.MjModel` and
        impl="warp", since it refuses an `mjx.Model` (`rollout_program(warp_host_model=...)`).
        No gradients.
Both take the rest state as an argument, so one compiled program serves every domain of a
segment count (the domains differ only in model values).

Pose check: the first `--check-batch` programs of the smallest batch are compared with MuJoCo C
(float64) and, for warp, with MJX-JAX on the same programs; the largest tip-position (mm) and
d3-director differences are recorded.

    python -m bench.throughput --out bench/results/h200               # on a GPU machine
    python -m bench.throughput --impl jax warp --segments 10 20 30 --batches 8192 32768 --seconds 2
    python -m bench.throughput --quick                                # CPU smoke run
    python -m bench.throughput --set timestep_s=0.002 ...             # a variant of ArmParams
    python -m bench.throughput --report-only --out DIR --merge other.json   # tables from results

Writes throughput{tag}.md, throughput{tag}.json and throughput{tag}_check_poses.npz to --out (the
tag names the overrides, and "_segments" with --segments; not the implementations or counts).
With --append, the rows, checks and poses already there are kept (rows of the same segments,
domain, impl and batch are replaced), so runs of one implementation or segment count after
another end in one table. Every row keeps the machine it was measured on (JSON "machine" of
each row; "machines" lists them), so a table merged or rewritten on another machine
(--report-only) still names the machines of its rows, not its own. Files are rewritten after
every row, so a run stopped part-way leaves what it measured.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import os
import shlex
import sys
import time
from importlib import metadata
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

import mjx_arm  # sets the XLA CPU flag; jax reads it when its backend starts
from ccgan.cli import cli_parser
from mjx_arm.arm import (
    mjx,  # imported by mjx_arm without its notice when warp is absent
    rollout_program,
)
from mjx_arm.machine import cpu_model
from mjx_arm.programs import bench_programs

IMPLS = ("jax", "warp")
IMPL_NAMES = {"jax": "MJX-JAX", "warp": "MJX-Warp"}
DOMAIN_ORDER = ("source", "constrained")


WARP_DENSE_NV_MAX = 60  # MuJoCo Warp refuses a dense Jacobian above this many dofs


def host_model(arm: mjx_arm.Arm) -> mujoco.MjModel:
    """The arm's model as MJX-Warp runs it: sensors off (rollouts read the tip site directly).

    Above 60 dofs MuJoCo Warp accepts only the sparse Jacobian, so longer chains switch to it
    (the dynamics are the same; only the linear algebra's layout changes).
    """
    m = copy.copy(arm.mj_model)
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
    if m.nv > WARP_DENSE_NV_MAX:
        m.opt.jacobian = mujoco.mjtJacobian.mjJAC_SPARSE
    return m


def device_model(arm: mjx_arm.Arm, impl: str) -> mjx.Model:
    if impl == "jax":
        return arm.mjx_model
    return mjx.put_model(host_model(arm), impl="warp")


def batched_rollout(arm: mjx_arm.Arm, impl: str):
    """jit(vmap(program)): (model, commands [B, T, 3], rest_qpos, rest_qvel) -> (poses, ok)."""
    bound = dict(
        tip_site=arm.tip_site_id,
        actuators=tuple(int(i) for i in arm.actuator_ids),
        n_substeps=arm.n_substeps,
        valve_params=arm.valve,
        controls=arm.chamber_controls,
    )
    if impl == "warp":
        bound["warp_host_model"] = host_model(arm)

    def one(model, commands, rest_qpos, rest_qvel):
        return rollout_program(model, commands, rest_qpos=rest_qpos, rest_qvel=rest_qvel, **bound)

    return jax.jit(jax.vmap(one, in_axes=(None, 0, None, None)))


def same_signature(a, b) -> bool:
    """Whether two models can share one compiled program (same tree, static fields, shapes)."""
    ta, tb = jax.tree_util.tree_structure(a), jax.tree_util.tree_structure(b)
    if ta != tb:
        return False
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    return all(
        np.shape(x) == np.shape(y) and jnp.result_type(x) == jnp.result_type(y)
        for x, y in zip(la, lb, strict=True)
    )


def sharded_commands(batch: int, periods: int):
    devices = jax.devices()
    mesh = Mesh(np.array(devices), ("batch",))
    padded = -(-batch // len(devices)) * len(devices)
    commands = jnp.asarray(bench_programs(padded, periods), dtype=jnp.float32)
    return jax.device_put(commands, NamedSharding(mesh, PartitionSpec("batch"))), padded


def time_mjx(compiled, model, commands, rest: tuple, n_keep: int) -> dict:
    """First (warm-up) call and a timed call; returns times and the first n_keep poses."""
    start = time.perf_counter()
    jax.block_until_ready(compiled(model, commands, *rest))
    first = time.perf_counter() - start
    start = time.perf_counter()
    poses, ok = jax.block_until_ready(compiled(model, commands, *rest))
    wall = time.perf_counter() - start
    ok = np.asarray(ok)
    if not ok.all():
        bad = np.flatnonzero(~ok[:, -1])
        raise RuntimeError(f"MJX rollout diverged in {bad.size} trajectories, e.g. {bad[:5]}")
    return {
        "first_call_s": first,
        "wall_s": wall,
        "poses": np.asarray(poses[:n_keep], dtype=np.float64),
    }


def time_c(arm: mjx_arm.Arm, batch: int, periods: int) -> dict:
    commands = bench_programs(batch, periods)
    arm.rollout(commands[:2, :2], backend="c")  # warm-up thread pool
    start = time.perf_counter()
    arm.rollout(commands, backend="c")
    return {"wall_s": time.perf_counter() - start, "batch": batch}


def pose_diff(a: np.ndarray, b: np.ndarray) -> dict:
    """Largest tip-position (mm) and d3 differences between poses [..., 6]."""
    return {
        "pos_mm": round(float(np.abs(a[..., :3] - b[..., :3]).max()) * 1e3, 6),
        "d3": float(f"{float(np.abs(a[..., 3:] - b[..., 3:]).max()):.3g}"),
    }


def version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def fmt(x) -> str:
    return "" if x is None else f"{x:.3g}"


def row_key(r: dict) -> tuple:
    return (r["segments"], r["domain"], r["impl"], r["batch"])


def check_key(c: dict) -> tuple:
    return (c["segments"], c["domain"], c["impl"])


class Results:
    """Rows, pose checks and check poses of a run, kept in --out and rewritten after each row."""

    def __init__(self, out: Path, tag: str, machine: dict, command: str, append: bool):
        self.json_path = out / f"throughput{tag}.json"
        self.md_path = out / f"throughput{tag}.md"
        self.poses_path = out / f"throughput{tag}_check_poses.npz"
        self.machine, self.rows, self.checks, self.poses, self.commands = machine, [], [], {}, []
        if append:
            self.merge(self.json_path)
        if command:
            self.commands.append(command)

    def merge(self, path: Path) -> None:
        if not path.exists():
            return
        old = json.loads(path.read_text())
        # Each row keeps the machine it was measured on: its own, else its file's (files from
        # before rows carried one). This run's machine never relabels older rows.
        for r in old.get("rows", []):
            self.add_row({"machine": old.get("machine", {}), **r}, write=False)
        for c in old.get("checks", []):
            self.add_check(c, write=False)
        self.commands = old.get("commands", []) + self.commands
        poses_path = path.with_name(path.stem + "_check_poses.npz")
        if poses_path.exists():
            with np.load(poses_path) as f:
                self.poses.update({k: f[k] for k in f.files if k not in self.poses})
        self.check_warp_against_jax()

    def check_warp_against_jax(self) -> None:
        """Fills a Warp check's `vs_jax` from MJX-JAX poses of the same programs, from any run."""
        for c in self.checks:
            if c["impl"] != "warp" or c.get("vs_jax"):
                continue
            warp = self.poses.get(f"seg{c['segments']}_{c['domain']}_warp")
            jax_poses = self.poses.get(f"seg{c['segments']}_{c['domain']}_jax")
            if warp is not None and jax_poses is not None and warp.shape == jax_poses.shape:
                c["vs_jax"] = pose_diff(warp, jax_poses)

    def add_row(self, row: dict, write: bool = True) -> None:
        """Adds (or replaces) a row; a row without a "machine" is this run's measurement."""
        row = {"machine": self.machine, **row}
        self.rows = [r for r in self.rows if row_key(r) != row_key(row)] + [row]
        if write:
            self.write()

    def add_check(self, check: dict, write: bool = True) -> None:
        self.checks = [c for c in self.checks if check_key(c) != check_key(check)] + [check]
        if write:
            self.write()

    def write(self) -> None:
        self.json_path.parent.mkdir(parents=True, exist_ok=True)
        order = {impl: i for i, impl in enumerate(IMPLS)}

        def domain(name: str) -> tuple:
            return (DOMAIN_ORDER.index(name) if name in DOMAIN_ORDER else 99, name)

        self.rows.sort(
            key=lambda r: (r["segments"], domain(r["domain"]), order[r["impl"]], r["batch"])
        )
        self.checks.sort(key=lambda c: (c["segments"], domain(c["domain"]), order[c["impl"]]))
        data = {
            "machines": self.machines(),
            "commands": self.commands,
            "rows": self.rows,
            "checks": self.checks,
        }
        self.json_path.write_text(json.dumps(data, indent=1) + "\n")
        if self.poses:
            np.savez_compressed(self.poses_path, **self.poses)
        self.md_path.write_text(self.markdown())

    def machines(self) -> list[dict]:
        """The distinct machines the rows were measured on, in row order."""
        seen: dict[str, dict] = {}
        for r in self.rows:
            seen.setdefault(json.dumps(r.get("machine", {}), sort_keys=True), r.get("machine", {}))
        return list(seen.values())

    def markdown(self) -> str:
        machines = self.machines()
        r0 = self.rows[0] if self.rows else {}
        m = machines[0] if len(machines) == 1 else {}

        def describe(m: dict) -> str:
            return (
                f"{m.get('accelerator')} ({m.get('backend')}), CPU {m.get('cpu')} x"
                f" {m.get('cpu_cores')} cores; jax {m.get('jax')}, mujoco {m.get('mujoco')},"
                f" mujoco-mjx {m.get('mujoco_mjx')}, warp-lang {m.get('warp_lang')}"
            )

        lines = [
            "# Rollout throughput: MJX-JAX and MJX-Warp beside MuJoCo C",
            "",
            *(
                [f"Machine: {describe(m)}."]
                if len(machines) == 1
                else ["Machines (rows from several runs; each row's is in the JSON):"]
                + [f"- {describe(x)}" for x in machines]
            ),
            f"Model: {r0.get('model', '')} {r0.get('overrides') or ''}; segment counts other than"
            " the committed 10 from `generate_xml(dataclasses.replace(ArmParams(),"
            " n_segments=N))`. Step at the model's timestep"
            f" ({r0.get('timestep_s', '?')} s), {r0.get('sim_seconds', '?')} simulated s per"
            " rollout. MJCF hashes (`Arm.model_hash`): "
            + ", ".join(
                f"{n} segments {h}"
                for n, h in sorted({(r["segments"], r.get("model_hash")) for r in self.rows})
            )
            + ".",
            "MuJoCo C: `mujoco.rollout`, "
            + (f"{m['cpu_cores']} threads" if m else "one thread per core of each row's machine")
            + f", batch"
            f" {r0.get('c_batch', '?')}, measured once per segment count and domain in each run.",
            "Compile: lower + XLA compile. First-call extra: the warm-up call's time less the"
            " timed call's (Warp builds and loads its CUDA kernels then; the kernel cache"
            " ~/.cache/warp was empty at the start of the run only for its first program)."
            " 'shared': the program compiled for the first domain served this one.",
            "Commands:",
            *[f"- `{c}`" for c in self.commands],
            "",
            "| segments | nv | domain | impl | batch | compile s | first-call extra s"
            " | MJX sim s/s | MJX steps/s | C sim s/s | MJX / C | Warp / JAX |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        jax_rate = {
            (r["segments"], r["domain"], r["batch"]): r["mjx_sim_s_per_s"]
            for r in self.rows
            if r["impl"] == "jax"
        }
        for r in self.rows:
            compile_s = "shared" if r.get("compile_shared") else f"{r['mjx_compile_s']:.1f}"
            base = jax_rate.get((r["segments"], r["domain"], r["batch"]))
            vs_jax = f"{r['mjx_sim_s_per_s'] / base:.2f}" if r["impl"] == "warp" and base else ""
            extra = max(0.0, r["mjx_first_call_s"] - r["mjx_wall_s"])
            lines.append(
                f"| {r['segments']} | {r['nv']} | {r['domain']} | {IMPL_NAMES[r['impl']]}"
                f" | {r['batch']} | {compile_s} | {extra:.1f} | {r['mjx_sim_s_per_s']:.0f}"
                f" | {r['mjx_steps_per_s']:.3g} | {r['c_sim_s_per_s']:.0f} | {r['mjx_over_c']}"
                f" | {vs_jax} |"
            )
        lines += [
            "",
            "Pose check: the same programs from rest, largest difference over every control"
            " period of the tip position (mm) and of the unit d3 director. MJX runs in float32,"
            " MuJoCo C in float64.",
            "",
            "| segments | domain | impl | programs | vs C: tip mm | vs C: d3 | vs MJX-JAX: tip mm"
            " | vs MJX-JAX: d3 |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for c in self.checks:
            vj = c.get("vs_jax") or {}
            lines.append(
                f"| {c['segments']} | {c['domain']} | {IMPL_NAMES[c['impl']]} | {c['programs']}"
                f" | {fmt(c['vs_c']['pos_mm'])} | {fmt(c['vs_c']['d3'])}"
                f" | {fmt(vj.get('pos_mm'))} | {fmt(vj.get('d3'))} |"
            )
        return "\n".join(lines) + "\n"


def parse_overrides(items: list[str]) -> dict:
    overrides = {}
    for item in items:
        field, value = item.split("=", 1)
        default = getattr(mjx_arm.ArmParams(), field)
        overrides[field] = (
            value.lower() in ("1", "true") if isinstance(default, bool) else type(default)(value)
        )
    return overrides


@dataclasses.dataclass(frozen=True)
class RunPlan:
    """What one run measures, read from its command line."""

    label: str
    """Name of the model variant (the table's model column)."""
    overrides: dict
    """ArmParams fields changed from the committed model (`--set`)."""
    domains: tuple[str, ...]
    """Domains timed; MJX compiles for the first and reuses the program where it can."""
    impls: tuple[str, ...]
    """MJX implementations, jax first: warp is checked against it."""
    batches: tuple[int, ...]
    """MJX batch sizes (trajectories), ascending; the smallest one's programs are pose-checked."""
    seconds: float
    """Simulated seconds per rollout."""
    c_batch: int
    """MuJoCo C batch (trajectories)."""
    n_check: int
    """Programs in the pose check."""

    @property
    def periods(self) -> int:
        """Control periods per rollout (10 Hz)."""
        return int(round(self.seconds * 10))


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m bench.throughput`` (the module docstring is its help)."""
    parser = cli_parser("bench.throughput", __doc__)
    parser.add_argument("--impl", nargs="+", choices=IMPLS, default=["jax"])
    parser.add_argument("--domains", nargs="+", default=["source", "constrained"])
    parser.add_argument("--segments", type=int, nargs="+", default=None, help="n_segments each")
    parser.add_argument("--batches", type=int, nargs="+", default=[1024, 4096, 16384, 65536])
    parser.add_argument("--c-batch", type=int, default=None, help="C batch (default 16/core)")
    parser.add_argument("--check-batch", type=int, default=64, help="programs in the pose check")
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated s per rollout")
    parser.add_argument("--quick", action="store_true", help="tiny CPU smoke run")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="generate the model from ArmParams with this field changed (repeatable)",
    )
    parser.add_argument(
        "--label",
        default="ArmParams() (models/softarm.xml at its 10 segments)",
        help="name of the model variant",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("runs/bench"),
        help="output folder (committed results: bench/results)",
    )
    parser.add_argument("--append", action="store_true", help="keep the results in --out")
    parser.add_argument("--report-only", action="store_true", help="only rewrite the tables")
    parser.add_argument("--merge", type=Path, nargs="*", default=[], help="more result json")
    return parser


def machine_info(cores: int) -> dict:
    """The accelerator, CPU and package versions a run's rows were measured with."""
    device = jax.devices()[0]
    return {
        "accelerator": f"{len(jax.devices())} x {device.device_kind}",
        "backend": jax.default_backend(),
        "cpu": cpu_model(),
        "cpu_cores": cores,
        "jax": jax.__version__,
        "mujoco": mujoco.__version__,
        "mujoco_mjx": version("mujoco-mjx"),
        "warp_lang": version("warp-lang"),
    }


def run_tag(overrides: dict, segments: list[int] | None) -> str:
    """The result files' name tag: the overrides, and "_segments" when --segments is given."""
    tag_parts = [f"{k}-{v}" for k, v in overrides.items()]
    if segments:  # not the counts themselves: runs of some counts append to one table
        tag_parts.append("segments")
    return "".join("_" + p for p in tag_parts)


def mjx_row(
    plan: RunPlan, impl: str, domain: str, arm: mjx_arm.Arm, n_seg: int, timing: dict, c: dict
) -> dict:
    """One table row: an MJX timing (`time_mjx`'s plus "batch" (padded), "compile_s",
    "compile_shared") beside MuJoCo C's rates `c` ("c_sim_s_per_s", "c_steps_per_s") in the
    same domain; rates are simulated s per wall s and physics steps per wall s."""
    padded, wall_s = timing["batch"], timing["wall_s"]
    sim_rate = padded * plan.seconds / wall_s
    return {
        "model": plan.label,
        "overrides": plan.overrides,
        "impl": impl,
        "domain": domain,
        "segments": n_seg,
        "nv": int(arm.mj_model.nv),
        "model_hash": arm.model_hash,
        "timestep_s": arm.timestep_s,
        "batch": padded,
        "sim_seconds": plan.seconds,
        "mjx_compile_s": round(timing["compile_s"], 2),
        "compile_shared": timing["compile_shared"],
        "mjx_first_call_s": round(timing["first_call_s"], 3),
        "mjx_wall_s": round(wall_s, 3),
        "mjx_sim_s_per_s": round(sim_rate, 1),
        "mjx_steps_per_s": round(padded * plan.periods * arm.n_substeps / wall_s),
        "c_batch": plan.c_batch,
        "c_sim_s_per_s": round(c["c_sim_s_per_s"], 1),
        "c_steps_per_s": round(c["c_steps_per_s"]),
        "mjx_over_c": round(sim_rate / c["c_sim_s_per_s"], 2),
    }


def pose_check(
    results: Results, poses: np.ndarray, n_seg: int, domain: str, impl: str, n_check: int
) -> dict:
    """Stores an implementation's check poses [n_check, T, 6] and compares them with MuJoCo C's
    (and, for warp, with MJX-JAX's of the same programs when this run has them)."""
    results.poses[f"seg{n_seg}_{domain}_{impl}"] = poses
    check = {
        "segments": n_seg,
        "domain": domain,
        "impl": impl,
        "programs": n_check,
        "vs_c": pose_diff(poses, results.poses[f"seg{n_seg}_{domain}_c"]),
    }
    jax_poses = results.poses.get(f"seg{n_seg}_{domain}_jax")
    if impl == "warp" and jax_poses is not None:
        if jax_poses.shape == poses.shape:
            check["vs_jax"] = pose_diff(poses, jax_poses)
    return check


def time_c_domains(plan: RunPlan, arms: dict, n_seg: int, results: Results) -> dict:
    """MuJoCo C's rates in each domain ({domain: {"c_sim_s_per_s", "c_steps_per_s"}}); stores
    its check poses (float64) of the first `n_check` programs."""
    check_commands = bench_programs(plan.n_check, plan.periods)
    rates = {}
    for d, arm in arms.items():
        c = time_c(arm, plan.c_batch, plan.periods)
        rates[d] = {
            "c_sim_s_per_s": c["batch"] * plan.seconds / c["wall_s"],
            "c_steps_per_s": c["batch"] * plan.periods * arm.n_substeps / c["wall_s"],
        }
        results.poses[f"seg{n_seg}_{d}_c"] = arm.rollout(check_commands, backend="c")
        print(f"segments {n_seg} {d}: MuJoCo C {rates[d]['c_sim_s_per_s']:.0f} sim s/s", flush=True)
    return rates


def time_impl(
    plan: RunPlan, impl: str, arms: dict, n_seg: int, c_rates: dict, results: Results
) -> None:
    """Times one MJX implementation at every batch size in every domain, adding a row each
    (and a pose check at the smallest batch); a domain whose model has the same signature as
    the last compiled one reuses its program ("compile_shared")."""
    models = {d: device_model(arm, impl) for d, arm in arms.items()}
    fn = batched_rollout(arms[plan.domains[0]], impl)
    for bi, batch in enumerate(plan.batches):
        commands, padded = sharded_commands(batch, plan.periods)
        compiled, compiled_for, compile_s = None, None, 0.0
        for d, arm in arms.items():
            rest = (jnp.asarray(arm.rest_qpos), jnp.asarray(arm.rest_qvel))
            shared = compiled is not None and same_signature(compiled_for, models[d])
            if not shared:
                start = time.perf_counter()
                compiled = fn.lower(models[d], commands, *rest).compile()
                compile_s = time.perf_counter() - start
                compiled_for = models[d]
            r = time_mjx(compiled, models[d], commands, rest, plan.n_check if bi == 0 else 0)
            r |= {"batch": padded, "compile_s": compile_s, "compile_shared": shared}
            row = mjx_row(plan, impl, d, arm, n_seg, r, c_rates[d])
            print(row, flush=True)
            if bi == 0:
                check = pose_check(results, r["poses"], n_seg, d, impl, plan.n_check)
                print(check, flush=True)
                results.add_check(check, write=False)
            results.add_row(row)


def time_segments(plan: RunPlan, n_segments: int | None, results: Results) -> None:
    """Times one chain (`n_segments`, None: the overrides' own count): MuJoCo C, then each MJX
    implementation, in every domain."""
    params = dataclasses.replace(mjx_arm.ArmParams(), **plan.overrides)
    if n_segments is not None:
        params = dataclasses.replace(params, n_segments=n_segments)
    xml = mjx_arm.generate_xml(params)
    arms = {d: mjx_arm.load(xml=xml, domain=d) for d in plan.domains}
    c_rates = time_c_domains(plan, arms, params.n_segments, results)
    for impl in plan.impls:
        time_impl(plan, impl, arms, params.n_segments, c_rates, results)


def main(argv: list[str] | None = None) -> None:
    """Runs ``python -m bench.throughput`` with `argv` (default: sys.argv[1:])."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.quick:
        args.batches, args.seconds = [8], 1.0
    overrides = parse_overrides(args.set)
    if args.segments and "n_segments" in overrides:
        parser.error("give --segments or --set n_segments=N, not both")
    cores = os.cpu_count() or 1
    plan = RunPlan(
        label=args.label,
        overrides=overrides,
        domains=tuple(args.domains),
        impls=tuple(impl for impl in IMPLS if impl in args.impl),
        batches=tuple(sorted(args.batches)),
        seconds=args.seconds,
        c_batch=args.c_batch or 16 * cores,
        n_check=max(1, min(args.check_batch, *args.batches)),
    )
    command = (
        ""
        if args.report_only
        else "python -m bench.throughput " + shlex.join(argv if argv is not None else sys.argv[1:])
    )
    tag = run_tag(overrides, args.segments)
    results = Results(args.out, tag, machine_info(cores), command, args.append or args.report_only)
    for path in args.merge:
        results.merge(path)
    if args.report_only:
        results.write()
        print(results.markdown())
        return
    for n in args.segments or [None]:
        time_segments(plan, n, results)
    print(results.markdown())


if __name__ == "__main__":
    main()
