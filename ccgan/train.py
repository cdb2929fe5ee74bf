"""CCGAN-GP training (and the WCGAN-GP baseline): pure step/epoch functions and a thin driver.

The pure functions are `ccgan.trainer`'s (`make_train`, `make_trainer`, `TrainState`, ...; they
are importable from here too). `train_and_evaluate` drives the trainer's epoch function in chunks
with tqdm, a CSV log and atomic checkpoints; a resumed run ends with exactly the parameters of an
uninterrupted one because every epoch's randomness is `fold_in(key, epoch)`. `python -m
ccgan.train` first trains the forward models F_s and F_c (`train_forward_models`), then the CCGAN
against the frozen F_c.

The settings (`TrainConfig`) live in `ccgan.config`, the flags made from them in `ccgan.cli`.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import shutil
import signal
import sys
import threading
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ccgan import checkpoint
from ccgan import data as data_lib
from ccgan.cli import (
    add_config_flags,
    add_data_flags,
    cli_parser,
    config_from_args,
    data_from_args,
    lock_output_dir,
)
from ccgan.config import (
    FEEDBACK_IMPLS,
    K_CHOICE_PROGRAMS,
    RENAMED_FIELDS,
    RETIRED_FEEDBACK_IMPLS,
    TrainConfig,
    check_forward_config,
)
from ccgan.data import TranslationData, read_domain
from ccgan.forward import ForwardConfig
from ccgan.models import ForwardModel

# The trainer's API, all importable as ccgan.train.<name> (the one import a training script needs).
from ccgan.trainer import (  # noqa: F401
    METRICS,
    Trainer,
    TrainState,
    check_data,
    generator,
    init_each,
    make_train,
    make_trainer,
    resolved_feedback_impl,
)
from mjx_arm.atomic import write_atomically
from tracking.config import ConfigError  # noqa: F401  (kept importable as ccgan.train.ConfigError)


def data_fingerprint(data: TranslationData) -> str:
    """Hash of the prepared windows and bounds, recorded in checkpoints: a stored run or forward
    model is reused only on the data it was trained on."""
    return checkpoint.fingerprint(
        data.source.train,
        data.source.val,
        data.constrained.train,
        data.constrained.val,
        data.bounds.low,
        data.bounds.high,
    )


def _read_rows(path: Path) -> list[dict]:
    """The rows of a CSV written by `_write_rows` (ints for seed and epoch, floats otherwise)."""
    if not path.exists():
        return []
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return [
        {k: int(v) if k in ("seed", "epoch") else float(v) for k, v in row.items()} for row in rows
    ]


def _write_rows(path: Path, rows: list[dict], fieldnames=None) -> None:
    """Writes rows as a CSV, atomically; columns `fieldnames` (default: the first row's keys)."""
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fieldnames or list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


def _resume_expectation(ckpt_path: Path, meta: dict) -> dict:
    """The metadata a stored run must match to be resumed by a run with `meta`.

    A run stored with a retired feedback rollout (`RETIRED_FEEDBACK_IMPLS`) resumes with this
    run's, with a warning: every rollout computes the same function up to float rounding, so
    only the stored name differs. The next checkpoint records this run's rollout.

    A run stored before a field was renamed (`RENAMED_FIELDS`) resumes too: its fields are
    compared under their old names, and the next checkpoint records the new ones.
    """
    stored = checkpoint.read(ckpt_path)[0].get("config")
    if isinstance(stored, dict):
        old_names = {new: old for old, new in RENAMED_FIELDS.items() if old in stored}
        meta = meta | {"config": {old_names.get(k, k): v for k, v in meta["config"].items()}}
    impl = stored.get("feedback_impl") if isinstance(stored, dict) else None
    if impl not in RETIRED_FEEDBACK_IMPLS:
        return meta
    warnings.warn(
        f"{ckpt_path} was trained with feedback_impl={impl!r}, a retired rollout"
        f" (docs/benchmarks.md); resuming with {meta['config']['feedback_impl']!r}, the same"
        " function up to float rounding",
        stacklevel=3,
    )
    return meta | {"config": meta["config"] | {"feedback_impl": impl}}


def train_and_evaluate(
    config: TrainConfig,
    data: TranslationData,
    forward_c_params,
    workdir: str | os.PathLike,
    seeds: tuple[int, ...] = (0,),
    forward_model: ForwardModel | None = None,
    resume: bool = True,
    max_chunks: int | None = None,
    progress: bool = True,
    model_hash: str | None = None,
    stop=None,
    domains: tuple[str, str] | None = None,
    k_choice=None,
):
    """Trains one or several seeds (vmapped), with a CSV log, checkpoints and a translator file.

    Files in `workdir`: `state.ckpt` (stacked TrainState of every seed, every checkpoint_every
    epochs), `metrics.csv` (one row per seed and epoch, every loss term), `translator_seed{s}.ckpt`
    and `translator.ckpt` (first seed) for `ccgan.load_translator`; with `config.k_choice`
    "simulator", `k_choices.csv` too (one row per seed and choice: the held-out error at every k).

    Args:
      config, data, forward_c_params, forward_model: as `make_trainer`.
      workdir: output folder.
      seeds: PRNG seeds, trained together with vmap.
      resume: continue from `workdir/state.ckpt` if present (it must match config, data and seeds).
      max_chunks: stop after this many chunks (to test resumption); None runs to the end.
      progress: show a tqdm bar over epochs.
      model_hash: `Arm.model_hash` of the arm the data comes from, recorded in the translator
        files (`ccgan.finetune` and `ccgan.distill` refuse to refine them on another arm).
      domains: (source, target) domain names of the data (e.g. ("source", "aged")), recorded
        with the method and `model_hash` as the translator files' labels
        (`ccgan.translator.LABELS`); without them and `model_hash` the files are unlabelled.
      stop: a `threading.Event`; once set, the run checkpoints after the epoch in progress and
        returns unfinished (no translator files), to be resumed.
      k_choice: a `ccgan.sim_choice.SimulatorChoice` on the target-domain arm; needed when
        `config.k_choice` is "simulator" (it chooses k before training, every `stretch_every`
        epochs and after the last).

    Returns:
      (state with a leading seed axis, rows of the metrics CSV).
    """
    from tqdm.auto import tqdm

    if config.k_choice == "simulator" and k_choice is None:
        raise ValueError(
            'config.k_choice is "simulator": pass k_choice=ccgan.sim_choice.SimulatorChoice(arm,'
            ' data, config) on the target-domain arm, or set k_choice="forward"'
        )
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    ckpt_path, csv_path = workdir / "state.ckpt", workdir / "metrics.csv"
    choices_path = workdir / "k_choices.csv"
    meta = {"config": config.to_dict(), "data": data_fingerprint(data), "seeds": list(seeds)}
    resuming = resume and ckpt_path.exists()
    if resuming:
        expect = _resume_expectation(ckpt_path, meta)
        checkpoint.load(ckpt_path, expect=expect)  # fail fast, before compiling anything
    trainer = make_trainer(config, data, forward_c_params, forward_model)
    state, run_keys = _initial_states(trainer, seeds)
    rows: list[dict] = []
    choice_rows: list[dict] = []
    if resuming:
        state, rows = _resumed(ckpt_path, csv_path, state, expect)
        choice_rows = [r for r in _read_rows(choices_path) if r["epoch"] <= int(state.epoch[0])]
    done = int(np.asarray(state.epoch)[0])
    after_epoch = None
    best = None
    settled = threading.Event()  # set once `config.patience` scorings gave no seed a new best
    if k_choice is not None and config.k_choice == "simulator":
        best = BestGenerators(workdir / "best_gen.ckpt", meta, len(seeds), resuming)
        after_epoch = _simulator_choice(
            k_choice, config, seeds, choice_rows, choices_path,
            best if config.keep_best else None, settled,
        )  # fmt: skip
        if not resuming:  # like the authors' code: once before training, untrained G_c
            state, _ = after_epoch(0, state, None)
        elif best.settled(done, config):  # stopped early before, then resumed
            settled.set()
    bar = tqdm(total=config.epochs, initial=done, unit="epoch", disable=not progress, desc="ccgan")
    record = _chunk_recorder(ckpt_path, csv_path, meta, seeds, rows, bar)
    if not settled.is_set():
        state = _run_chunks(
            trainer, state, run_keys, config, done, max_chunks, record, stop, after_epoch,
            settled,
        )  # fmt: skip
    bar.close()
    if int(np.asarray(state.epoch)[0]) >= config.epochs or settled.is_set():
        _save_translators(
            workdir,
            best.applied(state) if best is not None and config.keep_best else state,
            seeds,
            data,
            config,
            forward_c_params,
            forward_model,
            model_hash,
            domains,
        )
    return state, rows


class BestGenerators:
    """Each seed's generators at its scored epoch with the lowest held-out error, kept in
    `path` (rewritten at each improvement, so a resumed run keeps them).

    Args:
      path: the checkpoint file (`best_gen.ckpt` in the workdir).
      meta: the run's metadata (config, data, seeds): a stored file of another run is ignored.
      n_seeds: S.
      resume: read `path` if it belongs to this run.
    """

    def __init__(self, path: Path, meta: dict, n_seeds: int, resume: bool):
        self.path, self.meta = path, meta
        self.error = np.full(n_seeds, np.inf)
        self.epoch = np.zeros(n_seeds, int)
        self.k = np.zeros(n_seeds, int)
        self.gen = None  # [S, ...] generators' variables (numpy), once any seed was scored
        if resume and path.exists():
            try:
                self.gen, stored = checkpoint.load(path, expect=meta)
            except checkpoint.CheckpointError:
                return
            self.error = np.asarray(stored["best_error_cm"], float)
            self.epoch = np.asarray(stored["best_epoch"], int)
            self.k = np.asarray(stored["best_k"], int)

    def update(self, epochs_done: int, gen, k: np.ndarray, error: np.ndarray) -> None:
        """Keeps the seeds whose `error` [S] (cm) at `epochs_done` beats their best so far."""
        better = np.asarray(error) < self.error
        if epochs_done == 0 or not better.any():
            return
        now = jax.tree.map(np.asarray, gen)
        if self.gen is None:
            self.gen = now
        else:
            self.gen = jax.tree.map(
                lambda b, n: np.where(better.reshape((-1,) + (1,) * (n.ndim - 1)), n, b),
                self.gen,
                now,
            )
        self.error = np.where(better, error, self.error)
        self.epoch = np.where(better, epochs_done, self.epoch)
        self.k = np.where(better, k, self.k)
        checkpoint.save(
            self.path,
            self.gen,
            self.meta
            | {
                "best_error_cm": self.error.tolist(),
                "best_epoch": self.epoch.tolist(),
                "best_k": self.k.tolist(),
            },
        )

    def settled(self, epochs_done: int, config: TrainConfig) -> bool:
        """True when `config.patience` (> 0) scorings up to `epochs_done` gave no seed a lower
        error than it had: the early stop of `train`."""
        if not config.patience or self.gen is None:
            return False
        return epochs_done - int(self.epoch.max()) >= config.patience * config.stretch_every

    def applied(self, state):
        """`state` with each scored seed's best generators and k (others as they are)."""
        if self.gen is None:
            return state
        scored = self.epoch > 0
        gen = jax.tree.map(
            lambda b, n: np.where(scored.reshape((-1,) + (1,) * (n.ndim - 1)), b, np.asarray(n)),
            self.gen,
            state.params["gen"],
        )
        k = np.where(scored, self.k, np.asarray(state.k))
        return state.replace(params={**state.params, "gen": gen}, k=jnp.asarray(k, state.k.dtype))


def _simulator_choice(
    k_choice, config: TrainConfig, seeds, rows: list[dict], path: Path, best=None, settled=None
):
    """`after_epoch(epochs_done, state, metrics) -> (state, metrics)` for `_run_chunks`.

    After the epochs where k is due (every `stretch_every` and the last; 0 = before training),
    chooses each seed's k in the simulator, sets it in the state and in that epoch's metrics
    (k, val_error_cm), and appends one row per seed to `rows`, rewritten to `path`. With `best`
    (a `BestGenerators`), each seed's generators at its lowest error are kept there, and
    `settled` (a `threading.Event`) is set once `best.settled` (config.patience).
    """

    def after_epoch(epochs_done: int, state, metrics):
        due = epochs_done % config.stretch_every == 0 or epochs_done == config.epochs
        if not due:
            return state, metrics
        g_c = jax.tree.map(lambda x: x[:, 0], state.params["gen"])
        choice = k_choice.choose(g_c)
        state = state.replace(k=jnp.asarray(choice.k, state.k.dtype))
        for s_i, seed in enumerate(seeds):
            row = {"seed": seed, "epoch": epochs_done, "k": int(choice.k[s_i])}
            for k, err in zip(config.hold_factors, choice.errors_cm[s_i], strict=True):
                row[f"error_cm_k{k}"] = float(err)
            rows.append(row)
        _write_rows(path, rows)
        if best is not None:
            best.update(epochs_done, state.params["gen"], choice.k, choice.error_cm)
            if settled is not None and best.settled(epochs_done, config):
                settled.set()
        if metrics is not None:
            metrics = dict(metrics)
            metrics["k"] = metrics["k"].at[:, -1].set(jnp.asarray(choice.k, jnp.float32))
            metrics["val_error_cm"] = metrics["val_error_cm"].at[:, -1].set(choice.error_cm)
        return state, metrics

    return after_epoch


def _initial_states(trainer: Trainer, seeds: tuple[int, ...]):
    """(TrainState of every seed stacked on a leading axis [S, ...], run keys [S, 2]).

    Seed s's `PRNGKey(s)` splits once into its init key and its run key; every epoch folds its
    number into the run key (`make_trainer`), which is what lets a resumed run continue exactly.
    """
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds))
    init_keys, run_keys = jnp.swapaxes(jax.vmap(jax.random.split)(keys), 0, 1)
    return init_each(trainer.init, init_keys), run_keys


