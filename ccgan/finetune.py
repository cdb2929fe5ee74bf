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
`translator_seed{s}.ckpt` and `translator.ckpt` (the first seed), for `ccgan.load_translator`
and `python -m eval.shapes --ccgan-path`.

    python -m ccgan.finetune --translators results/ccgan/translator_seed{0,1,2}.ckpt \\
        --seeds 0 1 2 --out results/ccgan_sim

The CLI simulates the arm of `--model` (default `mjx_arm.constants.SOLID_MODEL_PATH`, the
solid-disc arm every committed translator was trained on; `models/softarm.xml` is another arm)
in D_s and in `--domain`, and refuses translators whose file records another arm's model hash.

Gradients through thousands of MJX physics steps are slow on a CPU: use a GPU for real runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from ccgan import checkpoint
from ccgan.cli import add_config_flags, check_output_dir, cli_parser, config_from_args
from ccgan.data import PRESSURE_DIM, denormalise_pressure, samples
from ccgan.translator import Translator, translator_from_checkpoint
from mjx_arm import constants
from mjx_arm.programs import shape_like_programs
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
    return babble.make_programs(bcfg, range(n), domain="finetune", split=split)


def generator_commands(translator: Translator, g_params, samples_s):
    """G_c's D_c commands [B, T, 3] (bar, one per source step) for normalised D_s samples
    [B, T, 9] (`ccgan.data.samples`); differentiable in g_params."""
    out = translator.generator.apply(g_params, samples_s)
    return denormalise_pressure(out[..., :PRESSURE_DIM])


def x_err_cm_c(arm_c, commands_bar: np.ndarray, k: int, target: np.ndarray):
    """Mean X_err (cm) of held commands [..., B, T, 3] in the MuJoCo C simulator against the
    targets [B, T, 6], all in one batched rollout; a float for [B, T, 3], else an array [...]."""
    commands_bar = np.asarray(commands_bar)
    lead = commands_bar.shape[:-3]
    flat = commands_bar.reshape((-1,) + commands_bar.shape[-2:])
    poses = run_dc(arm_c, stretch(flat, k), k, "c").reshape(lead + np.shape(target))
    err = position_error_cm(poses, target).mean(axis=(-2, -1))
    return float(err) if not lead else err


def common_k(translators: list[Translator]) -> int:
    """The hold factor k every translator shares.

    Raises:
      ValueError: no translators, or they disagree on k.
    """
    if not translators:
        raise ValueError("need at least one translator")
    k = translators[0].k
    if any(t.k != k for t in translators):
        raise ValueError(f"translators disagree on k: {[t.k for t in translators]}")
    return k


