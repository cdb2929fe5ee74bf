"""Choosing k in the target-domain simulator during a training run, and keeping the best G_c.

With `TrainConfig.k_choice` "simulator", `train_and_evaluate` (`ccgan.training_run`) calls
`simulator_choice_hook` after every epoch: where k is due it scores every seed's G_c in the D_c
arm (`ccgan.sim_choice.SimulatorChoice`), sets k, logs `k_choices.csv`, and (with
`keep_best`) keeps each seed's generators at their lowest held-out error (`BestGenerators`),
which also decides the early stop of `patience`.
"""

from __future__ import annotations

import threading
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ccgan import checkpoint
from ccgan.config import TrainConfig
from ccgan.run_files import write_rows


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
        error than it had: the early stop of `train_and_evaluate`."""
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


def simulator_choice_hook(
    k_choice,
    config: TrainConfig,
    seeds,
    rows: list[dict],
    path: Path,
    best: BestGenerators | None = None,
    settled: threading.Event | None = None,
):
    """`after_epoch(epochs_done, state, metrics) -> (state, metrics)` for
    `ccgan.training_run.run_chunks`.

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
        write_rows(path, rows)
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
