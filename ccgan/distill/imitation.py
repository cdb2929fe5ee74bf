"""The imitation: G_c trained to reproduce the teacher's commands, scored on held-out programs.

`imitation_data` normalises the teacher's programs as the translator sees them;
`init_imitation` gives every seed's jitted Adam step; `make_validation` scores the seeds'
commands in MuJoCo C (the mean of the X_err over the first window_s and the whole program);
`_save_training` and `_load_training` keep a stopped run's state so that it resumes at its next
epoch. `ccgan.distill.distill` composes them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from ccgan.data import PRESSURE_DIM, normalise_pressure, samples
from ccgan.distill.config import DistillConfig
from ccgan.distill.teacher import teacher_data
from ccgan.stage import BestIterates, generator_commands, validated_loop
from ccgan.translator import Translator
from mjx_arm.atomic import write_atomically
from tracking.held import run_dc, stretch
from tracking.metrics import position_error_cm


class ImitationData(NamedTuple):
    """What `distill` trains and scores on: `teacher_data`'s programs as the translator sees them.

    s_train [N, T, 9]: normalised samples (`ccgan.data.samples`) of the training programs;
    c_train [N, T, 3]: the teacher's commands for them (pressures normalised to [0, 1]);
    s_val [V, T, 9] and x_val [V, T, 6] (float64): the held-out programs' samples and the
    targets they are scored against (their D_s poses, or the teacher's corrected targets:
    `teacher_data`'s "t_val"); p_val [V, T, 3]: their D_s commands (bar), which stretch only
    holds k periods; c_val [V, T, 3]: the teacher's held-out commands (bar);
    teacher_val_x_err_cm [V]: the teacher's own held-out X_err (cm); window: control steps in
    window_s.
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
        x_val=np.asarray(data["t_val"], np.float64),
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
    squared difference of G_c's normalised pressures from the teacher's. A conditioned G_c's
    samples carry its condition, [B, T, 9 + C] (`ccgan.distill_range`). The step size's
    schedule spans `config.epochs` passes over data's N training programs.
    """
    import jax
    import jax.numpy as jnp
    import optax

    tr = translators[0]
    step_weight = head_weights(data.s_train.shape[1], data.window, config.head_weight)

    def loss_fn(g_params, s_batch, c_batch):
        out = tr.generator.apply(g_params, s_batch)[..., :PRESSURE_DIM]
        return jnp.mean(step_weight * (out - c_batch) ** 2)

    n_train = data.s_train.shape[0]  # config.n_train_programs here; more over media
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
    if not config.k_candidates:  # the same: k set or the translators' own
        settings.pop("k_candidates")
        settings.pop("k_choice_seconds")
    if not config.correction_translator:  # the same: no correction from the target's rollouts
        for name in ("correction_translator", "correction_domain", "correction_dtype"):
            settings.pop(name)
    if config.train_sets == 1:  # the same: one pair
        settings.pop("train_sets")
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


def train_with_resume(
    config: DistillConfig,
    step,
    stacked,
    opt_state,
    data: ImitationData,
    n_train: int,
    validate,
    new_history,
    start_line,
    *,
    key: str,
    resume: Path | None,
    on_validation,
    t0: float,
    desc: str,
    progress: bool,
    log,
    stop,
) -> tuple[list[dict], dict]:
    """The imitation's epochs, validated and resumable: shared by `ccgan.distill` (one medium)
    and `ccgan.distill_range` (a range of media), which differ only in their data, scores and
    history.

    Args:
      step, stacked, opt_state: `init_imitation`'s.
      data, n_train: the training programs and how many one epoch passes over.
      validate: params -> {"score": [S] cm, ...}, the held-out scores that pick the iterate.
      new_history: () -> the history of a fresh run (its "val" filled in here).
      start_line: history -> the line logged before the first epoch.
      key: the run's settings, for `resume` (`_resume_key`).
      resume, on_validation, stop: as `ccgan.distill.distill` takes them.

    Returns:
      (`_best_of_seeds`, history, with "complete" whether training ran to its end).
    """
    saved = None if resume is None else _load_training(resume, key, stacked, opt_state, log)

    def validate_epoch(epoch: int, params) -> np.ndarray:
        """Scores the parameters, adds the scores to the history; returns the [S] score."""
        scores = validate(params)
        history["val"][epoch] = {name: v.tolist() for name, v in scores.items()}
        return scores["score"]

    if saved is None:
        first = 1
        history = new_history()
        best = BestIterates.start(stacked, validate_epoch(0, stacked))
        rng = np.random.default_rng(config.seed)
    else:
        done, stacked, opt_state, best, history, rng = saved
        first = done + 1
        log(f"resuming from {resume}: {done} of {config.epochs} epochs done")
    log(start_line(history))
    latest: dict = {}  # the last epoch's (epoch, params, opt_state), kept for a stop

    def train_once(epoch: int, params, opt_state):
        """One pass over the teacher programs in a random order."""
        order = rng.permutation(n_train)
        params, opt_state, loss = _epoch(step, params, opt_state, data, order, config.batch_size)
        history["train_loss"].append(loss.tolist())
        latest.update(epoch=epoch, params=params, opt_state=opt_state)
        return params, opt_state, loss

    def report(best: BestIterates) -> None:
        """After every validation: the training state kept (a run killed before its SIGTERM
        handler ends, e.g. at a machine's time limit, loses at most `eval_every` epochs),
        then the caller's callback."""
        if resume is not None and latest and latest["epoch"] < config.epochs:
            _save_training(
                resume, key, latest["epoch"], latest["params"], latest["opt_state"], best,
                history, rng,
            )  # fmt: skip
        if on_validation is not None:
            on_validation(_best_of_seeds(best, history, t0), history)

    best = validated_loop(
        config.epochs, stacked, opt_state, best, train_once, validate_epoch,
        None if on_validation is None and resume is None else report, config=config, t0=t0,
        desc=desc,
        unit="epoch", progress=progress, log=log, stop=stop, start=first,
    )  # fmt: skip
    history["complete"] = stop is None or not stop.is_set()
    if resume is not None and not history["complete"] and latest:
        _save_training(
            resume, key, latest["epoch"], latest["params"], latest["opt_state"], best, history, rng
        )
        log(f"training state after epoch {latest['epoch']} kept in {resume}")
    elif resume is not None and history["complete"]:
        resume.unlink(missing_ok=True)
    return _best_of_seeds(best, history, t0), history