def _resumed(ckpt_path: Path, csv_path: Path, state: TrainState, expect: dict):
    """(stored TrainState, its CSV rows) of a run to continue.

    `state` gives the tree structure to read into; `expect` is the metadata the stored run must
    match (`_resume_expectation`). Rows past the checkpoint's epoch (logged after it by a run that
    was then killed) are dropped: those epochs run again.
    """
    state, _ = checkpoint.load(ckpt_path, target=state, expect=expect)
    done = int(np.asarray(state.epoch)[0])
    return state, [r for r in _read_rows(csv_path) if int(r["epoch"]) <= done]


def _chunk_recorder(ckpt_path: Path, csv_path: Path, meta: dict, seeds, rows: list[dict], bar):
    """`record(start, n, state, metrics)`: the host side of a finished chunk of n epochs.

    Appends one row per seed and epoch to `rows` (metrics {name: [S, n]}), checkpoints the state
    with `meta` and the epoch reached, rewrites the CSV and advances the progress bar.
    """

    def record(start, n, state, metrics):
        metrics = jax.device_get(metrics)
        for s_i, seed in enumerate(seeds):
            for e in range(n):
                row = {"seed": seed, "epoch": start + e + 1}
                row.update({m: float(metrics[m][s_i, e]) for m in METRICS})
                rows.append(row)
        checkpoint.save(ckpt_path, jax.device_get(state), meta | {"epoch": start + n})
        _write_rows(csv_path, rows, ["seed", "epoch", *METRICS])
        bar.set_postfix({m: float(np.nanmean(metrics[m][:, -1])) for m in ("generator_total", "k")})
        bar.update(n)

    return record


