"""Choose segment count and timestep: error against a fine reference beside simulation speed.

For each segment count and physics timestep, the same babbling programs run in MuJoCo C (both
domains). The error is the tip RMS distance to the same segment count at a 0.5 ms step (the
time-discretisation error) and to 20 segments at 0.5 ms (the space-discretisation error, which
`python -m mjx_arm.fidelity` measures properly against the Cosserat rod). Speed is MuJoCo C on one
thread, simulated seconds per wall second.

    python -m studies.timestep               # writes studies/results/cpu/timestep.{md,json}
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

import mjx_arm
from ccgan.cli import cli_parser
from mjx_arm import ArmParams, generate_xml
from mjx_arm.machine import cpu_model
from mjx_arm.programs import bench_programs
from studies.checks import parse_checked_args

REFERENCE_STEP_S = 0.0005


def single_thread_speed(arm: mjx_arm.Arm, seconds: float = 5.0) -> float:
    """Simulated seconds per wall second of one MuJoCo C thread under mid pressures."""
    data = mujoco.MjData(arm.mj_model)
    data.qpos[:] = arm.rest_qpos
    data.ctrl[:] = arm.chamber_controls.numpy(np.full(3, 1.5))
    steps = int(round(seconds / arm.timestep_s))
    start = time.perf_counter()
    mujoco.mj_step(arm.mj_model, data, nstep=steps)
    return seconds / (time.perf_counter() - start)


def rms_mm(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt((np.linalg.norm(a[..., :3] - b[..., :3], axis=-1) ** 2).mean()) * 1e3)


def main(argv: list[str] | None = None) -> None:
    parser = cli_parser("studies.timestep", __doc__)
    parser.add_argument("--segments", type=int, nargs="+", default=[5, 10, 20])
    parser.add_argument("--timesteps", type=float, nargs="+", default=[0.001, 0.002, 0.004, 0.005])
    parser.add_argument("--trajectories", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("runs/studies"),
        help="output folder (committed results: studies/results/cpu)",
    )
    args = parse_checked_args(parser, argv)
    commands = bench_programs(args.trajectories, int(round(args.seconds * 10)), seed=7)

    def load(n, dt, domain):
        params = dataclasses.replace(ArmParams(), n_segments=n, timestep_s=dt)
        return mjx_arm.load(xml=generate_xml(params), domain=domain)

    rows = []
    for domain in ("source", "constrained"):
        finest = load(20, REFERENCE_STEP_S, domain).rollout(commands, backend="c")
        for n in args.segments:
            reference = load(n, REFERENCE_STEP_S, domain).rollout(commands, backend="c")
            for dt in args.timesteps:
                row = {"domain": domain, "segments": n, "timestep_s": dt}
                try:
                    arm = load(n, dt, domain)
                    poses = arm.rollout(commands, backend="c")
                except mjx_arm.SimulationDivergedError:
                    row["diverged"] = True
                    rows.append(row)
                    continue
                row.update(
                    inertia_scale=round(arm.inertia_scale, 1),
                    rms_vs_same_segments_mm=round(rms_mm(poses, reference), 4),
                    rms_vs_20_segments_mm=round(rms_mm(poses, finest), 4),
                    tip_motion_rms_mm=round(rms_mm(finest, finest.mean(axis=(0, 1))), 3),
                    c_sim_s_per_s_one_thread=round(single_thread_speed(arm), 1),
                )
                rows.append(row)
                print(row, flush=True)

    args.out.mkdir(parents=True, exist_ok=True)
    machine = cpu_model()
    command = " ".join(["python -m studies.timestep", *sys.argv[1:]])
    (args.out / "timestep.json").write_text(
        json.dumps({"cpu": machine, "command": command, "rows": rows}, indent=1)
    )
    lines = [
        "# Segment count and timestep: error beside speed",
        "",
        f"CPU: {machine}. Command: `{command}`. {args.trajectories} babbling"
        f" programs of {args.seconds:g} s; errors are tip RMS distances over all 10 Hz poses.",
        "",
        "| domain | segments | timestep ms | inertia scale | RMS vs same at 0.5 ms, mm |"
        " RMS vs 20 seg at 0.5 ms, mm | tip motion RMS, mm | C sim s/s (1 thread) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r.get("diverged"):
            lines.append(
                f"| {r['domain']} | {r['segments']} | {r['timestep_s'] * 1e3:g} |"
                " diverged | | | | |"
            )
            continue
        lines.append(
            f"| {r['domain']} | {r['segments']} | {r['timestep_s'] * 1e3:g} | {r['inertia_scale']}"
            f" | {r['rms_vs_same_segments_mm']} | {r['rms_vs_20_segments_mm']} |"
            f" {r['tip_motion_rms_mm']} | {r['c_sim_s_per_s_one_thread']} |"
        )
    (args.out / "timestep.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
