"""Hyperparameter search for CCGAN-GP with Optuna (TPE, no pruning), stored in SQLite.

`python -m ccgan.tune --source S_train.npz S_val.npz --constrained C_train.npz C_val.npz
--n-trials 20 --epochs 20` searches lambda_cycle, lambda_feedback, both learning rates and the
window length, minimising the validation tracking error (cm) that `ccgan.train` logs as
`val_error_cm`: G_c translates the held-out D_s trajectories, F_c runs them open loop, and the
error at the best hold factor k is the trial's value. Every trial trains one seed for `--epochs`
epochs from the same key, so trials differ only in their hyperparameters.

The study lives in an SQLite file (`--storage`, `--study-name`); rerunning the same command adds
`--n-trials` more trials to it. The sampler's seed is `--seed` plus the number of trials already
stored, so a resumed study does not replay the first trials' random start-up points. F_c is
trained once per window length and cached beside the database, or read from
`--forward-workdir/forward_c.ckpt` (as `ccgan.train` writes it) for every window length.

Writes `tune.md`, `tune.json` and `tune_history.png` into `--report-dir`.
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

import jax
import jax.numpy as jnp
import numpy as np
import optuna

from ccgan import checkpoint
from ccgan import data as data_lib
from ccgan import forward as forward_lib
from ccgan.cli import (
    add_config_flags,
    add_data_flags,
    check_output_dir,
    cli_parser,
    config_from_args,
    data_from_args,
)
from ccgan.config import TrainConfig, check_forward_config
from ccgan.train import data_fingerprint
from ccgan.trainer import make_trainer
from mjx_arm.dataset import DatasetError
from mjx_arm.machine import cpu_model
from tracking.config import ConfigError, check_fields

#: The TrainConfig fields the search sets; every other field comes from the base config.
TUNED = ("lambda_cycle", "lambda_feedback", "lr_generator", "lr_critic", "window_length")
#: The tuned fields that enter training only as numbers (not shapes): traced, not compiled in.
CONTINUOUS = TUNED[:4]


@dataclasses.dataclass(frozen=True)
class SearchSpace:
    """Ranges of the searched hyperparameters (continuous ones are sampled log-uniformly)."""

    #: Range (low, high) of the cycle-loss weight lambda_c (paper code: 10).
    lambda_cycle: tuple[float, float] = (1.0, 100.0)
    #: Range of the feedback-loss weight lambda_f (paper code: 5).
    lambda_feedback: tuple[float, float] = (0.5, 50.0)
    #: Range of the generator learning rate (paper: 1e-4).
    lr_generator: tuple[float, float] = (1e-5, 1e-3)
    #: Range of the critic learning rate (paper: 2e-4).
    lr_critic: tuple[float, float] = (1e-5, 1e-3)
    #: Control steps per training window to choose from (each >= 2, as TrainConfig's).
    window_lengths: tuple[int, ...] = (5, 10, 20)

    def __post_init__(self):
        """Refuses empty or inverted ranges (ConfigError names the field)."""
        check_fields(self, above={n: 0 for n in CONTINUOUS}, at_least={"window_lengths": 2})
        for name in CONTINUOUS:
            value = getattr(self, name)
            if len(value) != 2 or value[0] > value[1]:
                raise ConfigError(name, f"must be a range (low, high) with low <= high: {value}")


def suggest(trial: optuna.Trial, space: SearchSpace) -> dict:
    """Samples one point of `space`: {field of TUNED: value}."""
    params = {
        name: trial.suggest_float(name, *getattr(space, name), log=True) for name in CONTINUOUS
    }
    params["window_length"] = int(trial.suggest_categorical("window_length", space.window_lengths))
    return params


def make_validation_run(
    config: TrainConfig,
    data: data_lib.TranslationData,
    forward_c_params,
    forward_model=None,
):
    """A jitted `run(key, hparams) -> (metrics {name: [epochs]}, errors per k [K])`.

    `run` is `make_train(config with hparams, ...)(key)` (same key split) followed by
    `Trainer.validation_errors` on the final state. The CONTINUOUS fields of `hparams`
    ({name: float scalar}) are traced arguments, so one compilation serves every trial with the
    same window length (the window length sets array shapes).
    """

    @jax.jit
    def run(key, hparams):
        trainer = make_trainer(
            dataclasses.replace(config, **hparams), data, forward_c_params, forward_model
        )
        init_key, run_key = jax.random.split(key)
        state = trainer.init(init_key)
        state, metrics = trainer.run_epochs(state, run_key, jnp.int32(0), config.epochs)
        return metrics, trainer.validation_errors(state)

    return run


def validation_error_cm(run, config: TrainConfig, seed: int = 0) -> tuple[float, int, dict]:
    """Trains one seed with `run` (from `make_validation_run`) at config's CONTINUOUS values.

    Returns:
      (min over hold_factors of the mean held-out tip error in cm, the k reaching it,
       {metric: value at the last epoch}).
    """
    hparams = {n: jnp.float32(getattr(config, n)) for n in CONTINUOUS}
    metrics, errs = jax.device_get(run(jax.random.PRNGKey(seed), hparams))
    best = int(np.argmin(errs))
    last = {name: float(v[-1]) for name, v in metrics.items() if name != "val_error_cm"}
    return float(errs[best]), int(config.hold_factors[best]), last


class ForwardCache:
    """F_c variables per window length: from a workdir's forward_c.ckpt, or trained and cached."""

    def __init__(self, fconf: forward_lib.ForwardConfig, cache_dir: Path, workdir=None):
        self.fconf, self.cache_dir = fconf, Path(cache_dir)
        self.workdir = None if workdir is None else Path(workdir)
        self._params: dict[int, object] = {}

    def __call__(self, data: data_lib.TranslationData, window_length: int):
        if window_length in self._params:
            return self._params[window_length]
        conf = dataclasses.asdict(self.fconf)
        if self.workdir is not None:
            # F_c maps one control period to the next, so any window length's F_c serves; only
            # the network shape must match.
            params, _ = checkpoint.load(self.workdir / "forward_c.ckpt", expect={"config": conf})
        else:
            path = self.cache_dir / f"forward_c_L{window_length}.ckpt"
            meta = {"config": conf, "data": data_fingerprint(data)}
            if not path.exists():
                params, hist, metrics = forward_lib.train_forward(
                    self.fconf, data.constrained, data.bounds
                )
                checkpoint.save(path, params, meta | {"metrics": metrics})
                print(f"forward_c L={window_length}: {json.dumps(metrics)}", flush=True)
            params, _ = checkpoint.load(path, expect=meta)
        self._params[window_length] = params
        return params