def _run_chunks(
    trainer: Trainer,
    state,
    run_keys,
    config: TrainConfig,
    done,
    max_chunks,
    record,
    stop=None,
    after_epoch=None,
    settled=None,
):
    """Runs epochs done.. in chunks of `checkpoint_every` (vmapped over seeds); returns the state.

    Stops after `max_chunks` chunks (None: at config.epochs), or after the epoch running when
    `stop` or `settled` (`threading.Event`s: asked to stop; trained enough) is set: the chunk
    ends there, so a stopped run loses no finished epoch. `record(start, n, state, metrics)`
    runs after each chunk. Epochs are dispatched one at
    a time and the host waits for each before the next, so it never runs ahead of a stop; the
    next chunk starts before the last one's files are written, so the device keeps working while
    the host saves (JAX dispatch is asynchronous; the arrays are immutable).
    `after_epoch(epochs_done, state, metrics [S, 1] each) -> (state, metrics)`, when given, runs
    after every epoch (`_simulator_choice`).
    """
    chunk = max(1, config.checkpoint_every)
    run = jax.jit(jax.vmap(trainer.run_epochs, in_axes=(0, 0, None, None)), static_argnums=3)
    starts = list(range(done, config.epochs, chunk))
    if max_chunks is not None:
        starts = starts[:max_chunks]
    pending = None
    for start in starts:
        parts = []
        for epoch in range(start, min(start + chunk, config.epochs)):
            state, metrics = run(state, run_keys, jnp.int32(epoch), 1)
            if after_epoch is not None:
                state, metrics = after_epoch(epoch + 1, state, metrics)
            parts.append(metrics)
            if settled is not None and settled.is_set():
                break
            if stop is not None:
                jax.block_until_ready(state)
                if stop.is_set():
                    break
        metrics = jax.tree.map(lambda *m: jnp.concatenate(m, axis=1), *parts)
        if pending is not None:
            record(*pending)
        pending = (start, len(parts), state, metrics)
        if any(e is not None and e.is_set() for e in (stop, settled)):
            break
    if pending is not None:
        record(*pending)
    return state


