"""The CCGAN-GP study: Optuna over the training settings, each trial scored in the D_c simulator.

`python -m ccgan.tune --source S_train.npz S_val.npz --constrained C_train.npz C_val.npz
--model models/softarm.xml --forward-workdir DIR --n-trials 64 --trials-per-batch 16` searches the
loss weights (adversarial is the reference, 1), both learning rates, the window length, the critic
steps and the generator kind. A trial's value is the held-out tracking error in the target-domain
simulator: its G_c translates the held-out D_s programs, each command is held k periods from rest
in the D_c arm, every k-th pose is compared with the D_s poses, and k is chosen there from
`--hold-factors` (`ccgan.sim_choice`, as the authors' code chooses it). The five shapes are never
used.

Trials run in batches (`--trials-per-batch`): Optuna's ask/tell hands out a batch, whose settings
differ only in numbers, so they train as one vmapped program (`ccgan.batch`). Each batch takes
one structural combination (window length, critic steps, generator kind), in turn; TPE samples
the numbers with the structure fixed (`optuna.samplers.PartialFixedSampler`). Every
`--stretch-every` epochs each live trial is scored and reported; the median pruner stops those
below the median of the finished trials at that epoch, which spares their simulator rollouts.

The study lives in Optuna's own storage (`--storage`: an SQLite file, or with a `.log` suffix a
journal file that processes on several machines can share), so trials can run in several
processes or on several machines; rerunning the command adds `--n-trials` more. The sampler's seed
is `--seed` plus the trials stored. Writes `tune.md`, `tune.json` and `tune_history.png` into
`--report-dir`.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import shlex
import sys
import time
import warnings
from pathlib import Path

import jax
import numpy as np
import optuna

from ccgan import checkpoint
from ccgan import data as data_lib
from ccgan import forward as forward_lib
from ccgan.batch import BatchTrainer
from ccgan.cli import (
    add_config_flags,
    add_data_flags,
    check_output_dir,
    cli_parser,
    config_from_args,
    data_from_args,
)
from ccgan.config import TrainConfig, check_forward_config
from ccgan.sim_choice import SimulatorChoice, describe_programs
from ccgan.train import data_fingerprint
from mjx_arm.dataset import DatasetError
from mjx_arm.machine import cpu_model
from tracking.config import ConfigError, check_fields

#: The TrainConfig fields sampled as numbers (log-uniform); they train vmapped in one batch.
NUMERIC = ("lambda_cycle", "lambda_identity", "lambda_feedback", "lr_generator", "lr_critic")
#: The TrainConfig fields that set a structure; one combination per batch.
STRUCTURAL = ("window_length", "critic_steps", "gen_residual")
#: Every TrainConfig field the search sets; every other field comes from the base config.
TUNED = NUMERIC + STRUCTURAL


@dataclasses.dataclass(frozen=True)
class SearchSpace:
    """Ranges of the searched settings (numbers log-uniform, structures from lists)."""

    #: Range (low, high) of the cycle-loss weight lambda_c (paper code: 10).
    lambda_cycle: tuple[float, float] = (0.1, 100.0)
    #: Range of the identity-loss weight (paper: 1; the authors' code: none).
    lambda_identity: tuple[float, float] = (0.01, 100.0)
    #: Range of the feedback-loss weight lambda_f (paper code: 5).
    lambda_feedback: tuple[float, float] = (0.1, 100.0)
    #: Range of the generator learning rate (paper: 1e-4).
    lr_generator: tuple[float, float] = (1e-5, 1e-3)
    #: Range of the critic learning rate (paper: 2e-4).
    lr_critic: tuple[float, float] = (1e-5, 1e-3)
    #: Control steps per training window to choose from (each >= 2, as TrainConfig's).
    window_lengths: tuple[int, ...] = (10, 20)
    #: Critic updates per generator update to choose from.
    critic_steps: tuple[int, ...] = (1, 5)
    #: Generator kinds to choose from: False the paper's, True the residual one.
    gen_residual: tuple[bool, ...] = (False, True)

    def __post_init__(self):
        """Refuses empty or inverted ranges (ConfigError names the field)."""
        check_fields(
            self,
            above={n: 0 for n in NUMERIC},
            at_least={"window_lengths": 2, "critic_steps": 1},
        )
        for name in NUMERIC:
            value = getattr(self, name)
            if len(value) != 2 or value[0] > value[1]:
                raise ConfigError(name, f"must be a range (low, high) with low <= high: {value}")
        if not self.gen_residual:
            raise ConfigError("gen_residual", "needs at least one generator kind")

    def structures(self) -> list[dict]:
        """Every structural combination, {field of STRUCTURAL: value}, in a fixed order."""
        values = (self.window_lengths, self.critic_steps, self.gen_residual)
        return [dict(zip(STRUCTURAL, v, strict=True)) for v in itertools.product(*values)]


def suggest(trial: optuna.Trial, space: SearchSpace) -> dict:
    """Samples one point of `space`: {field of TUNED: value}."""
    params = {name: trial.suggest_float(name, *getattr(space, name), log=True) for name in NUMERIC}
    params["window_length"] = int(trial.suggest_categorical("window_length", space.window_lengths))
    params["critic_steps"] = int(trial.suggest_categorical("critic_steps", space.critic_steps))
    params["gen_residual"] = bool(trial.suggest_categorical("gen_residual", space.gen_residual))
    return params


def storage_url(storage: str | Path):
    """Optuna storage of a path: a journal file for `.log`, else an SQLite file."""
    path = Path(storage).resolve()
    if path.suffix == ".log":
        from optuna.storages import JournalStorage
        from optuna.storages.journal import JournalFileBackend

        return JournalStorage(JournalFileBackend(str(path)))
    return f"sqlite:///{path}"


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
            # the network shape must match (--forward-hidden, --forward-fc).
            path = self.workdir / "forward_c.ckpt"
            params, meta = checkpoint.load(path)
            stored = meta.get("config", {})
            for name in ("hidden", "fc"):
                if stored.get(name) != conf[name]:
                    raise checkpoint.CheckpointError(
                        f"{path}: F_c {name} {stored.get(name)}, this run {conf[name]}"
                        f" (--forward-{name})"
                    )
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
    arm_c,
    storage: str | Path,
    study_name: str,
    n_trials: int,
    space: SearchSpace = SearchSpace(),
    fconf: forward_lib.ForwardConfig = forward_lib.ForwardConfig(),
    forward_workdir=None,
    seed: int = 0,
    timeout_s: float | None = None,
    trials_per_batch: int = 8,
    backend: str = "c",
    progress: bool = False,
    arm_s=None,
) -> optuna.Study:
    """Adds `n_trials` trials, in batches, to the study `study_name` in `storage`.

    Args:
      base: every TrainConfig field not in TUNED (epochs is the per-trial budget,
        stretch_every the scoring and pruning interval).
      arrays: (pressures_s, poses_s, pressures_c, poses_c, bounds or None), as
        `ccgan.data.read_translation_files` reads them.
      arm_c: the target-domain arm the data came from (the trials are scored in it).
      storage: SQLite file, or journal file with a `.log` suffix (created with its folder; F_c
        caches go beside it).
      study_name: the study's name in that storage.
      n_trials: trials to run now (on top of those stored).
      space: search ranges.
      fconf: F_c settings (its network must match a `forward_workdir` checkpoint).
      forward_workdir: a `ccgan.train` workdir whose forward_c.ckpt to use, or None.
      seed: sampler seed (offset by the trials stored) and the training seed of every trial.
      timeout_s: start no new batch after this many seconds (None: run all n_trials).
      arm_s: the source-domain arm; needed when base.k_choice_programs is "shape_like" (it
        simulates the held-out programs' targets).
      trials_per_batch: trials trained together as one vmapped program.
      backend: the simulator of the scoring rollouts, "c" or "mjx".
      progress: progress bars over the scoring rollouts.

    Returns:
      The study.

    Raises:
      ValueError: n_trials or trials_per_batch < 1, or timeout_s given and not > 0.
    """
    if n_trials < 1 or trials_per_batch < 1:
        raise ValueError(
            f"n_trials and trials_per_batch must be >= 1: {n_trials}, {trials_per_batch}"
        )
    if timeout_s is not None and not timeout_s > 0:
        raise ValueError(f"timeout_s must be > 0 (or None), got {timeout_s}")
    check_forward_config(fconf)
    storage = Path(storage)
    storage.parent.mkdir(parents=True, exist_ok=True)
    # Pruning compares a trial with the finished trials at the same epoch, so not before a whole
    # batch has finished.
    pruner = optuna.pruners.MedianPruner(n_startup_trials=trials_per_batch, n_warmup_steps=0)
    study = optuna.create_study(
        study_name=study_name,
        storage=storage_url(storage),
        direction="minimize",
        load_if_exists=True,
        pruner=pruner,
    )
    ps, xs, pc, xc, bounds = arrays
    cache_dir = storage.parent / f"{storage.stem}_{study_name}_cache"
    forward_c = ForwardCache(fconf, cache_dir, forward_workdir)
    structures = space.structures()
    prepared: dict[int, tuple] = {}
    trainers: dict[tuple, BatchTrainer] = {}
    start, added = time.perf_counter(), 0
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    while added < n_trials:
        if timeout_s is not None and time.perf_counter() - start > timeout_s:
            break
        n_batches = len({t.user_attrs.get("batch") for t in study.trials})
        fixed = structures[n_batches % len(structures)]
        tpe = optuna.samplers.TPESampler(seed=seed + len(study.trials))
        with warnings.catch_warnings():  # PartialFixedSampler is marked experimental
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            study.sampler = optuna.samplers.PartialFixedSampler(fixed, tpe)
        trials = [study.ask() for _ in range(min(trials_per_batch, n_trials - added))]
        configs = [dataclasses.replace(base, **suggest(t, space)) for t in trials]
        length = configs[0].window_length
        if length not in prepared:
            data = data_lib.prepare(ps, xs, pc, xc, length, base.n_val, None, bounds=bounds)
            judge = SimulatorChoice(arm_c, data, configs[0], backend, source_arm=arm_s)
            prepared[length] = (data, judge.stretch_only_errors())
        data, stretch_only = prepared[length]
        group = tuple(fixed.items())
        if group not in trainers:
            label = "scoring" if progress else None
            judge = SimulatorChoice(arm_c, data, configs[0], backend, label, source_arm=arm_s)
            trainers[group] = BatchTrainer(data, forward_c(data, length), judge, fconf.model)
        trainer = trainers[group]
        pruned: set[int] = set()

        def record(trial, epoch, k, errors_cm, stretch_only=stretch_only):
            """The trial's scores at its last scored epoch, as user attributes."""
            trial.set_user_attr("k", int(k))
            trial.set_user_attr("epoch", int(epoch))
            by_k = dict(zip(map(str, base.hold_factors), map(float, errors_cm), strict=True))
            trial.set_user_attr("errors_cm", by_k)
            trial.set_user_attr("stretch_only_cm", float(stretch_only[base.hold_factors.index(k)]))

        def on_choice(epoch, index, k, error_cm, errors_cm, trials=trials, pruned=pruned):
            for j, i in enumerate(index):
                trials[i].report(float(error_cm[j].mean()), epoch)
                if trials[i].should_prune():
                    record(trials[i], epoch, k[j, 0], errors_cm[j, 0])
                    study.tell(trials[i], state=optuna.trial.TrialState.PRUNED)
                    pruned.add(int(i))
            return np.asarray([i not in pruned for i in index])

        for t in trials:
            t.set_user_attr("batch", n_batches)
        batch_start = time.perf_counter()
        result = trainer.train(configs, (seed,), on_choice)
        secs = time.perf_counter() - batch_start
        for i, t in enumerate(trials):
            if i not in pruned:
                t.set_user_attr("batch_wall_s", secs)
                record(t, result.epoch[i], result.k[i, 0], result.errors_cm[i, 0])
                study.tell(t, float(result.error_cm[i, 0]))
        added += len(trials)
        done = [t for t in study.trials if t.value is not None]
        best = min(t.value for t in done) if done else float("nan")
        print(
            f"batch {n_batches} ({fixed}): {len(trials)} trials, {len(pruned)} pruned,"
            f" {secs:.0f} s; best so far {best:.3f} cm",
            flush=True,
        )
    return study


def _n_stored(storage, study_name: str) -> int:
    """Trials already stored in the study (0 if the file or the study does not exist yet)."""
    if not Path(storage).exists():
        return 0
    url = storage_url(storage)
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
        trials.append(
            {
                "number": t.number,
                "state": t.state.name,
                "value_cm": t.value,
                "params": t.params,
                **{
                    n: t.user_attrs.get(n)
                    for n in ("batch", "batch_wall_s", "k", "epoch", "stretch_only_cm", "errors_cm")
                },
            }
        )
    done = [t for t in study.trials if t.value is not None]
    best = None
    if done:
        b = study.best_trial
        best = {
            "number": b.number,
            "value_cm": b.value,
            "params": b.params,
            "k": b.user_attrs.get("k"),
            "stretch_only_cm": b.user_attrs.get("stretch_only_cm"),
        }
    return extra | {"study_name": study.study_name, "best": best, "trials": trials}


def _plot_history(done: list[dict], study_name: str, path: Path) -> None:
    """The trials' values and the best so far, beside stretch only at each trial's k."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    if done:
        x = [t["number"] for t in done]
        y = [t["value_cm"] for t in done]
        ax.plot(x, y, "o", label="trial (D_c simulator, its k)")
        ax.step(x, np.minimum.accumulate(y), where="post", label="best so far")
        ax.plot(
            x, [t["stretch_only_cm"] for t in done], "x", c="grey", label="stretch only, same k"
        )
    ax.set_xlabel("trial")
    ax.set_ylabel("held-out tracking error (cm)")
    ax.set_title(f"Optuna TPE: {study_name}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def structure_lines(trials: list[dict]) -> list[str]:
    """A table of the trials by structure: count, pruned, best and median value, k chosen.

    A pruned trial's value is the last one it reported (Optuna's rule)."""
    groups: dict[tuple, list[dict]] = {}
    for t in trials:
        if all(n in t["params"] for n in STRUCTURAL):
            groups.setdefault(tuple(t["params"][n] for n in STRUCTURAL), []).append(t)
    lines = [
        "| " + " | ".join(STRUCTURAL) + " | trials | pruned | best (cm) | median (cm) | k chosen |",
        "|" + "---|" * (len(STRUCTURAL) + 5),
    ]
    for key, ts in groups.items():
        values = [t["value_cm"] for t in ts if t["value_cm"] is not None]
        ks = {}
        for t in ts:
            ks[t["k"]] = ks.get(t["k"], 0) + 1
        cells = [
            str(len(ts)),
            str(sum(t["state"] == "PRUNED" for t in ts)),
            f"{min(values):.3f}" if values else "",
            f"{np.median(values):.3f}" if values else "",
            ", ".join(f"{k}: {n}" for k, n in sorted(ks.items(), key=lambda kv: str(kv[0]))),
        ]
        lines.append("| " + " | ".join(map(str, key)) + " | " + " | ".join(cells) + " |")
    return [*lines, ""]


def write_report(summ: dict, report_dir: str | Path, note: str = "") -> dict[str, Path]:
    """Writes tune.md, tune.json and tune_history.png; returns their paths."""
    out = Path(report_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        k: out / f"tune{s}" for k, s in (("md", ".md"), ("json", ".json"), ("png", "_history.png"))
    }
    paths["json"].write_text(json.dumps(summ | {"note": note}, indent=2) + "\n")

    done = [t for t in summ["trials"] if t["value_cm"] is not None]
    try:
        _plot_history(done, summ["study_name"], paths["png"])
    except ImportError:  # a GPU image without matplotlib: the tables still get written
        paths.pop("png")

    base = summ["base_config"]
    lines = [f"# CCGAN-GP study: {summ['study_name']}", ""]
    if note:
        lines += [note, ""]
    n_pruned = sum(t["state"] == "PRUNED" for t in summ["trials"])
    lines += [
        f"- Command: `{summ['command']}`",
        f"- Machine: {summ['machine']} ({summ['device_kind']})",
        f"- This run: {summ['new_trials']} trials in {summ['wall_time_s']:.0f} s wall time"
        f" ({summ['wall_time_s'] / 60:.1f} min of this machine); study:"
        f" {len(summ['trials'])} trials"
        f" ({n_pruned} pruned) in `{summ['storage']}`",
        f"- Budget per trial: {base['epochs']} epochs, seed {summ['seed']}; scored and pruned"
        f" every {base['stretch_every']} epochs",
        f"- Objective: mean X_err (cm) of {describe_programs(base)}, translated by G_c and"
        " held k periods from rest in the D_c simulator, at the k of"
        f" {tuple(base['hold_factors'])} that scores best"
        " (`ccgan.sim_choice`). Stretch only: the untranslated programs at that k.",
        f"- Sampler: TPE, seed {summ['seed']} (+ trials already stored), one structure per batch"
        " of trials; median pruner",
        "",
    ]
    lines += structure_lines(summ["trials"])
    if summ["best"]:
        b = summ["best"]
        lines += [
            f"Best: trial {b['number']}, {b['value_cm']:.3f} cm at k = {b['k']}"
            f" (stretch only at that k: {b['stretch_only_cm']:.3f} cm)",
            "",
            "| parameter | value |",
            "|---|---|",
        ]
        lines += [f"| {n} | {_fmt(b['params'][n])} |" for n in TUNED]
        lines += [""]
    head = ["trial", "state", "error (cm)", "k", "stretch only (cm)", *TUNED, "batch"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for t in summ["trials"]:
        row = [
            str(t["number"]),
            t["state"],
            "" if t["value_cm"] is None else f"{t['value_cm']:.3f}",
            str(t["k"]),
            "" if t["stretch_only_cm"] is None else f"{t['stretch_only_cm']:.3f}",
            *(_fmt(t["params"].get(n, "")) for n in TUNED),
            str(t["batch"]),
        ]
        lines.append("| " + " | ".join(row) + " |")
    if "png" in paths:
        lines += ["", f"![optimisation history]({paths['png'].name})"]
    lines += [""]
    paths["md"].write_text("\n".join(lines))
    return paths


def build_parser() -> argparse.ArgumentParser:
    """The options of `python -m ccgan.tune`."""
    parser = cli_parser("ccgan.tune", __doc__)
    add_data_flags(parser)
    parser.add_argument(
        "--storage", default="runs/tune/tune.db", help="SQLite file, or a .log journal file"
    )
    parser.add_argument("--study-name", default="ccgan", help="the study's name in --storage")
    parser.add_argument("--n-trials", type=int, default=16, help="trials to add in this run")
    parser.add_argument(
        "--trials-per-batch", type=int, default=8, help="trials trained as one vmapped program"
    )
    parser.add_argument("--seed", type=int, default=0, help="sampler and training seed")
    parser.add_argument("--timeout-s", type=float, default=None, help="no new batch after this")
    parser.add_argument(
        "--backend", choices=("c", "mjx"), default="c", help="simulator of the scoring rollouts"
    )
    parser.add_argument(
        "--report-dir", default="runs/tune", help="folder for tune.md, .json, _history.png"
    )
    parser.add_argument(
        "--forward-workdir", default=None, help="reuse DIR/forward_c.ckpt (a ccgan.train workdir)"
    )
    parser.add_argument("--note", default="", help="a paragraph put at the top of tune.md")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="rewrite the report of the stored study from --storage and --report-dir/tune.json"
        " (the run's command, machine and times kept); run no trial",
    )
    add_config_flags(parser, forward_lib.ForwardConfig, prefix="forward-")
    add_config_flags(parser, SearchSpace, prefix="space-")
    add_config_flags(parser, TrainConfig, skip=TUNED)
    # A reduced budget per trial, scored (and pruned) twice.
    parser.set_defaults(epochs=50, stretch_every=25)
    return parser


def main(argv=None) -> None:
    """CLI: `python -m ccgan.tune --source S.npz... --constrained C.npz... [--n-trials N ...]`.

    Every option and data file is checked before any trial runs (usage errors, status 2).
    """
    import mjx_arm

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.report_only:
        old = Path(args.report_dir) / "tune.json"
        if not old.is_file() or not Path(args.storage).is_file():
            parser.error(f"--report-only needs {old} and --storage {args.storage}")
        extra = json.loads(old.read_text())
        study = optuna.load_study(study_name=args.study_name, storage=storage_url(args.storage))
        note = extra.pop("note", "")
        paths = write_report(summary(study, extra), args.report_dir, note)
        print("wrote", ", ".join(str(p) for p in paths.values()))
        return
    base = config_from_args(parser, args, TrainConfig, skip=TUNED)
    fconf = config_from_args(
        parser, args, forward_lib.ForwardConfig, prefix="forward-", check=check_forward_config
    )
    space = config_from_args(parser, args, SearchSpace, prefix="space-")
    if args.n_trials < 1:
        parser.error(f"--n-trials must be >= 1, got {args.n_trials}")
    if args.trials_per_batch < 1:
        parser.error(f"--trials-per-batch must be >= 1, got {args.trials_per_batch}")
    if args.timeout_s is not None and not args.timeout_s > 0:
        parser.error(f"--timeout-s must be > 0, got {args.timeout_s}")
    check_output_dir(parser, "--report-dir", args.report_dir)
    check_output_dir(parser, "--storage's folder", Path(args.storage).parent)
    if Path(args.storage).is_dir():
        parser.error(f"--storage {args.storage} is a folder, not a storage file")
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
    try:
        arm_c = mjx_arm.load(args.model, domain=d_c.domain)
    except (FileNotFoundError, ValueError) as err:
        parser.error(f"--model {args.model}: {err}")
    if arm_c.model_hash != d_c.model_hash:
        parser.error(
            f"the trials are scored in {arm_c.path} (model hash {arm_c.model_hash}), but the"
            f" data come from an arm with hash {d_c.model_hash}: pass that arm's MJCF as --model"
        )
    bounds = data_lib.union_bounds(d_s.bounds, d_c.bounds)

    from mjx_arm.machine import enable_compilation_cache

    enable_compilation_cache()
    start = time.perf_counter()
    n_before = _n_stored(args.storage, args.study_name)
    study = run_study(
        base,
        (d_s.pressures_bar, d_s.poses, d_c.pressures_bar, d_c.poses, bounds),
        arm_c,
        args.storage,
        args.study_name,
        args.n_trials,
        space,
        fconf,
        args.forward_workdir,
        args.seed,
        args.timeout_s,
        args.trials_per_batch,
        args.backend,
        progress=not args.no_progress,
        arm_s=mjx_arm.load(args.model, domain="source")
        if base.k_choice_programs == "shape_like"
        else None,
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
