"""A CCGAN-GP (or WCGAN-GP) training run on disk: `train_and_evaluate` and its epoch loop.

The pure functions are `ccgan.trainer`'s (`make_trainer`, `TrainState`, ...).
`train_and_evaluate` drives the trainer's epoch function over several seeds (vmapped) in chunks,
with tqdm, a CSV log and atomic checkpoints (`ccgan.run_files`); a resumed run ends with exactly
the parameters of an uninterrupted one because every epoch's randomness is
`fold_in(key, epoch)`. With `TrainConfig.k_choice` "simulator", k is chosen in the target-domain
arm between epochs (`ccgan.best_generators`).
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ccgan import checkpoint
from ccgan.best_generators import BestGenerators, simulator_choice_hook
from ccgan.config import TrainConfig
from ccgan.data import TranslationData
from ccgan.models import ForwardModel
from ccgan.run_files import (
    chunk_recorder,
    data_fingerprint,
    read_rows,
    resume_expectation,
    resumed_state,
    save_translators,
)
from ccgan.trainer import Trainer, init_each, make_trainer


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
        files (`ccgan.distill` refuses to refine them on another arm).
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
        expect = resume_expectation(ckpt_path, meta)
        checkpoint.load(ckpt_path, expect=expect)  # fail fast, before compiling anything
    trainer = make_trainer(config, data, forward_c_params, forward_model)
    state, run_keys = initial_states(trainer, seeds)
    rows: list[dict] = []
    choice_rows: list[dict] = []
    if resuming:
        state, rows = resumed_state(ckpt_path, csv_path, state, expect)
        choice_rows = [r for r in read_rows(choices_path) if r["epoch"] <= int(state.epoch[0])]
    done = int(np.asarray(state.epoch)[0])
    after_epoch = None
    best = None
    settled = threading.Event()  # set once `config.patience` scorings gave no seed a new best
    if k_choice is not None and config.k_choice == "simulator":
        best = BestGenerators(workdir / "best_gen.ckpt", meta, len(seeds), resuming)
        after_epoch = simulator_choice_hook(
            k_choice, config, seeds, choice_rows, choices_path,
            best if config.keep_best else None, settled,
        )  # fmt: skip
        if not resuming:  # like the authors' code: once before training, untrained G_c
            state, _ = after_epoch(0, state, None)
        elif best.settled(done, config):  # stopped early before, then resumed
            settled.set()
    bar = tqdm(total=config.epochs, initial=done, unit="epoch", disable=not progress, desc="ccgan")
    record = chunk_recorder(ckpt_path, csv_path, meta, seeds, rows, bar)
    if not settled.is_set():
        state = run_chunks(
            trainer, state, run_keys, config, done, max_chunks, record, stop, after_epoch,
            settled,
        )  # fmt: skip
    bar.close()
    if int(np.asarray(state.epoch)[0]) >= config.epochs or settled.is_set():
        save_translators(
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


def initial_states(trainer: Trainer, seeds: tuple[int, ...]):
    """(TrainState of every seed stacked on a leading axis [S, ...], run keys [S, 2]).

    Seed s's `PRNGKey(s)` splits once into its init key and its run key; every epoch folds its
    number into the run key (`make_trainer`), which is what lets a resumed run continue exactly.
    """
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds))
    init_keys, run_keys = jnp.swapaxes(jax.vmap(jax.random.split)(keys), 0, 1)
    return init_each(trainer.init, init_keys), run_keys


def run_chunks(
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
    after every epoch (`simulator_choice_hook`).
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
