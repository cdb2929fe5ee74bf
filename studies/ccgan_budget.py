"""Does the study's reduced budget rank CCGAN-GP settings as a longer training does?

`ccgan.tune` trains each trial 40 epochs. This study takes the trials of one batch of the stored
study (one structure, so they train as one vmapped program), adds the paper's own weights and
learning rates, trains them again from the same seed for `--epochs`, and scores every setting in
the D_c simulator every `--stretch-every` epochs, exactly as the study scores a trial. It reports:
  - the study's value beside the rerun's at the study's budget (the same computation, another
    process and machine: a check of determinism);
  - the rank correlation (Spearman) of the study's values with the scores at each later epoch;
  - whether a longer training takes any setting below stretch only at its k.

    python -m studies.ccgan_budget --study-dir studies/results/h100/ccgan_study --batch 0 \\
        --epochs 200 --stretch-every 40 --out studies/results/h100

Held-out programs only: the five shapes are never used.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys
import time
from pathlib import Path

import jax
import numpy as np
import optuna

import mjx_arm
from ccgan import checkpoint
from ccgan import data as data_lib
from ccgan.batch import BatchTrainer
from ccgan.config import TrainConfig
from ccgan.forward import ForwardConfig
from ccgan.sim_choice import SimulatorChoice
from ccgan.tune import TUNED
from mjx_arm.machine import cpu_model
from studies.checks import parse_checked_args

#: The paper's numbers for the searched fields (the authors' code's weights, the paper's rates).
PAPER = {
    "lambda_cycle": 10.0,
    "lambda_identity": 1.0,
    "lambda_feedback": 5.0,
    "lr_generator": 1e-4,
    "lr_critic": 2e-4,
}


def spearman(a, b) -> float:
    """Spearman's rank correlation of two equal-length sequences (no ties expected)."""
    ra = np.argsort(np.argsort(a))
    rb = np.argsort(np.argsort(b))
    return float(np.corrcoef(ra, rb)[0, 1])


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m studies.ccgan_budget", description=__doc__)
    p.add_argument("--study-dir", required=True, help="a tools/device/ccgan_study.sh folder")
    p.add_argument("--study-name", default="ccgan_paper_scale")
    p.add_argument("--batch", type=int, default=0, help="the stored batch whose trials to rerun")
    p.add_argument("--epochs", type=int, default=200)
    p.add_argument("--stretch-every", type=int, default=40)
    p.add_argument("--model", default="models/softarm.xml")
    p.add_argument("--max-trials", type=int, default=None, help="the batch's first N trials only")
    p.add_argument("--out", required=True)
    a = parse_checked_args(p, argv)
    folder = Path(a.study_dir)
    study = optuna.load_study(study_name=a.study_name, storage=f"sqlite:///{folder / 'study.db'}")
    trials = [t for t in study.trials if t.user_attrs.get("batch") == a.batch][: a.max_trials]
    if not trials:
        p.error(f"no trials of batch {a.batch} in {folder / 'study.db'}")
    report = json.loads((folder / "report" / "tune.json").read_text())
    base = TrainConfig.from_dict(report["base_config"])
    structure = {n: trials[0].params[n] for n in TUNED if n not in PAPER}
    configs = [dataclasses.replace(base, **t.params) for t in trials]
    configs.append(dataclasses.replace(base, **structure, **PAPER))
    configs = [
        dataclasses.replace(c, epochs=a.epochs, stretch_every=a.stretch_every) for c in configs
    ]
    names = [f"trial {t.number}" for t in trials] + ["paper weights"]

    babble = folder / "babble"
    arm_c = mjx_arm.load(a.model, domain="constrained")
    d_s, d_c = data_lib.read_translation_files(
        [babble / f"source_{s}.npz" for s in ("train", "val")],
        [babble / f"constrained_{s}.npz" for s in ("train", "val")],
        arm_c.model_hash,
    )
    data = data_lib.prepare(
        d_s.pressures_bar, d_s.poses, d_c.pressures_bar, d_c.poses, configs[0].window_length,
        base.n_val, None, bounds=data_lib.union_bounds(d_s.bounds, d_c.bounds),
    )  # fmt: skip
    fc_params, _ = checkpoint.load(folder / "forward" / "forward_c.ckpt")
    judge = SimulatorChoice(arm_c, data, configs[0])
    stretch_only = dict(zip(base.hold_factors, judge.stretch_only_errors().tolist(), strict=True))
    trainer = BatchTrainer(data, fc_params, judge, ForwardConfig().model)

    scores: dict[int, list] = {}

    def on_choice(epoch, index, k, error_cm, errors_cm):
        scores[int(epoch)] = [(int(k[i, 0]), float(error_cm[i, 0])) for i in range(len(index))]
        return np.ones(len(index), bool)

    start = time.perf_counter()
    result = trainer.train(configs, (report["seed"],), on_choice)
    wall = time.perf_counter() - start
    scores[a.epochs] = [
        (int(k), float(e)) for k, e in zip(result.k[:, 0], result.error_cm[:, 0], strict=True)
    ]

    study_values = [t.value for t in trials]
    rows = []
    for i, name in enumerate(names):
        rows.append(
            {
                "setting": name,
                "params": configs[i].to_dict() if i == len(trials) else trials[i].params,
                "study_value_cm": study_values[i] if i < len(trials) else None,
                "study_k": trials[i].user_attrs.get("k") if i < len(trials) else None,
                "scores": {e: {"k": s[i][0], "error_cm": s[i][1]} for e, s in scores.items()},
            }
        )
    done = [i for i, v in enumerate(study_values) if v is not None]
    rank = {
        e: spearman([study_values[i] for i in done], [scores[e][i][1] for i in done])
        for e in sorted(scores)
    }
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = {
        "command": "python -m studies.ccgan_budget "
        + shlex.join(sys.argv[1:] if argv is None else argv),
        "machine": f"{cpu_model()} ({jax.devices()[0].device_kind})",
        "wall_time_s": wall,
        "structure": structure,
        "seed": report["seed"],
        "stretch_only_cm": stretch_only,
        "spearman_vs_study": rank,
        "rows": rows,
    }
    (out / "ccgan_budget.json").write_text(json.dumps(summary, indent=2) + "\n")
    epochs = sorted(scores)
    lines = [
        "# CCGAN-GP: the study's budget against a longer training",
        "",
        f"Machine: {summary['machine']}; {wall:.0f} s wall time. Study: `{folder}`, batch"
        f" {a.batch} ({structure}), seed {report['seed']}.",
        f"Every setting scored in the D_c simulator every {a.stretch_every} epochs as"
        " `ccgan.tune` scores a trial (held-out programs' first"
        f" {base.k_choice_seconds:g} s, best k of {base.hold_factors}).",
        "Stretch only (the untranslated held-out programs): "
        + ", ".join(f"k = {k}: {v:.3f} cm" for k, v in stretch_only.items()),
        "",
        "| setting | study (40 epochs) | " + " | ".join(f"epoch {e}" for e in epochs) + " |",
        "|---|---|" + "---|" * len(epochs),
    ]
    for r in rows:
        study_cell = (
            "" if r["study_value_cm"] is None else f"{r['study_value_cm']:.3f} (k {r['study_k']})"
        )
        cells = [f"{r['scores'][e]['error_cm']:.3f} (k {r['scores'][e]['k']})" for e in epochs]
        lines.append(f"| {r['setting']} | {study_cell} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Spearman rank correlation of the study's values with the scores at each epoch: "
        + ", ".join(f"epoch {e}: {v:.2f}" for e, v in rank.items()),
        "",
    ]
    (out / "ccgan_budget.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
