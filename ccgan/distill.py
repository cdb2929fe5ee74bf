"""Fine-tuning G_c by imitation of a simulator-based teacher (receding-horizon tracking).

`ccgan.finetune` differentiates the tracking error through the MJX rollout, which is slow and
reaches only a short window from rest. Here the simulator acts once, ahead of training: the
receding-horizon tracker `tracking.mpc.track` computes, in MuJoCo C, D_c commands that make the
arm in D_c follow the D_s poses of shape-like programs (`mjx_arm.programs.shape_like_programs`,
never the five test shapes), over their whole length. G_c is then trained to reproduce those
commands:

    D_s program p_s [T, 3] --D_s sim--> x_s [T, 6] --tracking.mpc.track (D_c sim)--> c* [T, 3]
    loss = mean_t(w_t (G_c(p_s, x_s)_t - c*_t)^2) over pressures normalised to [0, 1],
           w_t = head_weight in the first window_s seconds, 1 after (normalised to mean 1)

starting from a trained (or fine-tuned) translator, with Adam. Every `eval_every` epochs each
seed's G_c is scored in the MuJoCo C simulator on held-out programs: the mean of the X_err (cm)
over their first `window_s` seconds and over their whole length. Each seed's best iterate by that
score is written (the starting translator counts), so imitation that makes tracking worse writes
the original. The teacher's commands are cached in the output folder (`teacher.npz`, reused
while the settings match and grown when more programs are asked for), so a rerun trains
without recomputing them.

The files are translator checkpoints like `ccgan.finetune`'s (metadata "finetune" holds this
stage, with "method": "distill"; earlier stages stay in "finetune_earlier"), rewritten at every
validation ("complete": false until the run ends), so a killed run keeps its best iterates.

    python -m ccgan.distill \\
        --translators results/paper/rerun_2026-11-27/run/ccgan/translator_seed{0,1,2}.ckpt \\
        --seeds 0 1 2 --hold-factor 15 --out runs/ccgan_distilled

As `ccgan.finetune`, the CLI simulates the arm of `--model` (default the I-Support arm,
`mjx_arm.constants.TRANSLATOR_MODEL_PATH`, models/softarm.xml, the one the committed
translators were trained on).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from ccgan.cli import add_config_flags, config_from_args
from ccgan.data import PRESSURE_DIM, normalise_pressure, samples
from ccgan.stage import (
    BestIterates,
    common_k,
    generator_commands,
    stage_parser,
    start_stage,
    validated_loop,
)
from ccgan.translator import Translator
from mjx_arm import arm as mjx_arm_arm
from mjx_arm.atomic import link_or_copy, write_atomically
from mjx_arm.babble import BabbleConfig
from mjx_arm.programs import babble_programs, shape_like_programs
from tracking import mpc, mpc_mjx
from tracking.config import ConfigError, check_fields
from tracking.held import run_dc, stretch
from tracking.metrics import position_error_cm


@dataclasses.dataclass(frozen=True)
class DistillConfig:
    """Settings of an imitation fine-tune."""

    n_train: int = 128
    """Teacher programs to imitate."""
    n_val: int = 16
    """Held-out programs that pick the best iterate."""
    n_train_full: int = 0
    """More teacher programs, scaled to the full valve amplitude as the test shapes are
    (`shape_like_program(full_scale=True)`, their own random stream)."""
    n_val_full: int = 0
    """More held-out programs at the full amplitude."""
    n_train_babble: int = 0
    """More teacher programs from the babbling family (`mjx_arm.babble`'s, the paper's holds of
    0.5-3 s between 0 and 3.5 bar, a stream of their own): programs unlike any shape, for a
    translator that meets programs it was not written for."""
    n_val_babble: int = 0
    """More held-out babbling programs."""
    duration_s: float = 20.0
    """Length of every program, from rest (s of source time)."""
    window_s: float = 2.0
    """The held-out score averages the X_err over the first window_s seconds and the whole."""
    head_weight: float = 1.0
    """Weight of the first window_s seconds in the imitation loss (the rest weighs 1): the
    start from rest is where the oracle is compared and where the teacher's commands change
    fastest."""
    horizon_steps: int = 1
    """The teacher's planning horizon (`tracking.mpc.MpcConfig.horizon_steps`)."""
    iterations: int = 2
    """The teacher's Gauss-Newton iterations per step."""
    epochs: int = 300
    """Passes over the teacher programs."""
    batch_size: int = 16
    """Programs per Adam step."""
    learning_rate: float = 1e-3
    """Adam step size."""
    final_lr_factor: float = 1.0
    """The step size falls along a cosine from learning_rate to learning_rate x this over the
    run's epochs (1: constant). At k = 20 the held-out score of the constant rate moved by up to
    1.8x between validations (docs/distillation.md)."""
    eval_every: int = 50
    """Epochs between held-out scores (and the last epoch)."""
    seed: int = 0
    """Seed of the programs and of the batch order."""
    max_wall_s: float = 0.0
    """Stop training after this many seconds (0: no limit); the best iterate so far is kept."""
    teacher_backend: str = "c"
    """Where the teacher plans: "c" (`tracking.mpc`, MuJoCo C on the host's cores, any horizon)
    or "mjx" (`tracking.mpc_mjx`, every program at once on the accelerator, horizon 1); its
    commands are scored in MuJoCo C either way. `bench.teacher` measures which is faster."""
    generator_unroll: int = 1
    """LSTM time steps per loop iteration of G_c's scans while it trains and is scored (the
    numerics are unchanged; `bench.distill_step` measures the speed). A whole 60 s program is
    600 sequential steps per layer, forward and backward."""
    teacher_substeps: int = 0
    """Physics steps per control period of the arm the teacher plans in (0: the arm's own, 25 of
    4 ms). A planning copy (`mjx_arm.Arm.planning_copy`) with 5 runs five times fewer sequential
    steps; its commands are still scored in the arm itself (`studies.planning_arm` measures what
    the coarser arm costs the teacher)."""
    score_substeps: int = 0
    """Physics steps per control period of the arm the held-out programs are scored in, which
    picks the kept iterate (0: the arm's own, 25 of 4 ms). A planning copy of 5 scores five
    times faster (MuJoCo C): the chain's scorings of 48 programs of 900-1,500 simulated s took
    about 40 s each in the arm, four per run (`docs/chain.md`)."""
    teacher_shard: int = 0
    """Programs the teacher plans per call, across splits, the cache written after each (0: a
    split per call), so that a run stopped at a deadline keeps the shards it finished; with
    the MJX teacher one call's wall time barely grows with its programs."""
    hold_factor: int = 0
    """k, the control periods each command is held, for the teacher and the distilled
    translators (0: the translators' own, which must agree). G_c gives one command per source
    step whatever k is; a k at which the D_c arm keeps up with the targets keeps the teacher
    off the valve limits (`studies.mpc_saturation`)."""

    def __post_init__(self):
        """Refuses settings that would fail late, after the teacher's commands are computed and
        cached (ConfigError names the field)."""
        period = 1.0 / mjx_arm.CONTROL_HZ
        check_fields(
            self,
            at_least={
                "n_train": 0,
                "n_val": 0,
                "n_train_full": 0,
                "n_val_full": 0,
                "n_train_babble": 0,
                "n_val_babble": 0,
                "duration_s": period,
                "window_s": period,
                "horizon_steps": 1,
                "iterations": 1,
                "epochs": 1,
                "batch_size": 1,
                "eval_every": 1,
                "seed": 0,
                "max_wall_s": 0,
                "hold_factor": 0,
                "teacher_shard": 0,
                "teacher_substeps": 0,
                "score_substeps": 0,
                "generator_unroll": 1,
                "final_lr_factor": 0,
            },
            above={"head_weight": 0, "learning_rate": 0},
        )
        if self.teacher_backend not in ("c", "mjx"):
            raise ConfigError(
                "teacher_backend", f"must be 'c' or 'mjx', got {self.teacher_backend!r}"
            )
        if self.teacher_backend == "mjx" and self.horizon_steps != 1:
            raise ConfigError(
                "horizon_steps", f"must be 1 with teacher_backend 'mjx', got {self.horizon_steps}"
            )
        if self.batch_size > self.n_train_programs:
            raise ConfigError(
                "batch_size",
                f"must be <= n_train + n_train_full + n_train_babble = {self.n_train_programs}"
                f" training programs, got {self.batch_size}",
            )
        if self.n_val + self.n_val_full + self.n_val_babble < 1:
            raise ConfigError(
                "n_val", "plus n_val_full and n_val_babble must be >= 1 (held-out programs)"
            )

    @property
    def n_train_programs(self) -> int:
        """Training programs of every family."""
        return self.n_train + self.n_train_full + self.n_train_babble

    def teacher_key(self) -> dict:
        """The settings the cached teacher commands depend on (not the program counts)."""
        keys = ("duration_s", "horizon_steps", "iterations", "seed")
        key = {name: getattr(self, name) for name in keys}
        if self.teacher_backend != "c":  # caches of the C teacher keep their key
            key["teacher_backend"] = self.teacher_backend
            # TensorFloat32 plans (before MJX_MATMUL_PRECISION) are not reused
            key["mjx_matmul_precision"] = mjx_arm_arm.MJX_MATMUL_PRECISION
        if self.teacher_substeps:  # caches planned in the arm itself keep their key
            key["teacher_substeps"] = self.teacher_substeps
        return key


