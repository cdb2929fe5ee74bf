"""How coarse may the arm a planner uses be? A planning copy with fewer physics steps per control
period (`Arm.planning_copy`) beside the arm that scores, on the chain's held-out programs.

The chain's teachers and its oracle spend their time on sequential MJX physics steps (25 of 4 ms
per 0.1 s control period, `docs/chain.md`). The D_c media are so damped that a longer step
changes little, and a planner needs the arm's response, not its 4 ms detail. For each target
arm (D_c at k = 15, the aged arm at k = 25: the chain's distillation k) and each step count:

- **tip**: the chain's held-out programs (`ccgan.distill.held_out_programs` with the chain's
  settings) held k periods, rolled out in the copy and in the arm (MuJoCo C): mean and largest
  distance of the tip after each held step (mm);
- **teacher**: the chain's teacher (`tracking.mpc`, horizon 1, one Gauss-Newton iteration)
  planned in the copy on the first `--teacher-programs` of them, its commands scored in the arm
  itself: X_err (cm) and the planner's wall time (MuJoCo C on this host's cores).

    python -m studies.planning_arm --out studies/results/cpu/planning_arm
    python -m studies.planning_arm --substeps 25 5 --teacher-programs 1 --duration-s 5 --out /tmp/p

Writes OUT.md and OUT.json, rewritten after every row.
"""

from __future__ import annotations

import time

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan.cli import cli_parser
from ccgan.distill import DistillConfig, held_out_programs
from studies.checks import parse_checked_args
from tracking import mpc
from tracking.metrics import position_error_cm

#: The chain's distillation k per target arm (experiments/paper.json).
CHAIN_K = {"constrained": 15, "aged": 25}


def tip_distance_mm(plan_arm, arm, programs: np.ndarray, k: int) -> dict:
    """Mean and largest distance (mm) between the tips of `plan_arm` and `arm` after each held
    step of programs [B, T, 3] (bar) held k periods, from rest, in MuJoCo C."""
    held = np.repeat(programs, k, axis=1)
    a = plan_arm.rollout(held, backend="c")[:, k - 1 :: k, :3]
    b = arm.rollout(held, backend="c")[:, k - 1 :: k, :3]
    d = 1e3 * np.linalg.norm(a - b, axis=-1)
    return {"tip_mean_mm": float(d.mean()), "tip_max_mm": float(d.max())}


def teacher_in_copy(plan_arm, arm, arm_s, programs: np.ndarray, k: int) -> dict:
    """The chain's teacher planned in `plan_arm` for programs [B, T, 3] (bar), scored in `arm`:
    {"teacher_x_err_cm" (mean over programs and steps), "teacher_wall_s"}."""
    targets = arm_s.rollout(programs, backend="c")
    cfg = mpc.MpcConfig(horizon_steps=1, iterations=1)
    t0 = time.perf_counter()
    commands, _ = mpc.track(plan_arm, targets, k, programs, cfg, progress=True)
    wall = time.perf_counter() - t0
    poses = arm.rollout(commands, backend="c")[:, k - 1 :: k]
    return {
        "teacher_x_err_cm": float(position_error_cm(poses, targets).mean()),
        "teacher_wall_s": wall,
    }


def main(argv=None) -> None:
    p = cli_parser("studies.planning_arm", __doc__)
    p.add_argument("--model", default="models/softarm.xml", help="the arm's MJCF")
    p.add_argument("--domains", nargs="+", default=list(CHAIN_K), choices=list(CHAIN_K))
    p.add_argument("--substeps", type=int, nargs="+", default=[25, 10, 5, 2, 1])
    p.add_argument(
        "--teacher-programs",
        type=int,
        default=4,
        help="held-out programs the teacher plans (the first ones; 0: no teacher rows)",
    )
    p.add_argument("--duration-s", type=float, default=60.0, help="program length (s)")
    p.add_argument("--out", required=True, help="output prefix (writes .md and .json)")
    a = parse_checked_args(p, argv)
    if min(a.substeps) < 1 or a.teacher_programs < 0:
        p.error("--substeps must be >= 1 and --teacher-programs >= 0")
    chain = DistillConfig(n_train=1, batch_size=1, n_val=8, n_val_full=8, duration_s=a.duration_s)
    programs = held_out_programs(chain)  # the chain's 16 held-out programs (its train: unused)
    if a.teacher_programs > len(programs):
        p.error(f"--teacher-programs: the chain holds out {len(programs)} programs")
    arm_s = mjx_arm.load(a.model, "source")
    header = run_header("studies.planning_arm", argv)
    body = [
        "",
        f"{len(programs)} held-out programs of {a.duration_s:g} s (the chain's); the teacher on"
        f" the first {a.teacher_programs}. Tip: the copy against the arm, each program held k"
        " periods. Teacher X_err: its commands scored in the arm itself.",
        "",
        "| arm | k | steps per period | timestep ms | inertia scale | tip mean mm | tip max mm"
        " | teacher X_err cm | teacher wall s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    rows = []
    for domain in a.domains:
        k, arm = CHAIN_K[domain], mjx_arm.load(a.model, domain)
        for n in a.substeps:
            plan_arm = arm.planning_copy(n)
            row = {"domain": domain, "k": k, "substeps": n}
            row |= {"timestep_ms": 1e3 * plan_arm.timestep_s, "inertia": plan_arm.inertia_scale}
            row |= tip_distance_mm(plan_arm, arm, programs, k)
            if a.teacher_programs:
                row |= teacher_in_copy(plan_arm, arm, arm_s, programs[: a.teacher_programs], k)
            rows.append(row)
            teacher = (
                f"{row['teacher_x_err_cm']:.4f} | {row['teacher_wall_s']:.0f}"
                if a.teacher_programs
                else "- | -"
            )
            body.append(
                f"| {domain} | {k} | {n} | {row['timestep_ms']:g} | {row['inertia']:.0f} |"
                f" {row['tip_mean_mm']:.4f} | {row['tip_max_mm']:.3f} | {teacher} |"
            )
            print(body[-1], flush=True)
            write_results(
                a.out, header, {"rows": rows}, "Planning copies of the arm: error and cost", body
            )


if __name__ == "__main__":
    main()
