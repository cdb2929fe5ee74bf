"""The Optuna study of `ccgan.tune`: the search space and the batched, pruned trials.

`run_study` asks Optuna for a batch of trials that share one structure (window length, critic
steps, generator kind), trains them as one vmapped program (`ccgan.batch.BatchTrainer`) and scores
each in the target-domain simulator (`ccgan.sim_choice`); the median pruner stops the trials
below the median at a scoring epoch. The command line is `ccgan.tune`'s, the report
`ccgan.tune_report`'s.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import time
import warnings
from pathlib import Path

import numpy as np
import optuna

from ccgan import checkpoint
from ccgan import data as data_lib
from ccgan import forward as forward_lib
from ccgan.batch import BatchTrainer
from ccgan.config import TrainConfig, check_forward_config
from ccgan.run_files import data_fingerprint
from ccgan.sim_choice import SimulatorChoice
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


def n_stored(storage, study_name: str) -> int:
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
