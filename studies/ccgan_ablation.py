"""Which of CCGAN-GP's losses matter: each removed in turn, three seeds, scored in the simulator.

One call trains one batch: the paper's weights and rates ("full") and the same with the
adversarial, cycle, identity or feedback weight set to 0, each with every seed, as one vmapped
program (`ccgan.batch.BatchTrainer`: the weights are traced numbers). A batch fixes the rest:
  - the generator: the paper's LSTM over windows (default), the authors' per-sample generator
    (`--gen-per-sample`: their code trains on sequences of length 1) or a residual one;
  - the data: the study folder's paper-scale babbling (50 + 3 programs of 60 s), or MJX-scale
    babbling (`--gan-data FOLDER`: its training programs, with the study folder's held-out
    programs kept as the held-out set, so every batch is scored on the same programs);
  - the F_c of the feedback loss (`--forward-c`: the study folder's, or one of
    `studies.forward_data`, normalised with the same pose bounds);
  - the setting the variants start from: the paper's, or a study's best trial
    (`--setting-from STORAGE:STUDY`, its structure and numbers; the removed loss's weight is 0).
Every `--stretch-every` epochs each member's hold factor k is chosen on the held-out D_s
programs in the D_c simulator (`ccgan.sim_choice`) and its error there at that k is recorded.
The report gives, per variant, the mean and spread over seeds of the final error and of the error
at the scored epoch with the lowest error (a stop on held-out error: it picks the epoch on the
same programs it reports, so it flatters), beside stretch only at the same k.

    python -m studies.ccgan_ablation --study-dir studies/results/h100/ccgan_study \\
        --label "paper G, paper data" --epochs 100 --stretch-every 25 \\
        --out studies/results/h100/ccgan_ablation

Each call adds its batch to `ablation.json` (a label already there is replaced) and rewrites
`ablation.md`. Held-out programs only: the five shapes are never used.
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

from ccgan import checkpoint
from ccgan import data as data_lib
from ccgan.batch import BatchTrainer
from ccgan.config import K_CHOICE_PROGRAMS, TrainConfig
from ccgan.forward import ForwardConfig
from ccgan.sim_choice import SimulatorChoice, describe_programs
from mjx_arm.atomic import write_atomically
from mjx_arm.dataset import load_dataset
from mjx_arm.machine import cpu_model
from studies.checks import parse_checked_args
from studies.study_folder import StudyFolder, load_study_folder

#: The variants of one batch: the paper's weights, and each loss removed.
VARIANTS = {
    "full": {},
    "no adversarial": {"lambda_adversarial": 0.0},
    "no cycle": {"lambda_cycle": 0.0},
    "no identity": {"lambda_identity": 0.0},
    "no feedback": {"lambda_feedback": 0.0},
}


def gan_data(study: StudyFolder, folder: str | None, window_length: int):
    """The CCGAN's data: the study folder's babbling, or FOLDER's training programs with the
    study folder's held-out programs appended as the held-out set (same bounds either way)."""
    if folder is None:
        return study.translation_data(window_length, study.n_val)
    arrays = []
    for domain, d in (("source", study.d_s), ("constrained", study.d_c)):
        ds = load_dataset(Path(folder) / f"{domain}_train.npz", study.arm_c.model_hash)
        if ds.n_steps != d.pressures_bar.shape[1]:
            raise ValueError(
                f"{folder}: {domain} programs of {ds.n_steps} steps, the study folder's held-out"
                f" programs {d.pressures_bar.shape[1]}: babble them with the same --duration"
            )
        val = slice(len(d.pressures_bar) - study.n_val, None)
        arrays += [
            np.concatenate([ds.pressures_bar, d.pressures_bar[val]]),
            np.concatenate([ds.poses, d.poses[val]]),
        ]
    return data_lib.prepare(*arrays, window_length, study.n_val, None, bounds=study.bounds)


def load_forward_c(path: Path, study: StudyFolder):
    """(F_c variables, its `ForwardModel`) from a checkpoint normalised with the study's bounds.

    Raises:
      ValueError: the checkpoint records other pose bounds (its poses would mean other places).
    """
    params, meta = checkpoint.load(path)
    stored = meta.get("bounds")
    if stored is not None:
        b = data_lib.PoseBounds.from_dict(stored)
        if not (np.allclose(b.low, study.bounds.low) and np.allclose(b.high, study.bounds.high)):
            raise ValueError(f"{path}: F_c normalised with other pose bounds than {study.folder}")
    fields = {f.name for f in dataclasses.fields(ForwardConfig)}
    conf = ForwardConfig(**{k: v for k, v in meta.get("config", {}).items() if k in fields})
    return params, conf.model


