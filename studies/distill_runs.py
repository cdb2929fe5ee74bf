"""Distillation runs side by side on their own held-out programs: the translators, their teacher
and stretch only, from each run's `distill.json`.

`ccgan.distill` picks each seed's iterate on held-out 60 s programs and records their X_err and
its teacher's. Since it also records stretch only (the D_s commands held k periods), a run's
file holds every number of its row. For a run written before that, this study rebuilds the
held-out programs from the run's settings (`ccgan.distill.held_out_programs`: never a test
shape), simulates their D_s targets and stretch only in MuJoCo C on this host, and says so in
the table. Runs with the same held-out programs, domain and k share that computation.

    python -m studies.distill_runs --runs studies/results/h100/issue30/distill_k10 \\
        studies/results/h200/issue30/distill_k15 ... --out studies/results/cpu/issue30/distill_runs
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan.cli import cli_parser
from ccgan.distill import DistillConfig, held_out_programs, window_and_whole_x_err_cm
from studies.checks import parse_checked_args


def stretch_only_cm(run: dict) -> float:
    """X_err (cm, mean over the held-out programs' whole length) of stretch only on a run's
    held-out programs, in MuJoCo C on the run's arm and domain."""
    config = DistillConfig(**run["config"])
    k = run["history"]["k"]
    programs = held_out_programs(config)
    arm_s = mjx_arm.load(run["model"], "source")
    arm_c = mjx_arm.load(run["model"], run["domain"])
    if arm_c.model_hash != run["model_hash"]:
        raise ValueError(
            f"{run['model']} is now the arm {arm_c.model_hash}; the run was on {run['model_hash']}"
        )
    targets = arm_s.rollout(programs, backend="c")
    _, whole = window_and_whole_x_err_cm(arm_c, programs, k, targets, window=1)
    return float(whole)


def row(folder: Path, run: dict, stretch_cm: float, stretch_source: str) -> dict:
    """One run's numbers: its settings, each seed's kept held-out X_err, teacher, stretch only."""
    history, config = run["history"], DistillConfig(**run["config"])
    best = np.asarray(history["best_val_x_err_cm"])
    teacher = history["teacher_val_x_err_cm"]["whole"]
    return {
        "run": str(folder),
        "machine": run["machine"],
        "domain": run["domain"],
        "k": history["k"],
        "training_programs": config.n_train_programs,
        "babbling_programs": config.n_train_babble,
        "held_out_programs": len(held_out_programs(config)),
        "epochs": history["epochs_run"],
        "optimiser_steps": history["epochs_run"] * (config.n_train_programs // config.batch_size),
        "seeds_cm": best.tolist(),
        "best_epoch": history["best_epoch"],
        "start_cm": history["val_x_err_cm_before"],
        "teacher_cm": teacher,
        "stretch_cm": stretch_cm,
        "stretch_source": stretch_source,
        "over_teacher": (best / teacher).tolist(),
        "over_stretch": (best / stretch_cm).tolist(),
    }


def main(argv=None) -> None:
    p = cli_parser("studies.distill_runs", __doc__)
    p.add_argument("--runs", nargs="+", required=True, help="ccgan.distill output folders")
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    runs = []
    for folder in map(Path, a.runs):
        try:
            runs.append((folder, json.loads((folder / "distill.json").read_text())))
        except (OSError, ValueError) as err:
            p.error(f"--runs {folder}: no readable distill.json ({err})")
    rows, computed = [], {}
    for folder, run in runs:
        recorded = run["history"].get("stretch_val_x_err_cm")
        if recorded is not None:
            rows.append(row(folder, run, recorded["whole"], "recorded by the run"))
            continue
        config = DistillConfig(**run["config"])
        key = json.dumps(
            [
                [config.n_val, config.n_val_full, config.n_val_babble],
                [config.duration_s, config.seed],
                [run["model_hash"], run["domain"], run["history"]["k"]],
            ]
        )
        if key not in computed:
            print(f"stretch only for {folder} ({run['domain']}, k = {run['history']['k']})")
            computed[key] = stretch_only_cm(run)
        rows.append(row(folder, run, computed[key], "this study, MuJoCo C"))

    def spread(values) -> str:
        return f"{np.mean(values):.3f} ± {np.std(values):.3f}"

    body = [
        "",
        "Held-out X_err (cm) over whole 60 s programs in MuJoCo C; each seed's kept iterate.",
        "",
        "| run | domain | k | training programs (babbling) | epochs (steps) | seeds | mean ± std"
        " | teacher | / teacher | stretch only | / stretch only |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        seeds = " / ".join(f"{x:.3f}" for x in r["seeds_cm"])
        ratio_t = "-".join(f"{x:.2f}" for x in (min(r["over_teacher"]), max(r["over_teacher"])))
        ratio_s = "-".join(f"{x:.2f}" for x in (min(r["over_stretch"]), max(r["over_stretch"])))
        body.append(
            f"| {r['run']} | {r['domain']} | {r['k']} | {r['training_programs']}"
            f" ({r['babbling_programs']}) | {r['epochs']} ({r['optimiser_steps']}) | {seeds}"
            f" | {spread(r['seeds_cm'])} | {r['teacher_cm']:.3f} | {ratio_t}"
            f" | {r['stretch_cm']:.3f} | {ratio_s} |"
        )
    body += ["", "Where each run trained, and where its stretch only comes from:", ""]
    body += [f"- {r['run']}: {r['machine']}; stretch only: {r['stretch_source']}" for r in rows]
    write_results(
        a.out,
        run_header("studies.distill_runs", argv),
        {"rows": rows},
        "Distillation runs on their held-out programs",
        body,
    )
    print(Path(a.out).with_suffix(".md").read_text())


if __name__ == "__main__":
    main()