def run_study(
    base: TrainConfig,
    arrays: tuple,
    storage: str | Path,
    study_name: str,
    n_trials: int,
    space: SearchSpace = SearchSpace(),
    fconf: forward_lib.ForwardConfig = forward_lib.ForwardConfig(),
    forward_workdir=None,
    seed: int = 0,
    timeout_s: float | None = None,
) -> optuna.Study:
    """Adds `n_trials` TPE trials to the study `study_name` in the SQLite file `storage`.

    Args:
      base: every TrainConfig field not in TUNED (epochs is the per-trial budget).
      arrays: (pressures_s, poses_s, pressures_c, poses_c, bounds or None), as
        `ccgan.data.read_translation_files` reads them.
      storage: SQLite file (created with its folder; F_c caches go beside it).
      study_name: the study's name in that file.
      n_trials: trials to run now (on top of those stored).
      space: search ranges.
      fconf: F_c settings (its network must match a `forward_workdir` checkpoint).
      forward_workdir: a `ccgan.train` workdir whose forward_c.ckpt to use, or None.
      seed: sampler seed (offset by the trials stored) and the training seed of every trial.
      timeout_s: start no new trial after this many seconds (None: run all n_trials).

    Returns:
      The study.

    Raises:
      ValueError: n_trials < 1, or timeout_s given and not > 0.
    """
    if n_trials < 1:
        raise ValueError(f"n_trials must be >= 1, got {n_trials}")
    if timeout_s is not None and not timeout_s > 0:
        raise ValueError(f"timeout_s must be > 0 (or None), got {timeout_s}")
    check_forward_config(fconf)
    storage = Path(storage)
    storage.parent.mkdir(parents=True, exist_ok=True)
    study = optuna.create_study(
        study_name=study_name,
        storage=f"sqlite:///{storage.resolve()}",
        direction="minimize",
        load_if_exists=True,
    )
    study.sampler = optuna.samplers.TPESampler(seed=seed + len(study.trials))
    ps, xs, pc, xc, bounds = arrays
    cache_dir = storage.parent / f"{storage.stem}_{study_name}_cache"
    forward_c = ForwardCache(fconf, cache_dir, forward_workdir)
    runs: dict[int, object] = {}

    def objective(trial: optuna.Trial) -> float:
        params = suggest(trial, space)
        config = dataclasses.replace(base, **params)
        length = config.window_length
        if length not in runs:
            data = data_lib.prepare(
                ps, xs, pc, xc, length, config.n_val, config.stride, bounds=bounds
            )
            runs[length] = make_validation_run(config, data, forward_c(data, length), fconf.model)
        err, k, last = validation_error_cm(runs[length], config, seed)
        trial.set_user_attr("k", k)
        trial.set_user_attr("last_epoch", {m: v for m, v in last.items() if math.isfinite(v)})
        return err

    def report(study: optuna.Study, trial: optuna.trial.FrozenTrial) -> None:
        secs = (trial.datetime_complete - trial.datetime_start).total_seconds()
        value = "failed" if trial.value is None else f"{trial.value:.4f} cm"
        params = " ".join(f"{n}={_fmt(trial.params[n])}" for n in TUNED)
        best = study.best_value if any(t.value is not None for t in study.trials) else float("nan")
        print(
            f"trial {trial.number}: {value} (k={trial.user_attrs.get('k')}) {params} "
            f"[{secs:.1f} s, best {best:.4f} cm]",
            flush=True,
        )

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study.optimize(objective, n_trials=n_trials, timeout=timeout_s, callbacks=[report])
    return study