def best_setting(base: TrainConfig, spec: str, parser) -> TrainConfig:
    """`base` with the parameters of the best trial of `STORAGE:STUDY` (`ccgan.tune`'s)."""
    import optuna

    from ccgan.tune import storage_url

    storage, sep, name = spec.rpartition(":")
    if not sep or not storage or not name:
        parser.error(f"--setting-from {spec!r}: expected STORAGE:STUDY")
    try:
        best = optuna.load_study(study_name=name, storage=storage_url(storage)).best_trial
    except (KeyError, ValueError) as err:
        parser.error(f"--setting-from {spec}: {err}")
    print(f"setting of trial {best.number} ({best.value:.4f} cm): {best.params}", flush=True)
    return dataclasses.replace(base, **best.params)


def summarise(result, seeds, stretch_only: dict, variants=tuple(VARIANTS)) -> dict:
    """Per variant (in the order trained): final and best-epoch errors and k per seed, and the
    scoring history."""
    out = {}
    for c, name in enumerate(variants):
        hist = [
            {
                "epoch": h["epoch"],
                "k": h["k"][list(h["index"]).index(c)].tolist(),
                "error_cm": h["error_cm"][list(h["index"]).index(c)].tolist(),
            }
            for h in result.history
            if c in h["index"]
        ]
        errors = np.asarray([h["error_cm"] for h in hist])  # [E, S]
        best = errors.argmin(0)
        out[name] = {
            "final_cm": result.error_cm[c].tolist(),
            "final_k": result.k[c].tolist(),
            "stretch_only_at_final_k_cm": [stretch_only[int(k)] for k in result.k[c]],
            "best_cm": errors[best, np.arange(len(seeds))].tolist(),
            "best_epoch": [hist[i]["epoch"] for i in best],
            "history": hist,
        }
    return out


