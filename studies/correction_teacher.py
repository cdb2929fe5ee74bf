"""The teacher's half of `ccgan.distill --correction-translator`, scored in the reference rod: do
the commands of a teacher that tracks the corrected targets in the identified arm make the rod
trace the path? (issue 50 (d)).

On held-out programs of each family (`studies.rod_transfer.programs_by_family`, never a test
shape), in the arm identified from the rod's babbling: d0 = rod(u0) - arm(u0) along the
correction translator's commands u0 (which read the chain's D_s path), then the receding-horizon
tracker (`tracking.mpc`, MuJoCo C, the distillation's teacher settings: one step ahead, one
iteration, a planning copy of `--teacher-substeps`) plans towards

- x_chain: the chain's D_s path, uncorrected (what the committed data-only teacher tracks);
- x_chain - d0: corrected (`--correction-translator`'s teacher);
- x_rod - d0: corrected, towards the rod's own D_s path (`--source-simulator rod` with it).

Each plan's commands, u0's and stretch only's (the D_s program held k periods) run in the rod
in D_c (float64); X_err (cm, mean over each program) against the rod's D_s path, the target the
rod tables score.

    python -m studies.correction_teacher --teach-domain \\
        results/paper/chain_2026-11-28/run/identify_rod/identify.json \\
        --u0 studies/results/h200/rod_source/chain_source/translator_seed0.ckpt \\
        --n-shape-like 2 --n-other 2 \\
        --out studies/results/cpu/correction_teacher/correction_teacher_8
"""

from __future__ import annotations

import time

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan import load_translator
from ccgan.cli import cli_parser
from ccgan.distill.config import DistillConfig
from ccgan.distill.teacher import planner_config
from mjx_arm import domains
from studies.checks import parse_checked_args
from studies.rod_transfer import family_table, programs_by_family
from tracking import mpc
from tracking.metrics import position_error_cm


def main(argv=None) -> None:
    p = cli_parser("studies.correction_teacher", __doc__)
    p.add_argument("--teach-domain", required=True, help="the identified arm's Domain file")
    p.add_argument("--u0", required=True, help="the correction translator (a .ckpt)")
    p.add_argument("--model", default="models/softarm.xml")
    p.add_argument("--teacher-substeps", type=int, default=2)
    p.add_argument("--n-shape-like", type=int, default=1, help="per held-out split (2 splits)")
    p.add_argument("--n-other", type=int, default=1, help="per unseen family")
    p.add_argument("--duration-s", type=float, default=60.0)
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    if a.n_shape_like < 1 or a.n_other < 0 or a.duration_s <= 0 or a.teacher_substeps < 1:
        p.error("--n-shape-like and --teacher-substeps must be >= 1, --n-other >= 0")
    t0 = time.perf_counter()
    translator = load_translator(a.u0)
    k = translator.k
    arm_s = mjx_arm.load(a.model, "source")
    arm_c = mjx_arm.load(a.model, domains.read_domain_file(a.teach_domain).domain)
    rod_s, rod_c = mjx_arm.load_rod("source"), mjx_arm.load_rod("constrained")
    programs, families = programs_by_family(a.n_shape_like, a.n_other, a.duration_s)
    x_chain = arm_s.rollout(programs, backend="c")
    x_rod = rod_s.rollout(programs)
    u0 = np.stack([translator.translate(q, x)[0] for q, x in zip(programs, x_chain, strict=True)])
    d0 = rod_c.rollout(u0)[:, k - 1 :: k] - arm_c.rollout(u0, backend="c")[:, k - 1 :: k]
    print(f"d0 along u0: {len(programs)} programs ({time.perf_counter() - t0:.0f} s)")
    plan_arm = arm_c.planning_copy(a.teacher_substeps)
    cfg = planner_config(DistillConfig(horizon_steps=1, iterations=1))
    targets = {"teacher x_chain": x_chain, "teacher x_chain - d0": x_chain - d0}
    targets["teacher x_rod - d0"] = x_rod - d0
    commands = {"stretch": np.repeat(programs, k, axis=1), "u0 (translator)": u0}
    in_arm = {}
    for name, target in targets.items():
        commands[name], _ = mpc.track(plan_arm, target, k, programs, cfg)
        in_arm[name] = position_error_cm(
            arm_c.rollout(commands[name], backend="c")[:, k - 1 :: k], target
        ).mean(-1)
        print(f"{name}: planned ({time.perf_counter() - t0:.0f} s)")
    errors = {
        name: position_error_cm(rod_c.rollout(u)[:, k - 1 :: k], x_rod).mean(-1)
        for name, u in commands.items()
    }
    cols = list(errors)
    lines = [
        "",
        f"X_err (cm, mean over each program, then the family's) in the rod in D_c against the"
        f" rod's D_s path, k = {k}, {a.duration_s:g} s programs; the teachers plan in the arm"
        f" identified from the rod ({a.teach_domain}), a {a.teacher_substeps}-step planning copy;"
        f" d0 = rod - arm along u0 ({a.u0}). In the arm, each teacher's X_err against its own"
        " target: "
        + ", ".join(f"{n} {float(e.mean()):.3f} cm" for n, e in in_arm.items())
        + ".",
        "",
        "| family | programs | " + " | ".join(cols) + " | " + " | ".join(
            f"{c} / stretch" for c in cols[1:]
        ) + " |",
        "|---|---|" + "---|" * (2 * len(cols) - 1),
    ]  # fmt: skip
    by_family = family_table(families, errors)
    rows = {"all": by_family.pop("all")} | by_family  # "all" first
    for group, row in rows.items():
        lines.append(
            f"| {group} | {row['n']} | "
            + " | ".join(f"{row[c]:.3f}" for c in cols)
            + "".join(f" | {row[c] / row['stretch']:.2f}x" for c in cols[1:])
            + " |"
        )
    result = {
        "k": k,
        "families": families,
        "rows": rows,
        "teacher_x_err_in_arm_cm": {n: e.tolist() for n, e in in_arm.items()},
        "per_program_x_err_cm": {c: e.tolist() for c, e in errors.items()},
        "wall_s": time.perf_counter() - t0,
    }
    print("\n".join(lines))
    write_results(
        a.out,
        run_header("studies.correction_teacher", argv),
        result,
        "The corrected teacher's commands in the reference rod",
        lines,
    )


if __name__ == "__main__":
    main()
