"""Simulator-in-the-loop fine-tuning of a trained G_c through the differentiable MJX rollout.

`ccgan.train` teaches G_c to track through the learned forward model F_c, whose own open-loop
error (0.19 cm over 60 s on the paper-scale data) is several times the tracking errors that
separate the methods in `eval/`. Here the feedback loss is taken through the simulator itself:

    D_s program p_s [T, 3] --D_s sim--> target poses x_s [T, 6]
    G_c(p_s, x_s) -> D_c commands [T, 3], each held k periods --MJX D_c rollout from rest-->
    every k-th pose x_c [T, 6];   loss = mean(X_err_cm^2) + w^2 mean(phi_err^2)

and only G_c's weights change (Adam, small steps), starting from the trained translator. The
programs are `window_s` seconds from rest, drawn from their own random stream, never the
evaluation shapes: motor-babbling programs (`programs="babble"`) or random programs of the
shapes' signal types (`programs="shape_like"`, `mjx_arm.programs.shape_like_program`: ellipses,
spirals, polygons, staircases, phase jumps); their D_s targets come from one MuJoCo C batch.

The simulator's gradient only reaches the first `window_s` seconds of a program; left alone,
the rest of G_c's behaviour drifts (bench/results/cpu/finetune_window.md: without an anchor,
the five shapes' first 2 s went from 0.10-0.13 to 0.05-0.07 cm X_err, their whole 60 s from
0.040-0.061 to 0.070-0.092 cm). An anchor term keeps G_c's commands after the window
close to the trained translator's on longer programs (`anchor_s`):
anchor_weight * mean((G_c - G_c_trained)^2) over normalised pressures, for t >= window.

Several trained seeds are fine-tuned together, each with every learning rate (their parameters
vmapped over one rollout batch). The held-out score is the mean of the X_err (cm, MuJoCo C) on
held-out `window_s` programs and on held-out long programs (`val_long_s`, default `anchor_s`);
each seed's best iterate by that score is what is written, so a fine-tune that makes things
worse writes the original. A weak anchor can trade the long programs for the window
(bench/results/cpu/finetune_window.md: stages 2-3 improved the 10 s held-out programs while the
shapes' 60 s error rose); `--val-long-s 60` scores on programs of the evaluation's length
instead, at six times the validation rollouts. Babbling programs do not stand for the shapes' slow
periodic programs; with `--programs shape_like` every training, anchor and held-out program
is shape-like (README: stages 4-5).

The output files are translator checkpoints like `ccgan.train`'s (same generator, F_c, k and
pose bounds; the fine-tuning settings and history added to their metadata), named
`translator_seed{s}.ckpt` and `translator.ckpt` (a link to the first seed's), for
`ccgan.load_translator` and `python -m eval.shapes --ccgan-sim-path`.

    python -m ccgan.finetune \\
        --translators results/paper/rerun_2026-11-27/run/ccgan/translator_seed{0,1,2}.ckpt \\
        --seeds 0 1 2 --out runs/ccgan_ft

The CLI simulates the arm of `--model` (default `mjx_arm.constants.TRANSLATOR_MODEL_PATH`,
models/softarm.xml, the I-Support arm the committed translators were trained on;
`models/softarm_linear.xml` is the previous, linear-law arm, whose translators are in
results/paper/run/, and `models/softarm_solid.xml` the earlier solid-disc arm, whose
translators are in results/solid/translators/)
in D_s and in `--domain`, and refuses translators whose file records another arm's model hash.

Gradients through thousands of MJX physics steps are slow on a CPU: use a GPU for real runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from typing import Any, NamedTuple

import numpy as np

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from ccgan.cli import add_config_flags, config_from_args
from ccgan.data import PRESSURE_DIM, samples

# save_finetuned and trained_model_hash stay importable from here (eval.methods, tests).
from ccgan.stage import (  # noqa: F401
    BestIterates,
    common_k,
    generator_commands,
    save_finetuned,
    stage_parser,
    start_stage,
    trained_model_hash,
    validated_loop,
)
from ccgan.translator import Translator
from mjx_arm import constants
from mjx_arm.programs import babble_programs, shape_like_programs
from tracking.config import ConfigError, check_fields
from tracking.held import run_dc, stretch
from tracking.metrics import position_error_cm, tracking_loss

#: Program families a fine-tune can draw from (`FinetuneConfig.programs`).
PROGRAM_FAMILIES = ("babble", "shape_like")


@dataclasses.dataclass(frozen=True)
class FinetuneConfig:
    """Settings of a simulator-in-the-loop fine-tune."""

    programs: str = "babble"
    """Program family of every training, anchor and held-out program: "babble" (motor
    babbling, `mjx_arm.babble`) or "shape_like" (`mjx_arm.programs.shape_like_program`: random
    ellipses, polygons, staircases and phase jumps like the test shapes, never one of them)."""
    steps: int = 40
    """Adam steps."""
    batch_size: int = 16
    """Babbling programs per step (shared by every seed)."""
    window_s: float = 2.0
    """Length of each program, from rest (s of source time, 10 Hz)."""
    n_train: int = 256
    """Training programs (each family's "finetune" stream)."""
    n_val: int = 32
    """Held-out programs of `window_s` (and as many long ones) that pick the best iterate."""
    anchor_s: float = 10.0
    """Length of the anchor programs (s)."""
    val_long_s: float = 0.0
    """Length of the long held-out programs (s); 0: `anchor_s`."""
    n_anchor: int = 32
    """Anchor programs (all used in every step: G_c alone, no simulation)."""
    anchor_weights: tuple[float, ...] = (30.0, 300.0)
    """Weights of the anchor term (cm^2 of tracking loss per unit of mean squared normalised
    pressure difference; 0 turns it off), each run with every seed and learning rate."""
    learning_rates: tuple[float, ...] = (1e-4, 3e-4, 1e-3)
    """Adam step sizes, each run for every seed in the same batch; per seed, the best iterate
    over all of them (by the held-out error) is kept."""
    orientation_weight_cm_per_rad: float = 10.0
    """How many cm of position error one rad of orientation error is worth in the loss."""
    eval_every: int = 5
    """Steps between validation scores (and the first and last step)."""
    seed: int = 0
    """Seed of the programs and of the batch order."""
    max_wall_s: float = 0.0
    """Stop after this many seconds (0: no limit); the best iterate so far is kept."""
    hold_factor: int = 0
    """k, the control periods each command is held, for every fine-tuned translator (0: the
    translators' own, which must agree); the written files record it."""
    sim_substeps: int = 0
    """Physics steps per control period of the arm the gradient runs through (0: the arm's own,
    25 of 4 ms; 5: a planning copy, `mjx_arm.Arm.planning_copy`: the oracle's Adam steps through
    such a copy took 5.9 s on an H100, against 18-20 s through the arm, `docs/chain.md`).
    Held-out scores stay in the arm itself (MuJoCo C)."""

    def __post_init__(self):
        """Refuses settings that would fail late or compute nothing (ConfigError names the field).

        The anchor term compares G_c after the window, so anchor programs must be at least one
        control period longer than `window_s` (else the term is a mean over nothing: NaN).
        """
        if self.programs not in PROGRAM_FAMILIES:
            raise ConfigError(
                "programs", f"must be one of {PROGRAM_FAMILIES}, got {self.programs!r}"
            )
        period = 1.0 / constants.CONTROL_HZ
        check_fields(
            self,
            at_least={
                "steps": 1,
                "batch_size": 1,
                "window_s": period,
                "n_train": 1,
                "n_val": 1,
                "val_long_s": 0,
                "n_anchor": 1,
                "anchor_weights": 0,
                "orientation_weight_cm_per_rad": 0,
                "eval_every": 1,
                "seed": 0,
                "max_wall_s": 0,
                "hold_factor": 0,
                "sim_substeps": 0,
            },
            above={"learning_rates": 0},
        )
        if self.batch_size > self.n_train:
            raise ConfigError(
                "batch_size", f"must be <= n_train = {self.n_train}, got {self.batch_size}"
            )
        if not self.anchor_s >= self.window_s + period:
            raise ConfigError(
                "anchor_s",
                f"must exceed window_s = {self.window_s} by a control period ({period} s),"
                f" got {self.anchor_s}",
            )
        if 0 < self.val_long_s < period:
            raise ConfigError("val_long_s", f"must be 0 or >= {period} s, got {self.val_long_s}")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def training_programs(
    config: FinetuneConfig, n: int, split: str, duration_s: float | None = None
) -> np.ndarray:
    """[n, T, 3] programs (bar) of `config.programs`' family and `duration_s` (default
    `window_s`) seconds, from the split's own random stream."""
    duration_s = config.window_s if duration_s is None else duration_s
    if config.programs == "shape_like":
        return shape_like_programs(n, duration_s, seed=config.seed, split=f"finetune/{split}")
    from mjx_arm import babble

    bcfg = babble.BabbleConfig(seed=config.seed, duration_s=duration_s, n_train=n, n_val=0)
    return babble_programs(bcfg, range(n), domain="finetune", split=split)


def x_err_cm_c(arm_c, commands_bar: np.ndarray, k: int, target: np.ndarray):
    """Mean X_err (cm) of held commands [..., B, T, 3] in the MuJoCo C simulator against the
    targets [B, T, 6], all in one batched rollout; a float for [B, T, 3], else an array [...]."""
    commands_bar = np.asarray(commands_bar)
    lead = commands_bar.shape[:-3]
    flat = commands_bar.reshape((-1,) + commands_bar.shape[-2:])
    poses = run_dc(arm_c, stretch(flat, k), k, "c").reshape(lead + np.shape(target))
    err = position_error_cm(poses, target).mean(axis=(-2, -1))
    return float(err) if not lead else err


class FinetuneData(NamedTuple):
    """The programs of a fine-tune as normalised samples (`ccgan.data.samples`, [..., 9]) and
    their D_s targets ([..., 6]: tip xyz m, unit d3), simulated in MuJoCo C from rest.

    s_train [N, T, 9] (NumPy: batches are picked on the host), x_train [N, T, 6]: training
    programs of window_s; s_val [V, T, 9], x_val [V, T, 6]: held-out ones; s_anchor [A, T_a, 9]:
    anchor programs of anchor_s; s_long [V, T_l, 9], x_long [V, T_l, 6]: held-out programs of
    val_long_s (0: anchor_s); window_steps: T.
    """

    s_train: np.ndarray
    x_train: np.ndarray
    s_val: Any
    x_val: np.ndarray
    s_anchor: Any
    s_long: Any
    x_long: np.ndarray
    window_steps: int


def finetune_data(config: FinetuneConfig, arm_s, bounds, log=print) -> FinetuneData:
    """Draws every split's programs (`training_programs`) and simulates their D_s targets.

    Args:
      config: settings (program family, counts, lengths, seed).
      arm_s: the D_s arm.
      bounds: the translator's pose bounds, which normalise the samples.
    """
    import jax.numpy as jnp

    t0 = time.perf_counter()
    p_train = training_programs(config, config.n_train, "train")
    p_val = training_programs(config, config.n_val, "val")
    x_train = arm_s.rollout(p_train, backend="c")
    x_val = arm_s.rollout(p_val, backend="c")
    long_s = config.val_long_s or config.anchor_s
    p_anchor = training_programs(config, config.n_anchor, "anchor", config.anchor_s)
    p_long = training_programs(config, config.n_val, "val_long", long_s)
    x_anchor = arm_s.rollout(p_anchor, backend="c")
    x_long = arm_s.rollout(p_long, backend="c")
    log(
        f"D_s targets: {config.n_train} + {config.n_val} programs of {config.window_s} s,"
        f" {config.n_anchor} of {config.anchor_s} s, {config.n_val} of {long_s} s"
        f" ({time.perf_counter() - t0:.1f} s)"
    )
    return FinetuneData(
        s_train=samples(p_train, x_train, bounds),
        x_train=x_train,
        s_val=jnp.asarray(samples(p_val, x_val, bounds)),
        x_val=x_val,
        s_anchor=jnp.asarray(samples(p_anchor, x_anchor, bounds)),
        s_long=jnp.asarray(samples(p_long, x_long, bounds)),
        x_long=x_long,
        window_steps=p_train.shape[1],
    )


def member_grid(n_seeds: int, config: FinetuneConfig) -> list[tuple[int, float, float]]:
    """The members trained side by side (one vmapped batch): every seed index with every
    learning rate and anchor weight, as (seed index, learning rate, anchor weight)."""
    return [
        (s, lr, aw)
        for s in range(n_seeds)
        for lr in config.learning_rates
        for aw in config.anchor_weights
    ]


def init_members(translators: list[Translator], members, config: FinetuneConfig):
    """(optimiser, G_c parameters stacked over members [M, ...], the optimiser state of every
    member, anchor weights [M]).

    Adam's step size is part of the optimiser state (`optax.inject_hyperparams`), one per
    member, so every learning rate runs in the same compiled step.
    """
    import jax
    import jax.numpy as jnp
    import optax

    opt = optax.inject_hyperparams(optax.adam)(learning_rate=config.learning_rates[0])
    stacked = jax.tree.map(
        lambda *x: jnp.stack(x), *[translators[m[0]].g_c_params for m in members]
    )
    opt_state = jax.vmap(opt.init)(stacked)
    opt_state.hyperparams["learning_rate"] = jnp.asarray([m[1] for m in members], jnp.float32)
    anchor_weights = jnp.asarray([m[2] for m in members], jnp.float32)
    return opt, stacked, opt_state, anchor_weights


def make_finetune_step(
    translator: Translator, arm_c, k: int, config: FinetuneConfig, window_steps: int, opt
):
    """The jitted Adam step of every member at once.

    `step(params, opt_state, trained, anchor_weights, s_anchor, s_batch, x_batch) -> (params,
    opt_state, tracking loss [M] (cm^2))`, for parameters and trained parameters stacked over
    members [M, ...], anchor weights [M], anchor samples [A, T_a, 9], a batch of samples
    [B, T, 9] and its D_s targets [B, T, 6]. A member's loss is its tracking loss through the MJX
    D_c rollout (each command held k periods, every k-th pose scored) plus its anchor weight times
    the mean squared difference of its commands from the trained G_c's after the window.

    The trained parameters and the anchor data are arguments, not constants folded into the
    compiled step, so the persistent compilation cache serves every start point.
    """
    import jax
    import jax.numpy as jnp
    import optax

    tr = translator
    rollout = jax.vmap(arm_c.rollout_fn(), in_axes=(None, 0))
    mjx_model = arm_c.mjx_model
    w = config.orientation_weight_cm_per_rad

    def loss_one(g_params, g_trained, anchor_weight, s_anchor, s_batch, x_batch):
        """(Total loss, tracking part) for one member's parameters."""
        commands = generator_commands(tr, g_params, s_batch)
        poses, ok = rollout(mjx_model, jnp.repeat(commands, k, axis=-2))
        per_program = tracking_loss(poses[:, k - 1 :: k], x_batch, w)
        # A diverged rollout (never seen in practice) adds nothing rather than NaN.
        tracking = jnp.where(ok[:, -1], per_program, 0.0).mean()
        after = slice(window_steps, None)
        drift = (
            tr.generator.apply(g_params, s_anchor)[:, after, :PRESSURE_DIM]
            - tr.generator.apply(g_trained, s_anchor)[:, after, :PRESSURE_DIM]
        )
        return tracking + anchor_weight * jnp.mean(drift**2), tracking

    @jax.jit
    def step(params, opt_state, trained, anchor_weights, s_anchor, s_batch, x_batch):
        grad_fn = jax.value_and_grad(loss_one, has_aux=True)
        (_, loss), grads = jax.vmap(grad_fn, in_axes=(0, 0, 0, None, None, None))(
            params, trained, anchor_weights, s_anchor, s_batch, x_batch
        )
        updates, opt_state = jax.vmap(opt.update)(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss

    return step


def make_validation(translator: Translator, arm_c, k: int, data: FinetuneData):
    """`validate(params [M, ...]) -> (score, window programs' X_err, long programs' X_err)`, each
    [M] in cm: every member's commands for the held-out programs in one jitted call, scored in
    one MuJoCo C batch per program set; the score is the mean of the two."""
    import jax

    tr = translator

    @jax.jit
    def val_commands(params):
        short = jax.vmap(lambda g: generator_commands(tr, g, data.s_val))(params)
        long = jax.vmap(lambda g: generator_commands(tr, g, data.s_long))(params)
        return short, long

    def validate(params) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        short, long = (np.asarray(c, np.float64) for c in val_commands(params))
        err_short = x_err_cm_c(arm_c, short, k, data.x_val)
        err_long = x_err_cm_c(arm_c, long, k, data.x_long)
        return 0.5 * (err_short + err_long), err_short, err_long

    return validate


def hold_factor(translators: list[Translator], config: FinetuneConfig) -> int:
    """The k every translator is fine-tuned (and written) at: `config.hold_factor`, else the
    translators' own, which must agree (ValueError otherwise)."""
    return config.hold_factor or common_k(translators)


def _new_history(members) -> dict:
    """The history of a fine-tune before its first step (`finetune` documents its fields)."""
    return {
        "members": members,
        "val_window_x_err_cm": [],
        "val_long_x_err_cm": [],
        "train_loss": [],
        "step_wall_s": [],
        "val_x_err_cm": {},
        "complete": False,
    }


def _record_validation(history: dict, step: int, scores) -> np.ndarray:
    """Adds one validation's scores (`make_validation`) to the history; returns the [M] score."""
    score, err_short, err_long = scores
    history["val_x_err_cm"][step] = score.tolist()
    history["val_window_x_err_cm"].append(err_short.tolist())
    history["val_long_x_err_cm"].append(err_long.tolist())
    return score


def _best_per_seed(best: BestIterates, members, n_seeds: int, history: dict, t0: float):
    """Per seed, the best iterate of its member (learning rate, anchor weight) with the lowest
    held-out score so far; fills the history's summary fields (wall time since `t0`)."""
    pick = [
        min((m for m, member in enumerate(members) if member[0] == s), key=lambda m: best.score[m])
        for s in range(n_seeds)
    ]
    history["steps_run"] = len(history["train_loss"])
    history["best_step"] = [int(best.step[m]) for m in pick]
    history["best_learning_rate"] = [members[m][1] for m in pick]
    history["best_anchor_weight"] = [members[m][2] for m in pick]
    history["val_x_err_cm_before"] = [float(history["val_x_err_cm"][0][m]) for m in pick]
    history["best_val_x_err_cm"] = [float(best.score[m]) for m in pick]
    history["wall_s"] = time.perf_counter() - t0
    return best.take(pick)


def finetune(
    translators: list[Translator],
    arm_s,
    arm_c,
    config: FinetuneConfig,
    progress: bool = True,
    log=print,
    on_validation=None,
) -> tuple[list[dict], dict]:
    """Fine-tunes each translator's G_c through the MJX D_c rollout.

    Args:
      translators: trained translators (the same generator shape and k), one per seed.
      arm_s, arm_c: the D_s and D_c arms (`mjx_arm.load`).
      config: fine-tuning settings.
      on_validation: optional callable(best parameters per translator, history), called after
        every validation with the best iterates so far (e.g. to write them, so that a run that
        is killed keeps its progress); the history then has "complete": False.

    Returns:
      (best G_c parameters per translator, history: "members" [M] (seed index, learning
      rate, anchor weight) for M = seeds x learning rates x anchor weights, "train_loss"
      [steps, M] (the tracking part, cm^2), "val_x_err_cm" {step: [M]} (held-out score),
      "val_window_x_err_cm" and "val_long_x_err_cm" [validations, M] (its two parts),
      "best_step" [S] (0: the original was best), "best_learning_rate" [S],
      "best_anchor_weight" [S], "best_val_x_err_cm" [S], "wall_s", "step_wall_s").
    """
    import jax.numpy as jnp

    k = hold_factor(translators, config)
    tr = translators[0]
    t0 = time.perf_counter()
    data = finetune_data(config, arm_s, tr.bounds, log)
    members = member_grid(len(translators), config)
    opt, trained, opt_state, anchor_weights = init_members(translators, members, config)
    sim_arm = arm_c.planning_copy(config.sim_substeps)
    step = make_finetune_step(tr, sim_arm, k, config, data.window_steps, opt)
    validate = make_validation(tr, arm_c, k, data)
    history = _new_history(members) | {"k": int(k)}
    best = BestIterates.start(trained, _record_validation(history, 0, validate(trained)))
    log(f"validation X_err before fine-tuning (cm): {np.round(best.score, 4).tolist()}")
    rng = np.random.default_rng(config.seed)

    def train_once(i: int, params, opt_state):
        """One Adam step of every member on a random batch of the training programs."""
        pick = rng.choice(config.n_train, size=config.batch_size, replace=False)
        t_step = time.perf_counter()
        x_batch = jnp.asarray(data.x_train[pick], jnp.float32)
        batch = (data.s_anchor, jnp.asarray(data.s_train[pick]), x_batch)
        params, opt_state, loss = step(params, opt_state, trained, anchor_weights, *batch)
        loss = np.asarray(loss)
        history["step_wall_s"].append(time.perf_counter() - t_step)
        history["train_loss"].append(loss.tolist())
        return params, opt_state, loss

    def report(best: BestIterates) -> None:
        on_validation(_best_per_seed(best, members, len(translators), history, t0), history)

    best = validated_loop(
        config.steps,
        trained,
        opt_state,
        best,
        train_once,
        lambda i, params: _record_validation(history, i, validate(params)),
        None if on_validation is None else report,
        config=config,
        t0=t0,
        desc="finetune",
        unit="step",
        progress=progress,
        log=log,
    )
    history["complete"] = True
    return _best_per_seed(best, members, len(translators), history, t0), history


def build_parser() -> argparse.ArgumentParser:
    """The options of `python -m ccgan.finetune`."""
    p = stage_parser("ccgan.finetune", __doc__)
    add_config_flags(p, FinetuneConfig, choices={"programs": PROGRAM_FAMILIES})
    return p


def main(argv=None) -> None:
    """CLI: `python -m ccgan.finetune --translators A.ckpt [B.ckpt ...] --out DIR`."""
    p = build_parser()
    a = p.parse_args(argv)
    config = config_from_args(p, a, FinetuneConfig)
    stage = start_stage(p, a, "ccgan.finetune", config.to_dict(), argv)
    try:
        hold_factor(stage.translators, config)
    except ValueError as err:
        p.error(f"{err}: give --hold-factor")

    def write(params, history) -> None:
        """The best translators so far and the history (rewritten at every validation, so a
        killed run keeps its progress)."""
        keys = ("best_step", "best_learning_rate", "best_anchor_weight", "val_x_err_cm_before")
        per_seed = [
            {"complete": history["complete"]}
            | {key: history[key][s_i] for key in keys}
            | {"val_x_err_cm_best": history["best_val_x_err_cm"][s_i]}
            for s_i in range(len(stage.seeds))
        ]
        stage.write(params, per_seed, history, "finetune.json", k=history["k"])

    params, history = finetune(
        stage.translators, stage.arm_s, stage.arm_c, config, on_validation=write
    )
    write(params, history)
    before = np.round(history["val_x_err_cm_before"], 4).tolist()
    print(
        f"wrote {stage.out}: validation X_err (cm) before {before}"
        f" -> best {np.round(history['best_val_x_err_cm'], 4).tolist()}"
        f" at steps {history['best_step']}; {history['wall_s']:.1f} s"
    )


if __name__ == "__main__":
    main()