def _save_translators(
    workdir: Path,
    state: TrainState,
    seeds,
    data: TranslationData,
    config: TrainConfig,
    forward_c_params,
    forward_model: ForwardModel | None,
    model_hash: str | None,
    domains: tuple[str, str] | None = None,
) -> None:
    """Writes `translator_seed{s}.ckpt` per seed; `translator.ckpt` links to the first seed's.

    `state` is the trained TrainState of every seed [S, ...]; the other arguments are as
    `train_and_evaluate`'s, recorded in each file for `ccgan.load_translator`.
    """
    from ccgan.translator import save_translator

    for s_i, seed in enumerate(seeds):
        one = jax.tree.map(lambda x, i=s_i: np.asarray(x)[i], state)
        save_translator(
            workdir / f"translator_seed{seed}.ckpt",
            generator(one.params, 0),
            int(one.k),
            data.bounds,
            config,
            forward_c_params,
            forward_model,
            model_hash=model_hash,
            domains=domains,
        )
    checkpoint.link_first_seed(workdir, f"translator_seed{seeds[0]}.ckpt")


def load_npz(*paths: str | os.PathLike):
    """Concatenated (pressures [N, T, 3] bar, poses [N, T, 6], bounds) of one domain's files.

    The files are read and checked by `ccgan.data.read_domain` (one domain, one arm, one program
    length; a corrupt file raises `mjx_arm.dataset.DatasetError` naming it); the bounds span
    every file's. List the validation file last (the last `n_val` trajectories are held out).
    """
    d = read_domain(paths)
    return d.pressures_bar, d.poses, d.bounds


