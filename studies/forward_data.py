"""How F_c's open-loop error over held commands falls with data, babbling holds and training.

The feedback loss runs F_c open loop over D_c commands held k periods, and F_c trained on the
paper-scale babbling (holds of 0.5-3 s, 50 programs, teacher-forced on 10-step windows) is off by
9-12 cm there (`studies/results/cpu/forward_open_loop.md`). This study trains F_c again with
three levers, alone and together, and scores every F_c the same way:
  - more data: the first N programs of a babbling set (MJX-scale data: hundreds of programs);
  - babbling whose holds let the slow D_c arm settle (`mjx_arm.babble --hold-min/--hold-max`);
  - open-loop training on windows as long as the horizon F_c predicts in the feedback loss
    (`ccgan.forward.ForwardConfig.open_loop`; 10 steps x k = 15 = 150 periods).

Every F_c is normalised with the study folder's pose bounds (the CCGAN data's), so any of them
can serve the CCGAN's feedback loss (`studies.ccgan_ablation --forward-c`). Each trains a fixed
number of optimiser steps, so a larger data set is not also a longer training. The score: the
held-out D_s programs of the study folder (60 s) held k periods from rest in the D_c simulator
(MuJoCo C) and through F_c in open loop from the rest pose; X_err at every k-th pose (what a
translator is scored on), over every period, and the largest.

    python -m studies.forward_data --study-dir studies/results/h100/ccgan_study \\
        --data long=runs/babble_long --runs paper:50:teacher:10 long:800:open:150 \\
        --steps 4000 --out studies/results/h100/forward_data

A run is written as soon as it is scored (`forward_data.json`, its `forward_c.ckpt`); a rerun
with the same --out skips the runs already there. Held-out programs only: the five shapes are
never used.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import shlex
import sys
import time
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from ccgan import checkpoint
from ccgan import data as data_lib
from ccgan.forward import ForwardConfig, make_train_forward
from mjx_arm.atomic import write_atomically
from mjx_arm.dataset import load_dataset
from mjx_arm.machine import cpu_model
from studies.checks import parse_checked_args
from studies.forward_open_loop import open_loop_cm
from studies.study_folder import StudyFolder, load_study_folder
from tracking import held, metrics

#: Training modes of a run: teacher-forced (the paper's) or on F's own predictions.
MODES = ("teacher", "open")


class Run(NamedTuple):
    """One F_c to train: `data` names a babbling set, `n` its first programs, `mode` one of
    `MODES`, `window` the training window (control steps)."""

    data: str
    n: int
    mode: str
    window: int

    @property
    def name(self) -> str:
        return f"{self.data}_n{self.n}_{self.mode}{self.window}"

    @classmethod
    def parse(cls, text: str) -> Run:
        """`DATA:N:MODE:WINDOW`, e.g. `long:800:open:150`.

        Raises:
          ValueError: malformed, an unknown mode, or N or WINDOW below 1.
        """
        parts = text.split(":")
        if len(parts) != 4:
            raise ValueError(f"{text!r}: expected DATA:N:MODE:WINDOW, e.g. long:800:open:150")
        data, n, mode, window = parts
        if mode not in MODES:
            raise ValueError(f"{text!r}: mode must be one of {MODES}, got {mode!r}")
        run = cls(data, int(n), mode, int(window))
        if run.n < 1 or run.window < 1:
            raise ValueError(f"{text!r}: N and WINDOW must be at least 1")
        return run


def training_split(
    pressures_bar: np.ndarray, poses: np.ndarray, bounds, window: int
) -> data_lib.DomainSplit:
    """All of one babbling set's programs as training windows of `window` steps (none held out:
    the study scores on the study folder's held-out D_s programs instead)."""
    return data_lib.split_domain(pressures_bar, poses, bounds, window, n_val=0, name="D_c")


