"""The files of a `ccgan.train` run: metadata, CSV logs, resumption and translator files.

`train_and_evaluate` (`ccgan.training_run`) writes `state.ckpt` and `metrics.csv` after every
chunk of epochs (`chunk_recorder`), resumes from them only when the stored run matches this
one's config, data and seeds (`resume_expectation`, `resumed_state`), and ends with one
translator file per seed (`save_translators`). `data_fingerprint` ties checkpoints and forward
models to the windows they were trained on.
"""

from __future__ import annotations

import csv
import os
import warnings
from pathlib import Path

import jax
import numpy as np

from ccgan import checkpoint
from ccgan.config import RENAMED_FIELDS, RETIRED_FEEDBACK_IMPLS, TrainConfig
from ccgan.data import TranslationData
from ccgan.models import ForwardModel
from ccgan.trainer import METRICS, TrainState, generator


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


def read_rows(path: Path) -> list[dict]:
    """The rows of a CSV written by `write_rows` (ints for seed and epoch, floats otherwise)."""
    if not path.exists():
        return []
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return [
        {k: int(v) if k in ("seed", "epoch") else float(v) for k, v in row.items()} for row in rows
    ]


def write_rows(path: Path, rows: list[dict], fieldnames=None) -> None:
    """Writes rows as a CSV, atomically; columns `fieldnames` (default: the first row's keys)."""
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fieldnames or list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


def resume_expectation(ckpt_path: Path, meta: dict) -> dict:
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


def resumed_state(ckpt_path: Path, csv_path: Path, state: TrainState, expect: dict):
    """(stored TrainState, its CSV rows) of a run to continue.

    `state` gives the tree structure to read into; `expect` is the metadata the stored run must
    match (`resume_expectation`). Rows past the checkpoint's epoch (logged after it by a run that
    was then killed) are dropped: those epochs run again.
    """
    state, _ = checkpoint.load(ckpt_path, target=state, expect=expect)
    done = int(np.asarray(state.epoch)[0])
    return state, [r for r in read_rows(csv_path) if int(r["epoch"]) <= done]


def chunk_recorder(ckpt_path: Path, csv_path: Path, meta: dict, seeds, rows: list[dict], bar):
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
        write_rows(csv_path, rows, ["seed", "epoch", *METRICS])
        bar.set_postfix({m: float(np.nanmean(metrics[m][:, -1])) for m in ("generator_total", "k")})
        bar.update(n)

    return record


def save_translators(
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