def forward_splits(
    data: TranslationData, d_s, d_c, config: TrainConfig, window: int, forward_c=None
) -> dict:
    """The windows F_s and F_c train on: {"forward_s": DomainSplit, "forward_c": DomainSplit}.

    By default both are the CCGAN's own windows (`data`). `window` (control steps) re-cuts the
    programs (`d_s`, `d_c`: `ccgan.data.DomainData`) to another length: open-loop training
    (`ForwardConfig.open_loop`) wants windows as long as the horizon F_c predicts in the feedback
    loss (window_length x k). `forward_c`, D_c babbling of the same arm (a `DomainData`, e.g.
    with holds long enough for the slow D_c arm to settle:
    `studies/results/h200/issue29/forward_data/forward_data.md`), replaces D_c's training
    programs for F_c. Either way F_c is evaluated on the CCGAN's held-out D_c programs, and
    every window is normalised with the CCGAN's pose bounds.
    """
    if window == config.window_length and forward_c is None:
        return {"forward_s": data.source, "forward_c": data.constrained}

    def cut(d, n_val, name):
        return data_lib.split_domain(
            d.pressures_bar, d.poses, data.bounds, window, n_val, name=name
        )

    train_c = cut(d_c, config.n_val, "D_c") if forward_c is None else cut(forward_c, 0, "F_c data")
    return {
        "forward_s": cut(d_s, config.n_val, "D_s"),
        "forward_c": data.constrained._replace(
            train=train_c.train, train_prev_pose=train_c.train_prev_pose
        ),
    }