def _n_stored(storage, study_name: str) -> int:
    """Trials already stored in the study (0 if the file or the study does not exist yet)."""
    if not Path(storage).exists():
        return 0
    url = f"sqlite:///{Path(storage).resolve()}"
    names = [s.study_name for s in optuna.get_all_study_summaries(url)]
    return (
        len(optuna.load_study(study_name=study_name, storage=url).trials)
        if study_name in names
        else 0
    )


def _fmt(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def summary(study: optuna.Study, extra: dict) -> dict:
    """The study as a JSON-able dict: best trial, every trial, and `extra` (machine, command...)."""
    trials = []
    for t in study.trials:
        secs = None
        if t.datetime_complete and t.datetime_start:
            secs = (t.datetime_complete - t.datetime_start).total_seconds()
        trials.append(
            {
                "number": t.number,
                "state": t.state.name,
                "value_cm": t.value,
                "params": t.params,
                "k": t.user_attrs.get("k"),
                "duration_s": secs,
                "last_epoch": t.user_attrs.get("last_epoch"),
            }
        )
    done = [t for t in study.trials if t.value is not None]
    best = None
    if done:
        b = study.best_trial
        best = {"number": b.number, "value_cm": b.value, "params": b.params, "k": b.user_attrs["k"]}
    return extra | {"study_name": study.study_name, "best": best, "trials": trials}


def write_report(summ: dict, report_dir: str | Path, note: str = "") -> dict[str, Path]:
    """Writes tune.md, tune.json and tune_history.png; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(report_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        k: out / f"tune{s}" for k, s in (("md", ".md"), ("json", ".json"), ("png", "_history.png"))
    }
    paths["json"].write_text(json.dumps(summ | {"note": note}, indent=2) + "\n")

    done = [t for t in summ["trials"] if t["value_cm"] is not None]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    if done:
        x = [t["number"] for t in done]
        y = [t["value_cm"] for t in done]
        ax.plot(x, y, "o", label="trial")
        ax.step(x, np.minimum.accumulate(y), where="post", label="best so far")
    ax.set_xlabel("trial")
    ax.set_ylabel("validation tracking error (cm)")
    ax.set_title(f"Optuna TPE: {summ['study_name']}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(paths["png"], dpi=120)
    plt.close(fig)

    lines = [f"# CCGAN-GP hyperparameter search: {summ['study_name']}", ""]
    if note:
        lines += [note, ""]
    lines += [
        f"- Command: `{summ['command']}`",
        f"- Machine: {summ['machine']} ({summ['device_kind']})",
        f"- This run: {summ['new_trials']} trials in {summ['wall_time_s']:.0f} s wall time; "
        f"study: {len(summ['trials'])} trials in `{summ['storage']}`",
        f"- Budget per trial: {summ['base_config']['epochs']} epochs, one seed; objective: "
        "held-out tracking error through F_c at the best k (cm), as `val_error_cm` in "
        "`ccgan.train`",
        f"- Sampler: TPE, seed {summ['seed']} (+ trials already stored), no pruning",
        "",
    ]
    if summ["best"]:
        b = summ["best"]
        lines += [f"Best: trial {b['number']}, {b['value_cm']:.4f} cm at k = {b['k']}", ""]
        lines += ["| parameter | value |", "|---|---|"]
        lines += [f"| {n} | {_fmt(b['params'][n])} |" for n in TUNED]
        lines += [""]
    head = ["trial", "state", "error (cm)", "k", *TUNED, "time (s)"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for t in summ["trials"]:
        row = [
            str(t["number"]),
            t["state"],
            "" if t["value_cm"] is None else f"{t['value_cm']:.4f}",
            str(t["k"]),
            *(_fmt(t["params"].get(n, "")) for n in TUNED),
            "" if t["duration_s"] is None else f"{t['duration_s']:.1f}",
        ]
        lines.append("| " + " | ".join(row) + " |")
    lines += ["", f"![optimisation history]({paths['png'].name})", ""]
    paths["md"].write_text("\n".join(lines))
    return paths


def build_parser() -> argparse.ArgumentParser:
    """The options of `python -m ccgan.tune`."""
    parser = cli_parser("ccgan.tune", __doc__)
    add_data_flags(parser)
    parser.add_argument("--storage", default="runs/tune/tune.db", help="SQLite file")
    parser.add_argument("--study-name", default="ccgan", help="the study's name in --storage")
    parser.add_argument("--n-trials", type=int, default=10, help="trials to add in this run")
    parser.add_argument("--seed", type=int, default=0, help="sampler and training seed")
    parser.add_argument("--timeout-s", type=float, default=None, help="no new trial after this")
    parser.add_argument(
        "--report-dir", default="runs/tune", help="folder for tune.md, .json, _history.png"
    )
    parser.add_argument(
        "--forward-workdir", default=None, help="reuse DIR/forward_c.ckpt (a ccgan.train workdir)"
    )
    parser.add_argument("--note", default="", help="a paragraph put at the top of tune.md")
    add_config_flags(parser, forward_lib.ForwardConfig, prefix="forward-")
    add_config_flags(parser, SearchSpace, prefix="space-")
    add_config_flags(parser, TrainConfig, skip=TUNED)
    # The trial's value is the F_c error at the best k, so k is chosen through F_c in training too.
    parser.set_defaults(epochs=5, k_choice="forward")
    return parser


def main(argv=None) -> None:
    """CLI: `python -m ccgan.tune --source S.npz... --constrained C.npz... [--n-trials N ...]`.

    Every option and data file is checked before any trial runs (usage errors, status 2).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    base = config_from_args(parser, args, TrainConfig, skip=TUNED)
    fconf = config_from_args(
        parser, args, forward_lib.ForwardConfig, prefix="forward-", check=check_forward_config
    )
    space = config_from_args(parser, args, SearchSpace, prefix="space-")
    if args.n_trials < 1:
        parser.error(f"--n-trials must be >= 1, got {args.n_trials}")
    if args.timeout_s is not None and not args.timeout_s > 0:
        parser.error(f"--timeout-s must be > 0, got {args.timeout_s}")
    check_output_dir(parser, "--report-dir", args.report_dir)
    check_output_dir(parser, "--storage's folder", Path(args.storage).parent)
    if Path(args.storage).is_dir():
        parser.error(f"--storage {args.storage} is a folder, not an SQLite file")
    if args.forward_workdir is not None:
        fc = Path(args.forward_workdir) / "forward_c.ckpt"
        if not fc.is_file():
            parser.error(f"--forward-workdir {args.forward_workdir}: no {fc}")
    d_s, d_c = data_from_args(parser, args)
    try:
        split_notes = data_lib.check_slot_splits(base.n_val, d_s, d_c)
    except DatasetError as err:
        parser.error(str(err))
    for note in split_notes:
        print(f"NOTE: {note}", file=sys.stderr)
    bounds = data_lib.union_bounds(d_s.bounds, d_c.bounds)

    start = time.perf_counter()
    n_before = _n_stored(args.storage, args.study_name)
    study = run_study(
        base,
        (d_s.pressures_bar, d_s.poses, d_c.pressures_bar, d_c.poses, bounds),
        args.storage,
        args.study_name,
        args.n_trials,
        space,
        fconf,
        args.forward_workdir,
        args.seed,
        args.timeout_s,
    )
    extra = {
        "command": "python -m ccgan.tune " + shlex.join(sys.argv[1:] if argv is None else argv),
        "machine": cpu_model(),
        "device_kind": jax.devices()[0].device_kind,
        "wall_time_s": time.perf_counter() - start,
        "new_trials": len(study.trials) - n_before,
        "storage": str(args.storage),
        "seed": args.seed,
        "base_config": base.to_dict(),
        "forward_config": dataclasses.asdict(fconf),
        "search_space": dataclasses.asdict(space),
    }
    paths = write_report(summary(study, extra), args.report_dir, args.note)
    print("wrote", ", ".join(str(p) for p in paths.values()))


if __name__ == "__main__":
    main()