def keep_better(best_params, params, better: np.ndarray):
    """Stacked parameters [M, ...]: params where better [M] is True, else best_params."""
    import jax
    import jax.numpy as jnp

    return jax.tree.map(
        lambda b, p: jnp.where(better.reshape((-1,) + (1,) * (p.ndim - 1)), p, b),
        best_params,
        params,
    )


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
    import jax
    import jax.numpy as jnp
    import optax
    from tqdm.auto import tqdm

    k = common_k(translators)
    tr = translators[0]
    w = config.orientation_weight_cm_per_rad

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
    window_steps = p_train.shape[1]

    rollout = jax.vmap(arm_c.rollout_fn(), in_axes=(None, 0))
    mjx_model = arm_c.mjx_model

    s_train = samples(p_train, x_train, tr.bounds)
    s_val = jnp.asarray(samples(p_val, x_val, tr.bounds))
    s_anchor = jnp.asarray(samples(p_anchor, x_anchor, tr.bounds))
    s_long = jnp.asarray(samples(p_long, x_long, tr.bounds))

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

    # Members: every seed with every learning rate and anchor weight, trained side by side (one
    # vmapped batch).
    members = [
        (s, lr, aw)
        for s in range(len(translators))
        for lr in config.learning_rates
        for aw in config.anchor_weights
    ]
    opt = optax.inject_hyperparams(optax.adam)(learning_rate=config.learning_rates[0])
    stacked = jax.tree.map(
        lambda *x: jnp.stack(x), *[translators[m[0]].g_c_params for m in members]
    )
    opt_state = jax.vmap(opt.init)(stacked)
    opt_state.hyperparams["learning_rate"] = jnp.asarray([m[1] for m in members], jnp.float32)
    trained = stacked
    anchor_weights = jnp.asarray([m[2] for m in members], jnp.float32)

    # The trained parameters and the anchor data are arguments, not constants folded into the
    # compiled step, so the persistent compilation cache serves every start point.
    @jax.jit
    def step(params, opt_state, trained, anchor_weights, s_anchor, s_batch, x_batch):
        grad_fn = jax.value_and_grad(loss_one, has_aux=True)
        (_, loss), grads = jax.vmap(grad_fn, in_axes=(0, 0, 0, None, None, None))(
            params, trained, anchor_weights, s_anchor, s_batch, x_batch
        )
        updates, opt_state = jax.vmap(opt.update)(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss

    @jax.jit
    def val_commands(params):
        short = jax.vmap(lambda g: generator_commands(tr, g, s_val))(params)
        long = jax.vmap(lambda g: generator_commands(tr, g, s_long))(params)
        return short, long

    def validate(params) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """([M] held-out score: the mean of its two parts, [M] window programs' X_err, [M] long
        programs' X_err), in cm."""
        short, long = (np.asarray(c, np.float64) for c in val_commands(params))
        err_short = x_err_cm_c(arm_c, short, k, x_val)
        err_long = x_err_cm_c(arm_c, long, k, x_long)
        return 0.5 * (err_short + err_long), err_short, err_long

    def record_validation(step_index: int, params) -> np.ndarray:
        """Validates, adds the scores to the history and returns the [M] held-out score."""
        score, err_short, err_long = validate(params)
        history["val_x_err_cm"][step_index] = score.tolist()
        history["val_window_x_err_cm"].append(err_short.tolist())
        history["val_long_x_err_cm"].append(err_long.tolist())
        return score

    history = {
        "members": members,
        "val_window_x_err_cm": [],
        "val_long_x_err_cm": [],
        "train_loss": [],
        "step_wall_s": [],
        "val_x_err_cm": {},
        "complete": False,
    }
    best_params = stacked
    best_err = record_validation(0, stacked)
    best_step = np.zeros(len(members), int)
    log(f"validation X_err before fine-tuning (cm): {np.round(best_err, 4).tolist()}")

    def best_so_far() -> list[dict]:
        """Per seed, the best iterate of the member (learning rate, anchor weight) with the
        lowest held-out score so far; fills the history's summary fields."""
        pick = [
            min(
                (m for m, member in enumerate(members) if member[0] == s), key=lambda m: best_err[m]
            )
            for s in range(len(translators))
        ]
        history["steps_run"] = len(history["train_loss"])
        history["best_step"] = [int(best_step[m]) for m in pick]
        history["best_learning_rate"] = [members[m][1] for m in pick]
        history["best_anchor_weight"] = [members[m][2] for m in pick]
        history["val_x_err_cm_before"] = [float(history["val_x_err_cm"][0][m]) for m in pick]
        history["best_val_x_err_cm"] = [float(best_err[m]) for m in pick]
        history["wall_s"] = time.perf_counter() - t0
        return [jax.tree.map(lambda x, m=m: np.asarray(x[m]), best_params) for m in pick]

    rng = np.random.default_rng(config.seed)
    params = stacked
    bar = tqdm(range(1, config.steps + 1), disable=not progress, desc="finetune", unit="step")
    for i in bar:
        pick = rng.choice(config.n_train, size=config.batch_size, replace=False)
        t_step = time.perf_counter()
        x_batch = jnp.asarray(x_train[pick], jnp.float32)
        params, opt_state, loss = step(
            params,
            opt_state,
            trained,
            anchor_weights,
            s_anchor,
            jnp.asarray(s_train[pick]),
            x_batch,
        )
        loss = np.asarray(loss)
        history["step_wall_s"].append(time.perf_counter() - t_step)
        history["train_loss"].append(loss.tolist())
        if not np.isfinite(loss).all():
            log(f"step {i}: non-finite loss {loss}; stopping, keeping the best iterate")
            break
        out_of_time = config.max_wall_s > 0 and time.perf_counter() - t0 > config.max_wall_s
        if i % config.eval_every == 0 or i == config.steps or out_of_time:
            err = record_validation(i, params)
            better = err < best_err
            best_params = keep_better(best_params, params, better)
            best_err = np.where(better, err, best_err)
            best_step = np.where(better, i, best_step)
            bar.set_postfix(loss=float(loss.mean()), val_cm=float(err.mean()))
            if on_validation is not None:
                on_validation(best_so_far(), history)
        if out_of_time:
            log(f"stopping after step {i}: max_wall_s = {config.max_wall_s} s reached")
            break
    bar.close()
    history["complete"] = True
    return best_so_far(), history


def finetuned_checkpoint(source: tuple[dict, dict], g_c_params, finetune_meta: dict):
    """(tree, meta) of a source translator checkpoint (`checkpoint.load`'s pair) with G_c
    replaced and `finetune_meta` added to its metadata.

    A source that was itself fine-tuned keeps its record: the metadata's "finetune" is this
    stage, "finetune_earlier" lists the earlier stages, oldest first.
    """
    tree, meta = source
    earlier = list(meta.get("finetune_earlier", [])) + (
        [meta["finetune"]] if "finetune" in meta else []
    )
    stages = {"finetune": finetune_meta} | ({"finetune_earlier": earlier} if earlier else {})
    return dict(tree) | {"g_c": g_c_params}, meta | stages


def save_finetuned(path, source_path, g_c_params, finetune_meta: dict) -> Path:
    """Writes `finetuned_checkpoint` of the translator file at `source_path` to `path`."""
    tree, meta = finetuned_checkpoint(checkpoint.load(source_path), g_c_params, finetune_meta)
    return checkpoint.save(path, tree, meta)


def stage_parser(module: str, doc: str) -> argparse.ArgumentParser:
    """A parser with the flags of every fine-tune stage's CLI (this module's and `ccgan.distill`'s):
    --translators, --seeds, --out, --model, --domain; `start_stage` checks and loads them."""
    p = cli_parser(module, doc)
    p.add_argument("--translators", nargs="+", required=True, help="translator checkpoints")
    p.add_argument("--seeds", type=int, nargs="+", help="seed of each file (default 0, 1, ...)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument(
        "--model",
        default=str(constants.SOLID_MODEL_PATH),
        help="MJCF of the arm to simulate: the one the translators were trained on (the"
        " committed translators: the solid-disc arm)",
    )
    p.add_argument(
        "--domain",
        default="constrained",
        choices=sorted(d for d in mjx_arm.DOMAINS if d != "source"),
        help="D_c domain (mjx_arm.DOMAINS)",
    )
    return p


@dataclasses.dataclass
class Stage:
    """What a fine-tune stage's CLI loaded: its translators (each file read once), the arms, the
    output folder and the run record every written file carries."""

    seeds: list[int]
    sources: list[tuple[dict, dict]]
    translators: list[Translator]
    arm_s: object
    arm_c: object
    out: Path
    run: dict

    def write(self, params, per_seed_meta: list[dict], history: dict, json_name: str) -> None:
        """Writes each seed's translator file (G_c replaced, the stage's record added to its
        metadata) and the history, atomically."""
        for s_i, (seed, source) in enumerate(zip(self.seeds, self.sources, strict=True)):
            meta = self.run | {"seed": seed} | per_seed_meta[s_i]
            tree, file_meta = finetuned_checkpoint(source, params[s_i], meta)
            names = [f"translator_seed{seed}.ckpt"] + (["translator.ckpt"] if s_i == 0 else [])
            for name in names:
                checkpoint.save(self.out / name, tree, file_meta)
        tmp = self.out / f"{json_name}.tmp"
        tmp.write_text(json.dumps(self.run | {"history": history}, indent=2))
        tmp.replace(self.out / json_name)


def trained_model_hash(meta: dict) -> str | None:
    """The `Arm.model_hash` a translator file says it was trained or last refined on, or None
    (files written before the hash was recorded)."""
    return meta.get("finetune", {}).get("model_hash") or meta.get("model_hash")


def start_stage(p: argparse.ArgumentParser, a, module: str, config: dict, argv) -> Stage:
    """Checks and loads what `stage_parser`'s flags name; `module` and `config` go into the run
    record. Every problem (seeds, output folder, an unreadable translator or MJCF, translators
    recorded on another arm) is a usage error (status 2) before any simulation starts."""
    import jax

    from mjx_arm.machine import cpu_model, enable_compilation_cache

    seeds = a.seeds if a.seeds is not None else list(range(len(a.translators)))
    if len(seeds) != len(a.translators):
        p.error("give one seed per translator file")
    if len(set(seeds)) != len(seeds):
        p.error(f"--seeds must be distinct, got {seeds}")
    check_output_dir(p, "--out", a.out)
    try:
        sources = [checkpoint.load(path) for path in a.translators]  # read once, rewritten often
        translators = [
            translator_from_checkpoint(src, path)
            for src, path in zip(sources, a.translators, strict=True)
        ]
    except checkpoint.CheckpointError as err:
        p.error(f"--translators: {err}")
    try:
        arm_s, arm_c = (mjx_arm.load(a.model, domain=d) for d in ("source", a.domain))
    except (FileNotFoundError, ValueError) as err:  # ModelValidationError is a ValueError
        p.error(f"--model {a.model}: {err}")
    for path, (_, meta) in zip(a.translators, sources, strict=True):
        trained = trained_model_hash(meta)
        if trained is not None and trained != arm_c.model_hash:
            p.error(
                f"{path} was trained on the arm with model hash {trained}, but --model"
                f" {a.model} has {arm_c.model_hash}"
            )
    enable_compilation_cache()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    dev = jax.devices()[0]
    run = {
        "command": f"python -m {module} " + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": f"{cpu_model()}; JAX device: {dev.platform} ({dev.device_kind})",
        "config": config,
        "model": str(a.model),
        "model_hash": arm_c.model_hash,
        "domain": a.domain,
        "sources": [str(x) for x in a.translators],
        "seeds": seeds,
    }
    return Stage(seeds, sources, translators, arm_s, arm_c, out, run)


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
        stage.write(params, per_seed, history, "finetune.json")

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