def forward_meta(fconf: ForwardConfig, data: TranslationData, splits: dict | None = None) -> dict:
    """The metadata that ties F_s and F_c to their settings and data (checked on resume and by
    --forward-from). Windows other than the CCGAN's own (`forward_splits`) add their hash."""
    meta = {"config": dataclasses.asdict(fconf), "data": data_fingerprint(data)}
    if splits is not None and (
        splits["forward_s"] is not data.source or splits["forward_c"] is not data.constrained
    ):
        meta["forward_windows"] = checkpoint.fingerprint(
            *(a for split in splits.values() for a in (split.train, split.train_prev_pose))
        )
    return meta


def train_forward_models(
    fconf: ForwardConfig,
    data: TranslationData,
    workdir: Path,
    progress=True,
    resume=False,
    splits: dict | None = None,
    f_meta: dict | None = None,
):
    """Trains F_s and F_c, writes `forward_{s,c}.ckpt` and `forward_metrics.json` to workdir.

    F_s is not used by the CCGAN; it is trained for the report, as in the paper. The bar
    advances per epoch (minutes per model on a CPU at the default 300 epochs). Each model's
    checkpoint and metrics are written as soon as it is trained, so with `resume` a run stopped
    during F_c (a time limit, `experiments.paper`'s deadline) keeps F_s: a model whose checkpoint
    was trained with these settings on this data, and whose metrics are in the file, is not
    trained again.
    """
    from tqdm.auto import tqdm

    from ccgan import forward as forward_lib

    splits = splits or {"forward_s": data.source, "forward_c": data.constrained}
    f_meta = f_meta or forward_meta(fconf, data, splits)
    metrics_path = workdir / "forward_metrics.json"
    report = _finished_forward_models(workdir, metrics_path, f_meta) if resume else {}
    models = [(name, split) for name, split in splits.items() if name not in report]
    bar = tqdm(
        total=len(models) * fconf.epochs, desc="forward models", unit="epoch", disable=not progress
    )
    for name in report:
        bar.write(f"{name}: trained already with these settings ({workdir / f'{name}.ckpt'})")
    for name, split in models:
        bar.set_postfix_str(name)
        params, hist, metrics = forward_lib.train_forward(
            fconf, split, data.bounds, on_epoch=lambda _: bar.update(1)
        )
        checkpoint.save(workdir / f"{name}.ckpt", params, f_meta)
        report[name] = metrics | {"final_loss": float(hist[-1])}
        write_atomically(metrics_path, lambda f: f.write(json.dumps(report, indent=2).encode()))
        bar.write(f"{name} {json.dumps(report[name])}")
    bar.close()
    return report


def _finished_forward_models(workdir: Path, metrics_path: Path, f_meta: dict) -> dict:
    """{name: metrics} of the forward models in workdir that a resumed run can keep."""
    try:
        stored = json.loads(metrics_path.read_text())
    except (OSError, ValueError):
        return {}
    done = {}
    for name in ("forward_s", "forward_c"):
        try:
            _, stored_meta = checkpoint.load(workdir / f"{name}.ckpt", expect=f_meta)
        except checkpoint.CheckpointError:  # absent, corrupt or made otherwise: trained again
            continue
        if stored_meta.get("forward_windows") != f_meta.get("forward_windows"):
            continue  # trained on other windows
        if isinstance(stored, dict) and name in stored:
            done[name] = stored[name]
    return done


FORWARD_FILES = ("forward_s.ckpt", "forward_c.ckpt", "forward_metrics.json")