def write_report(out: Path, report: dict) -> None:
    """ablation.json and ablation.md (one table over every batch)."""
    write_atomically(
        out / "ablation.json", lambda f: f.write(json.dumps(report, indent=2).encode())
    )
    lines = [
        "# CCGAN-GP ablation on held-out programs",
        "",
        "Each row: one variant, its seeds trained in one vmapped batch, scored on the study"
        " batch's held-out D_s programs (named under its title) held k periods from rest"
        " in the D_c simulator (MuJoCo C), at the k each member chose among the hold factors."
        " Final: after the last epoch; best: the scored epoch with the lowest error (picked on"
        " the same programs). Mean +- std over seeds (cm); ratio: final / stretch only at the"
        " same k.",
        "",
    ]
    for label, b in report["batches"].items():
        lines += [
            f"## {label}",
            "",
            f"`{b['command']}`; {b['machine']}; {b['wall_s']:.0f} s. Data: {b['data']}; F_c:"
            f" {b['forward_c']}; {b['config']['epochs']} epochs, scored every"
            f" {b['config']['stretch_every']} on {describe_programs(b['config'])}. Stretch only: "
            + ", ".join(f"{v:.3f} cm at k = {k}" for k, v in b["stretch_only_cm"].items())
            + ".",
            "",
            "| variant | final (cm) | k chosen | best epoch's (cm) | ratio to stretch only |",
            "|---|---|---|---|---|",
        ]
        for name, v in b["variants"].items():
            final, best = np.asarray(v["final_cm"]), np.asarray(v["best_cm"])
            ratio = final / np.asarray(v["stretch_only_at_final_k_cm"])
            lines.append(
                f"| {name} | {final.mean():.3f} +- {final.std():.3f} |"
                f" {', '.join(str(k) for k in v['final_k'])} |"
                f" {best.mean():.3f} +- {best.std():.3f} | {ratio.mean():.3f} |"
            )
        lines.append("")
    (out / "ablation.md").write_text("\n".join(lines))


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m studies.ccgan_ablation", description=__doc__)
    p.add_argument("--study-dir", required=True, help="a tools/device/ccgan_study.sh folder")
    p.add_argument("--label", required=True, help="this batch's name in the report")
    p.add_argument("--forward-c", default=None, help="F_c checkpoint (default: the study's)")
    p.add_argument("--gan-data", default=None, help="a babbling folder (MJX-scale data)")
    p.add_argument("--epochs", type=int, default=100)
    p.add_argument("--stretch-every", type=int, default=25)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--hold-factors", type=int, nargs="+", default=[10, 15, 20])
    p.add_argument("--k-choice-seconds", type=float, default=20.0)
    p.add_argument(
        "--variants",
        nargs="+",
        choices=list(VARIANTS),
        default=list(VARIANTS),
        help="the variants to train (default: all); quote names with spaces",
    )
    p.add_argument("--k-choice-programs", choices=K_CHOICE_PROGRAMS, default="babbling")
    p.add_argument("--k-choice-n-programs", type=int, default=12)
    p.add_argument("--window-length", type=int, default=10)
    p.add_argument("--critic-steps", type=int, default=1)
    p.add_argument("--gen-per-sample", action="store_true")
    p.add_argument("--gen-residual", action="store_true")
    p.add_argument(
        "--setting-from",
        default=None,
        metavar="STORAGE:STUDY",
        help="start from the best trial of an Optuna study (an SQLite file or journal .log)",
    )
    p.add_argument("--small", action="store_true", help="tiny networks (tests)")
    p.add_argument("--model", default="models/softarm.xml")
    p.add_argument("--out", required=True)
    a = parse_checked_args(p, argv)
    small = dict(gen_hidden=4, gen_fc=8, critic_features=(4,) * 5, batch_size=4) if a.small else {}
    try:
        base = TrainConfig(
            epochs=a.epochs, stretch_every=a.stretch_every, hold_factors=tuple(a.hold_factors),
            k_choice_seconds=a.k_choice_seconds, window_length=a.window_length,
            k_choice_programs=a.k_choice_programs, k_choice_n_programs=a.k_choice_n_programs,
            critic_steps=a.critic_steps, gen_per_sample=a.gen_per_sample,
            gen_residual=a.gen_residual, **small,
        )  # fmt: skip
    except ValueError as err:
        p.error(str(err))
    if a.setting_from is not None:
        base = best_setting(base, a.setting_from, p)
    study = load_study_folder(a.study_dir, a.model)
    base = dataclasses.replace(base, n_val=study.n_val)  # the study folder's held-out programs
    forward_path = Path(a.forward_c or Path(a.study_dir) / "forward" / "forward_c.ckpt")
    try:
        data = gan_data(study, a.gan_data, base.window_length)
        fc_params, fc_model = load_forward_c(forward_path, study)
    except (ValueError, OSError, checkpoint.CheckpointError) as err:
        p.error(str(err))
    configs = [dataclasses.replace(base, **VARIANTS[name]) for name in a.variants]
    judge = SimulatorChoice(study.arm_c, data, base, source_arm=study.arm_s)
    stretch_only = dict(zip(base.hold_factors, judge.stretch_only_errors().tolist(), strict=True))
    start = time.perf_counter()
    result = BatchTrainer(data, fc_params, judge, fc_model).train(configs, a.seeds)
    wall = time.perf_counter() - start

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "ablation.json"
    report = json.loads(path.read_text()) if path.exists() else {"batches": {}}
    report["batches"][a.label] = {
        "command": "python -m studies.ccgan_ablation "
        + shlex.join(sys.argv[1:] if argv is None else argv),
        "machine": f"{cpu_model()} ({jax.devices()[0].device_kind})",
        "wall_s": wall,
        "data": a.gan_data or f"{study.folder}/babble (paper scale)",
        "n_train_programs": [
            int(len(data.source.train) * base.stride // data.source.val.shape[1]),
            int(len(data.constrained.train) * base.stride // data.constrained.val.shape[1]),
        ],
        "forward_c": str(forward_path),
        "seeds": a.seeds,
        "config": base.to_dict(),
        "setting_from": a.setting_from,
        "stretch_only_cm": {str(k): v for k, v in stretch_only.items()},
        "variants": summarise(result, a.seeds, stretch_only, a.variants),
    }
    write_report(out, report)
    print((out / "ablation.md").read_text())


if __name__ == "__main__":
    main()