def _next_shard(pending: list, size: int) -> list:
    """Takes the next shard off `pending` [(split, programs [N, T, 3])]: `size` programs,
    across splits in order (0: the first split's whole rest, one split per shard)."""
    if size == 0:
        return [pending.pop(0)]
    shard = []
    while pending and size > 0:
        split, programs = pending[0]
        shard.append((split, programs[:size]))
        if len(programs) <= size:
            pending.pop(0)
        else:
            pending[0] = (split, programs[size:])
        size -= len(shard[-1][1])
    return shard


def _stop_check(config: DistillConfig, t0: float, stop: threading.Event | None):
    """`should_stop()` for the teacher: True once `config.max_wall_s` (0: no limit) seconds
    have passed since t0 (`time.perf_counter()`) or `stop` is set."""

    def should_stop() -> bool:
        late = config.max_wall_s > 0 and time.perf_counter() - t0 > config.max_wall_s
        return late or (stop is not None and stop.is_set())

    return should_stop


def _programs(config: DistillConfig, family: str, split: str, n: int) -> np.ndarray:
    """The first n programs [n, T, 3] (bar) of a split; program i is the same whatever n is."""
    if family == "babbling":
        spec = BabbleConfig(seed=config.seed, duration_s=config.duration_s)
        return babble_programs(spec, np.arange(n), domain="distill", split=split)
    full_scale = family == "shape_like_full"
    return shape_like_programs(
        n, config.duration_s, seed=config.seed, split=f"distill/{split}", full_scale=full_scale
    )