def copy_forward_models(parser, source: Path, workdir: Path, f_meta: dict) -> None:
    """Copies F_s, F_c and their metrics from another workdir, after checking that they were
    trained on this data with these settings (a usage error otherwise, before any training)."""
    missing = [name for name in FORWARD_FILES if not (source / name).is_file()]
    if missing:
        parser.error(f"--forward-from {source}: no {', '.join(missing)} there")
    for name in ("forward_s.ckpt", "forward_c.ckpt"):
        try:
            _, stored = checkpoint.load(source / name, expect=f_meta)
        except checkpoint.CheckpointError as err:
            parser.error(f"--forward-from: {err}")
        if stored.get("forward_windows") != f_meta.get("forward_windows"):
            parser.error(
                f"--forward-from: {source / name} was trained on other windows (forward_windows"
                " differ): pass the --forward-data and --forward-window it was trained with"
            )
    for name in FORWARD_FILES:
        shutil.copy2(source / name, workdir / name)


def simulator_choice_from_args(parser, args, config: TrainConfig, data: TranslationData, d_c):
    """The `ccgan.sim_choice.SimulatorChoice` of --k-choice simulator: the target domain's arm
    from --model (default `models/softarm.xml`), which must be the arm the data came from."""
    import mjx_arm
    from ccgan.sim_choice import SimulatorChoice

    arm = mjx_arm.load(args.model, domain=d_c.domain)
    if d_c.model_hash is not None and d_c.model_hash != arm.model_hash:
        parser.error(
            f"--k-choice simulator scores k on {arm.path} (model hash {arm.model_hash}), but the"
            f" data come from an arm with hash {d_c.model_hash}: pass that arm's MJCF as --model"
        )
    arm = arm.planning_copy(config.k_choice_substeps)
    label = None if args.no_progress else "k in the simulator"
    source_arm = None
    if config.k_choice_programs == "shape_like":
        source_arm = mjx_arm.load(args.model, domain="source")
    return SimulatorChoice(arm, data, config, progress=label, source_arm=source_arm)


def forward_splits_from_args(parser, args, config: TrainConfig, data, d_s, d_c) -> dict:
    """`forward_splits` of --forward-window and --forward-data (usage errors for bad ones)."""
    from mjx_arm.dataset import DatasetError

    window = args.forward_window or config.window_length
    if window < 1:
        parser.error(f"--forward-window must be at least 1, got {window}")
    forward_c = None
    if args.forward_data:
        try:
            forward_c = read_domain(args.forward_data, "constrained", d_c.model_hash)
        except DatasetError as err:
            parser.error(f"--forward-data: {err}")
        if forward_c.domain != d_c.domain:
            parser.error(
                f"--forward-data holds domain {forward_c.domain!r}, --constrained {d_c.domain!r}"
            )
    shortest = min(d.pressures_bar.shape[1] for d in (d_s, forward_c or d_c))
    if window > shortest:
        parser.error(
            f"--forward-window {window} is longer than the programs F_s / F_c train on"
            f" ({shortest} steps)"
        )
    try:
        return forward_splits(data, d_s, d_c, config, window, forward_c)
    except ValueError as err:
        parser.error(f"--forward-window / --forward-data: {err}")