def epochs_for(n_windows: int, batch_size: int, steps: int) -> int:
    """Epochs that give at least `steps` optimiser steps of `batch_size` windows."""
    per_epoch = max(1, n_windows // min(batch_size, n_windows))
    return max(1, math.ceil(steps / per_epoch))


class Truth:
    """The held-out programs held k periods in the D_c simulator (MuJoCo C), cached per k."""

    def __init__(self, study: StudyFolder):
        self.study = study
        self._poses: dict[int, np.ndarray] = {}

    def __call__(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(commands [V, T k, 3] bar, D_c poses [V, T k, 6])."""
        commands = held.stretch(self.study.heldout_programs_bar, k)
        if k not in self._poses:
            self._poses[k] = np.asarray(self.study.arm_c.rollout(commands, backend="c"))
        return commands, self._poses[k]


def score(model, params, study: StudyFolder, truth: Truth, hold_factors) -> list[dict]:
    """F_c's open-loop X_err (cm) over the held-out programs at each k: at every k-th pose,
    over every period, and the largest."""
    rows = []
    for k in hold_factors:
        commands, poses_c = truth(k)
        pred = open_loop_cm(model, params, commands, study.bounds, study.arm_c.rest_pose())
        every = metrics.position_error_cm(pred, poses_c)
        kept = metrics.position_error_cm(held.every_kth(pred, k), held.every_kth(poses_c, k))
        rows.append(
            {
                "k": k,
                "kept_cm": float(kept.mean()),
                "every_period_cm": float(every.mean()),
                "max_cm": float(every.max()),
            }
        )
    return rows


def train_run(run: Run, sets: dict, study: StudyFolder, fconf: ForwardConfig, steps: int, seed):
    """Trains one run's F_c; returns (variables, its config, loss history [E], windows)."""
    pressures, poses = sets[run.data]
    if run.n > len(pressures):
        raise ValueError(f"{run.name}: {run.data} has {len(pressures)} programs, not {run.n}")
    split = training_split(pressures[: run.n], poses[: run.n], study.bounds, run.window)
    n_windows = len(split.train)
    conf = dataclasses.replace(
        fconf,
        open_loop=run.mode == "open",
        epochs=epochs_for(n_windows, fconf.batch_size, steps),
    )
    params, hist = jax.block_until_ready(
        jax.jit(make_train_forward(conf, split))(jax.random.PRNGKey(seed))
    )
    return params, conf, np.asarray(hist), n_windows


def read_sets(study: StudyFolder, named_folders: list[str], parser) -> dict:
    """{name: (pressures [N, T, 3] bar, poses [N, T, 6])}: "paper" is the study folder's D_c
    training babbling; each NAME=FOLDER adds FOLDER/constrained_train.npz of the same arm."""
    paper_n = len(study.d_c.pressures_bar) - study.n_val
    sets = {"paper": (study.d_c.pressures_bar[:paper_n], study.d_c.poses[:paper_n])}
    for item in named_folders:
        name, sep, folder = item.partition("=")
        if not sep or not name or not folder:
            parser.error(f"--data {item!r}: expected NAME=FOLDER")
        ds = load_dataset(Path(folder) / "constrained_train.npz", study.arm_c.model_hash)
        sets[name] = (ds.pressures_bar, ds.poses)
    return sets


def write_report(out: Path, summary: dict) -> None:
    """forward_data.json, forward_data.md and, with two or more N, forward_data.png."""
    write_atomically(
        out / "forward_data.json", lambda f: f.write(json.dumps(summary, indent=2).encode())
    )
    ks = summary["hold_factors"]
    lines = [
        "# F_c in open loop over held commands: data, holds and training",
        "",
        f"Command: `{summary['command']}`. Machine: {summary['machine']}.",
        f"Score: the {summary['n_programs']} held-out D_s programs of `{summary['study_dir']}`"
        f" ({summary['seconds_per_program']:g} s), each command held k periods from rest, in the"
        " D_c simulator (MuJoCo C) and through F_c in open loop. X_err (cm) at every k-th pose;"
        " in brackets, over every period / the largest.",
        f"Every F_c: {summary['steps']} optimiser steps of"
        f" {summary['forward_config']['batch_size']}"
        f" windows, seed {summary['seed']}. Babbling sets: "
        + "; ".join(f"{n}: {d}" for n, d in summary["sets"].items())
        + ".",
        "",
        "| run | data | N | training | window | "
        + " | ".join(f"k = {k}" for k in ks)
        + " | train s |",
        "|---|---|---|---|---|" + "---|" * len(ks) + "---|",
    ]
    for r in summary["runs"]:
        cells = [
            f"{s['kept_cm']:.2f} ({s['every_period_cm']:.2f} / {s['max_cm']:.1f})"
            for s in r["scores"]
        ]
        lines.append(
            f"| {r['name']} | {r['data']} | {r['n']} | {r['mode']} | {r['window']} | "
            + " | ".join(cells)
            + f" | {r['train_s']:.0f} |"
        )
    (out / "forward_data.md").write_text("\n".join(lines) + "\n")
    groups: dict[tuple, list] = {}
    for r in summary["runs"]:
        groups.setdefault((r["data"], r["mode"], r["window"]), []).append(r)
    if not any(len(g) > 1 for g in groups.values()):
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(ks), figsize=(4 * len(ks), 3.4), squeeze=False)
    for ax, k in zip(axes[0], ks, strict=True):
        for (data, mode, window), g in sorted(groups.items()):
            g = sorted(g, key=lambda r: r["n"])
            y = [next(s["kept_cm"] for s in r["scores"] if s["k"] == k) for r in g]
            ax.plot([r["n"] for r in g], y, "o-", label=f"{data}, {mode} {window}")
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set(xscale="log", yscale="log", xlabel="programs (N)", title=f"k = {k}")
    axes[0][0].set_ylabel("F_c open-loop X_err (cm)")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "forward_data.png", dpi=120)
    plt.close(fig)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m studies.forward_data", description=__doc__)
    p.add_argument("--study-dir", required=True, help="babble/ of a ccgan_study.sh run")
    p.add_argument("--data", nargs="*", default=[], metavar="NAME=FOLDER", help="babbling sets")
    p.add_argument("--runs", nargs="+", required=True, metavar="DATA:N:MODE:WINDOW")
    p.add_argument("--steps", type=int, default=4000, help="optimiser steps per F_c")
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--hold-factors", type=int, nargs="+", default=[1, 10, 15, 20])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", default="models/softarm.xml")
    p.add_argument("--out", required=True)
    a = parse_checked_args(p, argv)
    try:
        runs = list(dict.fromkeys(Run.parse(t) for t in a.runs))  # each once, in order
    except ValueError as err:
        p.error(f"--runs: {err}")
    if a.steps < 1 or a.batch_size < 1 or min(a.hold_factors) < 1:
        p.error("--steps, --batch-size and --hold-factors must be at least 1")
    study = load_study_folder(a.study_dir, a.model)
    sets = read_sets(study, a.data, p)
    for run in runs:
        if run.data not in sets:
            p.error(f"--runs {run.name}: no babbling set {run.data!r} (--data NAME=FOLDER)")
    fconf = ForwardConfig(batch_size=a.batch_size)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = {
        "command": "python -m studies.forward_data "
        + shlex.join(sys.argv[1:] if argv is None else argv),
        "machine": f"{cpu_model()} ({jax.devices()[0].device_kind})",
        "study_dir": str(study.folder),
        "n_programs": study.n_val,
        "seconds_per_program": study.heldout_programs_bar.shape[1] / 10.0,
        "hold_factors": a.hold_factors,
        "steps": a.steps,
        "seed": a.seed,
        "forward_config": dataclasses.asdict(fconf),
        "sets": {n: f"{len(s[0])} programs of {s[0].shape[1] / 10:g} s" for n, s in sets.items()},
        "runs": [],
    }
    stored = out / "forward_data.json"
    if stored.exists():
        summary["runs"] = [
            r
            for r in json.loads(stored.read_text()).get("runs", [])
            if (out / r["name"] / "forward_c.ckpt").exists()
        ]
    done = {r["name"] for r in summary["runs"]}
    truth = Truth(study)
    for run in runs:
        if run.name in done:
            print(f"{run.name}: scored already ({out / run.name})", flush=True)
            continue
        start = time.perf_counter()
        params, conf, hist, n_windows = train_run(run, sets, study, fconf, a.steps, a.seed)
        train_s = time.perf_counter() - start
        scores = score(conf.model, params, study, truth, a.hold_factors)
        record = run._asdict() | {
            "name": run.name,
            "windows": n_windows,
            "epochs": conf.epochs,
            "train_s": train_s,
            "final_loss": float(hist[-1]),
            "scores": scores,
        }
        checkpoint.save(
            out / run.name / "forward_c.ckpt",
            params,
            {"config": dataclasses.asdict(conf), "bounds": study.bounds.to_dict(), "run": record},
        )
        summary["runs"].append(record)
        write_report(out, summary)
        print(json.dumps(record), flush=True)
    write_report(out, summary)
    print((out / "forward_data.md").read_text())


if __name__ == "__main__":
    main()