def _splits(config: DistillConfig) -> tuple:
    """(split, programs, family) of the teacher's data, in the order they are stored: the
    training splits, then the held-out ones; the families are shape-like at its scale, at full
    scale, and babbling."""
    return (
        ("train", config.n_train, "shape_like"),
        ("train_full", config.n_train_full, "shape_like_full"),
        ("train_babble", config.n_train_babble, "babbling"),
        ("val", config.n_val, "shape_like"),
        ("val_full", config.n_val_full, "shape_like_full"),
        ("val_babble", config.n_val_babble, "babbling"),
    )


def held_out_programs(config: DistillConfig) -> np.ndarray:
    """The held-out programs [V, T, 3] (bar) that pick a run's iterate, as `teacher_data`'s
    "p_val" holds them; rebuilt from the settings alone, without the teacher (studies score
    other commands on them)."""
    return np.concatenate(
        [
            _programs(config, family, split, n)
            for split, n, family in _splits(config)
            if split.startswith("val") and n > 0
        ]
    )


def teacher_cache_key(config: DistillConfig, k: int, model_hash: str) -> str:
    """The key a teacher cache (`teacher.npz`) is stored under: the settings its commands
    depend on, k and the arm; a cache under another key is planned again."""
    return json.dumps(config.teacher_key() | {"k": k, "model": model_hash}, sort_keys=True)


def adopt_teacher(source: Path, cache: Path, key: str) -> bool:
    """Copies the teacher cache `source` (another run's `teacher.npz`, e.g. a chain stage that
    only planned) to `cache`, unless `cache` exists already (this run's own, perhaps grown).
    Returns whether it copied.

    Raises:
      ValueError: `source` is unreadable, or was planned under another key (other settings,
        k or arm): using it would plan everything again, silently.
    """
    if cache.exists():
        return False
    try:
        with np.load(source) as f:
            stored = str(f["key"])
    except (OSError, ValueError, KeyError) as err:
        raise ValueError(f"{source} is not a teacher cache ({err})") from err
    if stored != key:
        raise ValueError(f"{source} was planned with other settings: {stored}, this run: {key}")
    link_or_copy(source, cache)
    return True