def build_parser() -> argparse.ArgumentParser:
    """The options of `python -m ccgan.train`."""
    parser = cli_parser("ccgan.train", __doc__)
    add_data_flags(parser)
    parser.add_argument(
        "--workdir",
        default="runs/ccgan_train",
        help="output folder: state.ckpt, metrics.csv, forward_*.ckpt, translator*.ckpt",
    )
    parser.add_argument(
        "--seeds", type=int, nargs="+", default=[0], help="PRNG seeds, trained together"
    )
    parser.add_argument(
        "--no-resume",
        action="store_true",
        help="train afresh instead of continuing from the workdir's checkpoints",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.add_argument(
        "--forward-only", action="store_true", help="train F_s and F_c, then stop (no GAN)"
    )
    parser.add_argument(
        "--forward-from",
        metavar="DIR",
        default=None,
        help="take F_s and F_c from DIR (a --forward-only workdir) instead of training them;"
        " they must have been trained on the same data with the same --forward-* options",
    )
    parser.add_argument(
        "--forward-data",
        nargs="+",
        default=None,
        metavar="NPZ",
        help="D_c babbling files that F_c trains on instead of --constrained's training programs"
        " (the same arm and domain; e.g. holds long enough for the slow arm to settle)",
    )
    parser.add_argument(
        "--forward-window",
        type=int,
        default=0,
        help="control steps per F_s / F_c training window (0: --window-length); with"
        " --forward-open-loop, about the feedback horizon window_length x k",
    )
    add_config_flags(parser, ForwardConfig, prefix="forward-")
    add_config_flags(
        parser,
        TrainConfig,
        choices={"feedback_impl": FEEDBACK_IMPLS, "k_choice_programs": K_CHOICE_PROGRAMS},
    )
    return parser


def main(argv=None) -> None:
    """CLI: `python -m ccgan.train --source S.npz... --constrained C.npz... --workdir DIR [...]`.

    Every option and every data file is checked before anything is computed or written; a bad
    one exits with status 2 and a message naming it.
    """
    from ccgan import data as data_lib
    from mjx_arm.dataset import DatasetError

    parser = build_parser()
    args = parser.parse_args(argv)
    config = config_from_args(parser, args, TrainConfig)
    fconf = config_from_args(
        parser, args, ForwardConfig, prefix="forward-", check=check_forward_config
    )
    if len(set(args.seeds)) != len(args.seeds):
        parser.error(f"--seeds must be distinct, got {args.seeds}")
    lock_output_dir(parser, "--workdir", args.workdir)  # one trainer per workdir
    d_s, d_c = data_from_args(parser, args)
    try:
        split_notes = data_lib.check_slot_splits(config.n_val, d_s, d_c)
    except DatasetError as err:
        parser.error(str(err))
    for note in split_notes:
        print(f"NOTE: {note}", file=sys.stderr)

    from mjx_arm.machine import enable_compilation_cache

    try:
        data = data_lib.prepare(
            d_s.pressures_bar,
            d_s.poses,
            d_c.pressures_bar,
            d_c.poses,
            config.window_length,
            config.n_val,
            config.stride,
            bounds=data_lib.union_bounds(d_s.bounds, d_c.bounds),
        )
        check_data(config, data)
    except ValueError as err:
        parser.error(f"the data do not suit the options: {err}")
    k_choice = None
    if config.k_choice == "simulator" and not args.forward_only:
        k_choice = simulator_choice_from_args(parser, args, config, data, d_c)
    enable_compilation_cache()
    workdir = Path(args.workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    splits = forward_splits_from_args(parser, args, config, data, d_s, d_c)
    f_meta = forward_meta(fconf, data, splits)
    fc_path = workdir / "forward_c.ckpt"
    if args.forward_from is not None:
        copy_forward_models(parser, Path(args.forward_from), workdir, f_meta)
    elif args.no_resume or not all((workdir / name).exists() for name in FORWARD_FILES):
        train_forward_models(
            fconf, data, workdir, progress=not args.no_progress, resume=not args.no_resume,
            splits=splits, f_meta=f_meta,
        )  # fmt: skip
    fc_params, _ = checkpoint.load(fc_path, expect=f_meta)
    if args.forward_only:
        return
    # SIGTERM (a time limit, experiments.stages at its deadline) stops the run after the epoch in
    # progress, with a checkpoint to resume from; exit status 143 says it is unfinished.
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    state, _ = train_and_evaluate(
        config,
        data,
        fc_params,
        workdir,
        seeds=tuple(args.seeds),
        resume=not args.no_resume,
        forward_model=fconf.model,
        progress=not args.no_progress,
        model_hash=d_s.model_hash,
        stop=stop,
        domains=(d_s.domain, d_c.domain),
        k_choice=k_choice,
    )
    epochs_done = int(np.asarray(state.epoch)[0])
    if epochs_done < config.epochs and stop.is_set():
        print(f"stopped at epoch {epochs_done}: rerun to resume", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM)
    if epochs_done < config.epochs:  # not stopped: --patience ended it, its best written
        print(
            f"trained {epochs_done} of at most {config.epochs} epochs: {config.patience}"
            " scoring(s) in a row improved no seed (--patience)"
        )


if __name__ == "__main__":
    main()