def teacher_data(
    config: DistillConfig,
    arm_s,
    arm_c,
    k: int,
    cache: Path | None,
    log=print,
    progress=False,
    should_stop=None,
):
    """Programs, D_s targets and teacher commands of the train and val splits.

    Program i of a split is the same whatever the split's size (`shape_like_programs`), and the
    teacher plans each program on its own, so the cache grows: a run asking for more programs
    than it holds computes only the missing ones; one asking for fewer reads a prefix.

    With the MJX teacher, `should_stop()` (checked between chunks of source steps) stops a
    shard part-way: its simulator states go to `teacher_partial.npz` beside the cache, and the
    next run goes on from there (`tracking.mpc_mjx.TrackingStopped` is raised).

    Returns:
      dict of float32 arrays, each split followed by its full-amplitude and babbling parts
      ("train" has n_train + n_train_full + n_train_babble programs, "val" the same of val):
      "p_train" [N, T, 3] and "p_val" (bar), "x_train" [N, T, 6] and
      "x_val" (m, unit d3), "c_train" [N, T, 3] and "c_val" (teacher commands per source step,
      bar), plus "teacher_val_x_err_cm" [n_val] (the teacher's own held-out X_err).
    """
    key = teacher_cache_key(config, k, arm_c.model_hash)
    splits = _splits(config)
    store: dict[str, np.ndarray] = {}
    if cache is not None and cache.exists():
        try:
            with np.load(cache) as f:
                if str(f["key"]) == key:
                    store = {name: f[name] for name in f.files if name != "key"}
                else:
                    log(f"{cache} was made with other settings; recomputing")
        except (OSError, ValueError, KeyError) as err:
            log(f"{cache} is unreadable ({err}); recomputing")
    mpc_cfg = mpc.MpcConfig(horizon_steps=config.horizon_steps, iterations=config.iterations)
    track, resumable = mpc.track, {}
    if config.teacher_backend == "mjx":
        partial = None if cache is None else cache.with_name(cache.stem + "_partial.npz")
        track, resumable = mpc_mjx.track, {"resume": partial, "should_stop": should_stop}
    plan_arm = arm_c.planning_copy(config.teacher_substeps)
    pending = []  # (split, its programs not planned yet), in the splits' order
    for split, n, family in splits:
        have = len(store.get(f"p_{split}", ()))
        if n == 0:
            continue
        if have >= n:
            log(f"teacher: {n} {split} programs read from {cache}")
            continue
        pending.append((split, _programs(config, family, split, n)[have:]))
    total, planned = sum(len(programs) for _, programs in pending), 0
    while pending:
        shard = _next_shard(pending, config.teacher_shard)
        t0 = time.perf_counter()
        programs = np.concatenate([piece for _, piece in shard])
        targets = arm_s.rollout(programs, backend="c")
        commands, _ = track(plan_arm, targets, k, programs, mpc_cfg, progress=progress, **resumable)
        new = {"p": programs, "x": targets, "c": commands[:, k - 1 :: k]}
        first = 0
        for split, piece in shard:
            for name, value in new.items():
                value = value[first : first + len(piece)].astype(np.float32)
                old = store.get(f"{name}_{split}", np.zeros((0,) + value.shape[1:], np.float32))
                store[f"{name}_{split}"] = np.concatenate([old, value])
            first += len(piece)
        planned += len(programs)
        what = " + ".join(f"{len(piece)} new {split} programs" for split, piece in shard)
        log(
            f"teacher ({config.teacher_backend}): {what} of {config.duration_s} s"
            f" ({time.perf_counter() - t0:.0f} s), {planned} of {total}"
        )
        if cache is not None:  # kept after each shard: a run stopped later plans the rest
            cache.parent.mkdir(parents=True, exist_ok=True)
            write_atomically(cache, lambda f: np.savez_compressed(f, key=key, **store))
    data = {}
    for part in ("p", "x", "c"):
        for joined in ("train", "val"):
            pieces = [
                store[f"{part}_{split}"][:n]
                for split, n, _ in splits
                if split.split("_")[0] == joined and n > 0
            ]
            data[f"{part}_{joined}"] = np.concatenate(pieces)
    score_arm = arm_c.planning_copy(config.score_substeps)
    poses = score_arm.rollout(np.repeat(data["c_val"], k, axis=1), backend="c")[:, k - 1 :: k]
    data["teacher_val_x_err_cm"] = position_error_cm(poses, data["x_val"]).mean(-1)
    return data


class ImitationData(NamedTuple):
    """What `distill` trains and scores on: `teacher_data`'s programs as the translator sees them.

    s_train [N, T, 9]: normalised samples (`ccgan.data.samples`) of the training programs;
    c_train [N, T, 3]: the teacher's commands for them (pressures normalised to [0, 1]);
    s_val [V, T, 9] and x_val [V, T, 6] (float64): the held-out programs' samples and D_s
    targets; p_val [V, T, 3]: their D_s commands (bar), which stretch only holds k periods;
    c_val [V, T, 3]: the teacher's held-out commands (bar); teacher_val_x_err_cm [V]: the
    teacher's own held-out X_err (cm); window: control steps in window_s.
    """

    s_train: Any
    c_train: Any
    s_val: Any
    x_val: np.ndarray
    p_val: np.ndarray
    c_val: np.ndarray
    teacher_val_x_err_cm: np.ndarray
    window: int


def imitation_data(
    config: DistillConfig,
    translator: Translator,
    arm_s,
    arm_c,
    k: int,
    cache: Path | None,
    log=print,
    progress=False,
    should_stop=None,
) -> ImitationData:
    """`teacher_data` (computed, or read from `cache`), normalised with the translator's bounds."""
    import jax.numpy as jnp

    data = teacher_data(config, arm_s, arm_c, k, cache, log, progress, should_stop)
    bounds = translator.bounds
    return ImitationData(
        s_train=jnp.asarray(samples(data["p_train"], data["x_train"], bounds)),
        c_train=jnp.asarray(normalise_pressure(data["c_train"]), jnp.float32),
        s_val=jnp.asarray(samples(data["p_val"], data["x_val"], bounds)),
        x_val=np.asarray(data["x_val"], np.float64),
        p_val=np.asarray(data["p_val"], np.float64),
        c_val=data["c_val"],
        teacher_val_x_err_cm=data["teacher_val_x_err_cm"],
        window=int(round(config.window_s * mjx_arm.CONTROL_HZ)),
    )


def head_weights(n_steps: int, window: int, head_weight: float):
    """[1, T, 1] weight of each step in the imitation loss: head_weight in the first `window`
    steps, 1 after, normalised to mean 1 (so head_weight moves emphasis, not the loss scale)."""
    import jax.numpy as jnp

    step_weight = jnp.where(jnp.arange(n_steps) < window, head_weight, 1.0)
    return (step_weight / step_weight.mean())[None, :, None]


def init_imitation(translators: list[Translator], config: DistillConfig, data: ImitationData):
    """(jitted Adam step, G_c parameters stacked over seeds [S, ...], their Adam state).

    `step(params, opt_state, s_batch [B, T, 9], c_batch [B, T, 3]) -> (params, opt_state,
    loss [S])`: every seed's step on one batch; the loss is the `head_weights`-weighted mean
    squared difference of G_c's normalised pressures from the teacher's.
    """
    import jax
    import jax.numpy as jnp
    import optax

    tr = translators[0]
    step_weight = head_weights(data.s_train.shape[1], data.window, config.head_weight)

    def loss_fn(g_params, s_batch, c_batch):
        out = tr.generator.apply(g_params, s_batch)[..., :PRESSURE_DIM]
        return jnp.mean(step_weight * (out - c_batch) ** 2)

    n_train = config.n_train_programs
    total_steps = config.epochs * (n_train // config.batch_size)
    rate = optax.cosine_decay_schedule(config.learning_rate, total_steps, config.final_lr_factor)
    opt = optax.adam(rate if config.final_lr_factor != 1.0 else config.learning_rate)
    stacked = jax.tree.map(lambda *x: jnp.stack(x), *[t.g_c_params for t in translators])
    opt_state = jax.vmap(opt.init)(stacked)

    @jax.jit
    def step(params, opt_state, s_batch, c_batch):
        loss, grads = jax.vmap(jax.value_and_grad(loss_fn), in_axes=(0, None, None))(
            params, s_batch, c_batch
        )
        updates, opt_state = jax.vmap(opt.update)(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss

    return step, stacked, opt_state


def window_and_whole_x_err_cm(arm_c, commands, k: int, x_val: np.ndarray, window: int):
    """(X_err over the first `window` steps, over the whole program), cm, per leading index of
    commands [..., B, T, 3] (bar) against the D_s targets x_val [B, T, 6].

    One MuJoCo C rollout of every command held k periods; rollouts are causal, so the window's
    poses are the whole rollout's first ones.
    """
    commands = np.asarray(commands, np.float64)
    flat = commands.reshape((-1,) + commands.shape[-2:])
    poses = run_dc(arm_c, stretch(flat, k), k, "c").reshape(commands.shape[:-1] + (6,))
    err = position_error_cm(poses, x_val)
    return err[..., :window].mean(axis=(-2, -1)), err.mean(axis=(-2, -1))


def make_validation(translator: Translator, arm_c, k: int, data: ImitationData):
    """`validate(params [S, ...]) -> {"score", "window", "whole"}`, each [S] in cm: every seed's
    commands for the held-out programs in one jitted call, scored in one MuJoCo C batch; the
    score is the mean of the X_err over the first window_s and over the whole program."""
    import jax

    tr = translator

    @jax.jit
    def val_commands(params):
        return jax.vmap(lambda g: generator_commands(tr, g, data.s_val))(params)

    def validate(params) -> dict:
        head, whole = window_and_whole_x_err_cm(
            arm_c, val_commands(params), k, data.x_val, data.window
        )
        return {"score": 0.5 * (whole + head), "window": head, "whole": whole}

    return validate


def _epoch(step, params, opt_state, data: ImitationData, order: np.ndarray, batch_size: int):
    """One pass over the training programs in `order`, `batch_size` at a time (a last partial
    batch is left out): (params, opt_state, mean loss [S]) after `init_imitation`'s steps."""
    losses = []
    for b in range(len(order) // batch_size):
        pick = np.sort(order[b * batch_size : (b + 1) * batch_size])
        params, opt_state, loss = step(params, opt_state, data.s_train[pick], data.c_train[pick])
        losses.append(np.asarray(loss))
    return params, opt_state, np.mean(losses, axis=0)


def _new_history(arm_c, k: int, data: ImitationData) -> dict:
    """The history of a distill run before its first epoch, with the held-out X_err (cm) over
    the whole programs and over their first window_s of the teacher and of stretch only (the
    D_s commands held k periods): what the translator must approach, and what it must beat."""
    teacher_whole = float(data.teacher_val_x_err_cm.mean())
    # The teacher's and stretch only's commands in one MuJoCo C batch.
    (head, stretch_head), (_, stretch_whole) = window_and_whole_x_err_cm(
        arm_c, np.stack([data.c_val, data.p_val]), k, data.x_val, data.window
    )
    return {
        "train_loss": [],
        "val": {},
        "teacher_val_x_err_cm": {"whole": teacher_whole, "window": float(head)},
        "stretch_val_x_err_cm": {"whole": float(stretch_whole), "window": float(stretch_head)},
        "complete": False,
        "k": k,
    }


def _best_of_seeds(best: BestIterates, history: dict, t0: float) -> list[dict]:
    """Each seed's best iterate so far; fills the history's summary fields (wall time since
    `t0`)."""
    history.update(
        epochs_run=len(history["train_loss"]),
        best_epoch=best.step.tolist(),
        val_x_err_cm_before=history["val"][0]["score"],
        best_val_x_err_cm=best.score.tolist(),
        wall_s=time.perf_counter() - t0,
    )
    return best.take(range(len(best.score)))


def _resume_key(config: DistillConfig, k: int, start_params) -> str:
    """What a saved training state must match: every setting but the time limit, k, and the
    starting parameters (the translators it was distilled from)."""
    import jax

    h = hashlib.sha256()
    settings = dataclasses.asdict(config) | {"max_wall_s": None, "k": k}
    if not config.score_substeps:  # states saved before the field existed stay valid
        settings.pop("score_substeps")
    h.update(json.dumps(settings, sort_keys=True).encode())
    for leaf in jax.tree.leaves(start_params):
        h.update(np.ascontiguousarray(np.asarray(leaf)).tobytes())
    return h.hexdigest()


def _save_training(path: Path, key: str, epoch: int, params, opt_state, best, history, rng):
    """Writes a stopped run's training state after `epoch` to `path` (atomically): the
    parameters, the optimiser's state, the best iterates, the history and the batch order's
    random state."""
    import jax

    arrays = {}
    for name, tree in (("params", params), ("opt", opt_state), ("best", best.params)):
        for i, leaf in enumerate(jax.tree.leaves(tree)):
            arrays[f"{name}{i}"] = np.asarray(leaf)
    write_atomically(
        path,
        lambda f: np.savez(
            f, key=key, epoch=epoch, best_score=best.score, best_step=best.step,
            history=json.dumps(history), rng=json.dumps(rng.bit_generator.state), **arrays,
        ),
    )  # fmt: skip


def _load_training(path: Path, key: str, params, opt_state, log):
    """(epoch, params, opt_state, best, history, rng) of `_save_training`'s file for the same
    `key`, shaped like the templates `params` and `opt_state`; None when there is none, it was
    saved for other settings or translators, or it is unreadable (training starts afresh)."""
    import jax

    if not path.exists():
        return None
    try:
        with np.load(path) as f:
            if str(f["key"]) != key:
                log(f"{path} was saved for other settings or translators; training afresh")
                return None
            trees = []
            for name, template in (("params", params), ("opt", opt_state), ("best", params)):
                leaves, treedef = jax.tree.flatten(template)
                saved = [f[f"{name}{i}"] for i in range(len(leaves))]
                if any(a.shape != np.shape(b) for a, b in zip(saved, leaves, strict=True)):
                    raise ValueError("leaf shapes differ")
                trees.append(jax.tree.unflatten(treedef, [jax.numpy.asarray(a) for a in saved]))
            best = BestIterates(trees[2], f["best_score"], f["best_step"])
            rng = np.random.default_rng()
            rng.bit_generator.state = json.loads(str(f["rng"]))
            history = json.loads(str(f["history"]))
            history["val"] = {int(e): v for e, v in history["val"].items()}
            return int(f["epoch"]), trees[0], trees[1], best, history, rng
    except (OSError, ValueError, KeyError) as err:
        log(f"{path} is unreadable ({err}); training afresh")
        return None


def with_generator_unroll(translators: list[Translator], unroll: int) -> list[Translator]:
    """The translators with G_c's LSTM scans unrolled `unroll` steps per loop iteration (the
    same parameters and numerics; a file written afterwards records the generator's shape, not
    the unroll)."""
    return [
        dataclasses.replace(t, generator=t.generator.clone(unroll=unroll))
        if t.generator.unroll != unroll
        else t
        for t in translators
    ]


def distill(
    translators: list[Translator],
    arm_s,
    arm_c,
    config: DistillConfig,
    cache: Path | None = None,
    progress: bool = True,
    log=print,
    on_validation=None,
    stop: threading.Event | None = None,
    resume: Path | None = None,
) -> tuple[list[dict], dict]:
    """Trains each translator's G_c to reproduce the teacher's commands.

    Args:
      translators: trained translators (the same generator shape; the same k unless
        `config.hold_factor` sets one), one per seed.
      arm_s, arm_c: the D_s and D_c arms.
      config: settings.
      cache: file for the teacher's commands (read when its settings match, else written).
      on_validation: optional callable(best parameters per translator, history), called after
        every validation but the first with the best iterates so far (e.g. to write them, so
        that a killed run keeps its progress); the history then has "complete": False.
      stop: once set (e.g. by SIGTERM), the teacher stops after its chunk of source steps
        (`TrackingStopped`) or training after its epoch, as at `config.max_wall_s`.
      resume: a file for the training state: written when `stop` stops training (after that
        epoch's validation), read at the start when saved for the same settings and
        translators, so that a stopped run goes on from its next epoch instead of from the
        start (a distillation of 240 epochs takes 200-250 s of one H100, longer than what a
        deadline leaves of a 10-minute call); removed when training ends otherwise.

    Returns:
      (best G_c parameters per translator, history: "train_loss" [epochs, S] (weighted mean
      squared normalised pressure error), "val" {epoch: {"score", "window", "whole"} [S] cm},
      "teacher_val_x_err_cm" and "stretch_val_x_err_cm" (whole, window), "best_epoch" [S]
      (0: the original was best),
      "best_val_x_err_cm" [S], "val_x_err_cm_before" [S] (at this k), "k", "wall_s").
    """
    k = config.hold_factor or common_k(translators)
    n_train = config.n_train_programs  # >= batch_size (DistillConfig checks)
    t0 = time.perf_counter()
    translators = with_generator_unroll(translators, config.generator_unroll)

    should_stop = _stop_check(config, t0, stop)
    data = imitation_data(
        config, translators[0], arm_s, arm_c, k, cache, log, progress, should_stop
    )
    step, stacked, opt_state = init_imitation(translators, config, data)
    score_arm = arm_c.planning_copy(config.score_substeps)
    validate = make_validation(translators[0], score_arm, k, data)
    key = _resume_key(config, k, stacked)
    saved = None if resume is None else _load_training(resume, key, stacked, opt_state, log)

    def validate_epoch(epoch: int, params) -> np.ndarray:
        """Scores the parameters, adds the scores to the history; returns the [S] score."""
        scores = validate(params)
        history["val"][epoch] = {name: v.tolist() for name, v in scores.items()}
        return scores["score"]

    if saved is None:
        first = 1
        history = _new_history(score_arm, k, data)
        best = BestIterates.start(stacked, validate_epoch(0, stacked))
        rng = np.random.default_rng(config.seed)
    else:
        done, stacked, opt_state, best, history, rng = saved
        first = done + 1
        log(f"resuming from {resume}: {done} of {config.epochs} epochs done")
    teacher = history["teacher_val_x_err_cm"]
    log(
        f"held-out X_err (cm; mean of first {config.window_s} s and whole): before"
        f" {np.round(history['val'][0]['score'], 4).tolist()}; teacher: window"
        f" {teacher['window']:.4f}, whole {teacher['whole']:.4f}"
    )
    latest: dict = {}  # the last epoch's (epoch, params, opt_state), kept for a stop

    def train_once(epoch: int, params, opt_state):
        """One pass over the teacher programs in a random order."""
        order = rng.permutation(n_train)
        params, opt_state, loss = _epoch(step, params, opt_state, data, order, config.batch_size)
        history["train_loss"].append(loss.tolist())
        latest.update(epoch=epoch, params=params, opt_state=opt_state)
        return params, opt_state, loss

    def report(best: BestIterates) -> None:
        on_validation(_best_of_seeds(best, history, t0), history)

    best = validated_loop(
        config.epochs,
        stacked,
        opt_state,
        best,
        train_once,
        validate_epoch,
        None if on_validation is None else report,
        config=config,
        t0=t0,
        desc="distill",
        unit="epoch",
        progress=progress,
        log=log,
        stop=stop,
        start=first,
    )
    history["complete"] = stop is None or not stop.is_set()
    if resume is not None and not history["complete"] and latest:
        _save_training(
            resume, key, latest["epoch"], latest["params"], latest["opt_state"], best, history, rng
        )
        log(f"training state after epoch {latest['epoch']} kept in {resume}")
    elif resume is not None and history["complete"]:
        resume.unlink(missing_ok=True)
    return _best_of_seeds(best, history, t0), history


def build_parser() -> argparse.ArgumentParser:
    """The options of `python -m ccgan.distill`."""
    p = stage_parser("ccgan.distill", __doc__, translators_required=False)
    add_config_flags(p, DistillConfig)
    p.add_argument(
        "--teacher-only",
        action="store_true",
        help="plan the teacher's commands into --out/teacher.npz and stop (a later run with the"
        " same flags trains on them): to split a long run into calls. Needs no --translators"
        " when --hold-factor is given, so a chain can plan while its translators train",
    )
    p.add_argument(
        "--teacher-from",
        metavar="FILE",
        help="start from the teacher cache FILE (the teacher.npz of a --teacher-only run with"
        " the same settings, k and arm), copied into --out unless --out has its own; one"
        " planned under other settings is refused",
    )
    return p


def main(argv=None) -> None:
    """CLI: `python -m ccgan.distill --translators A.ckpt [B.ckpt ...] --out DIR`."""
    p = build_parser()
    a = p.parse_args(argv)
    if not a.translators and not a.teacher_only:
        p.error("--translators is required (only --teacher-only plans without translators)")
    config = config_from_args(p, a, DistillConfig)
    if not a.translators and config.hold_factor == 0:
        p.error("--teacher-only without --translators needs --hold-factor (k)")
    stage = start_stage(p, a, "ccgan.distill", dataclasses.asdict(config), argv)
    stage.run["method"] = "distill"
    if config.hold_factor == 0:
        try:
            common_k(stage.translators)
        except ValueError as err:
            p.error(f"{err}: give --hold-factor")
    if a.teacher_from:
        k = config.hold_factor or common_k(stage.translators)
        key = teacher_cache_key(config, k, stage.arm_c.model_hash)
        try:
            if adopt_teacher(Path(a.teacher_from), stage.out / "teacher.npz", key):
                print(f"teacher: started from {a.teacher_from}")
        except ValueError as err:
            p.error(f"--teacher-from: {err}")

    # SIGTERM (a time limit, experiments.stages at its deadline) stops the teacher after its
    # chunk of source steps (its progress kept) or training after its epoch (its best iterates
    # written); exit status 143 says the run is unfinished: rerun the same command to go on.
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        _run(a, config, stage, stop)
    except mpc_mjx.TrackingStopped as err:
        print(f"teacher: {err}: rerun the same command to go on", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM)
    finally:
        signal.signal(signal.SIGTERM, previous)
    if stop.is_set():
        print("stopped by SIGTERM: rerun the same command to go on", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM)


def _run(a: argparse.Namespace, config: DistillConfig, stage, stop: threading.Event) -> None:
    """`main`'s work: the teacher only, or the whole distillation."""
    if a.teacher_only:
        k = config.hold_factor or common_k(stage.translators)
        t0 = time.perf_counter()

        should_stop = _stop_check(config, t0, stop)
        data = teacher_data(
            config, stage.arm_s, stage.arm_c, k, stage.out / "teacher.npz", progress=True,
            should_stop=should_stop,
        )  # fmt: skip
        print(
            f"wrote {stage.out / 'teacher.npz'}: {len(data['p_train'])} training and"
            f" {len(data['p_val'])} held-out programs; the teacher's held-out X_err"
            f" {data['teacher_val_x_err_cm'].mean():.4f} cm"
        )
        return

    def write(params, history) -> None:
        """The best translators so far and the history (rewritten at every validation)."""
        per_seed = [
            {
                "complete": history["complete"],
                "best_epoch": history["best_epoch"][s_i],
                "val_x_err_cm_before": history["val_x_err_cm_before"][s_i],
                "val_x_err_cm_best": history["best_val_x_err_cm"][s_i],
            }
            for s_i in range(len(stage.seeds))
        ]
        stage.write(params, per_seed, history, "distill.json", k=history["k"])

    params, history = distill(
        stage.translators,
        stage.arm_s,
        stage.arm_c,
        config,
        cache=stage.out / "teacher.npz",
        on_validation=write,
        stop=stop,
        resume=stage.out / "training_state.npz",
    )
    write(params, history)
    print(
        f"wrote {stage.out}: held-out X_err (cm) before"
        f" {np.round(history['val_x_err_cm_before'], 4).tolist()} -> best"
        f" {np.round(history['best_val_x_err_cm'], 4).tolist()} at epochs"
        f" {history['best_epoch']}; teacher {history['teacher_val_x_err_cm']};"
        f" stretch only {history['stretch_val_x_err_cm']}; "
        f"{history['wall_s']:.1f} s"
    )


if __name__ == "__main__":
    main()
