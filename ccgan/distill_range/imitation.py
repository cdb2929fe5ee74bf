"""The imitation over media: the teacher's programs as a conditioned G_c sees them, and the
held-out score that picks the iterate, each program in its own medium.

The training step is `ccgan.distill.imitation.init_imitation`'s (the loss and Adam do not care
what the samples hold: here each carries its medium's condition at every step). The score is
the per-pair distillation's (the mean of the X_err over the first window_s and over the whole
program, MuJoCo C) in each training medium on its own held-out programs at its own k, averaged
over the media so that each weighs the same. Held-out media play no part.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

import mjx_arm
from ccgan.data import normalise_pressure, samples
from ccgan.distill.imitation import window_and_whole_x_err_cm
from ccgan.distill_range.media import Medium
from ccgan.media_range import MediaRange
from ccgan.stage import generator_commands
from ccgan.translator import Translator, with_condition


class RangeData(NamedTuple):
    """What the distillation over media trains and scores on.

    s_train [N, T, 11]: normalised samples of the training programs, each followed by its
    medium's condition (`ccgan.translator.with_condition`); c_train [N, T, 3]: the teacher's
    commands for them (pressures normalised to [0, 1]); s_val [V, T, 11], x_val [V, T, 6]
    (float64, m and unit d3), p_val [V, T, 3] (bar, D_s commands) and c_val [V, T, 3] (bar, the
    teacher's): the held-out programs of the training media; medium_val [V]: each one's medium;
    window: control steps in window_s.
    """

    s_train: Any
    c_train: Any
    s_val: Any
    x_val: np.ndarray
    p_val: np.ndarray
    c_val: np.ndarray
    medium_val: np.ndarray
    window: int


def range_data(
    teacher: dict, media: list[Medium], media_range: MediaRange, bounds, window_s: float
) -> RangeData:
    """`teacher_over_media`'s arrays as G_c sees them (normalised with the translator's pose
    bounds, each program's condition appended), split into training and held-out programs."""
    import jax.numpy as jnp

    conditions = np.stack([media_range.condition(m.drag_ratio, m.stiffness_scale) for m in media])
    s_all = with_condition(
        samples(teacher["p"], teacher["x"], bounds), conditions[teacher["medium"]]
    )
    val = teacher["is_val"]
    return RangeData(
        s_train=jnp.asarray(s_all[~val]),
        c_train=jnp.asarray(normalise_pressure(teacher["c"][~val]), jnp.float32),
        s_val=jnp.asarray(s_all[val]),
        x_val=np.asarray(teacher["x"][val], np.float64),
        p_val=np.asarray(teacher["p"][val], np.float64),
        c_val=np.asarray(teacher["c"][val], np.float64),
        medium_val=np.asarray(teacher["medium"][val]),
        window=int(round(window_s * mjx_arm.CONTROL_HZ)),
    )


def media_x_err_cm(score_arms: list, media: list[Medium], commands, data: RangeData):
    """(window, whole) X_err (cm) [..., M] of commands [..., V, T, 3] (bar, one per source
    step) for the held-out programs, each medium's in its arm at its k (MuJoCo C).

    A medium's batch is small (its 1-2 held-out programs for each seed: 3-6 trajectories), so
    on a host of more cores than that several media run at once, each in its own thread pool
    (MuJoCo C releases the GIL): the same rollouts, the same numbers, on a 16-core host about a
    third of the wall time of one medium after another. One core or few: one at a time."""
    from concurrent.futures import ThreadPoolExecutor

    from mjx_arm.machine import usable_cores

    commands = np.asarray(commands, np.float64)
    per_seed = int(np.prod(commands.shape[:-3], dtype=int))

    def one(m: int):
        mine = data.medium_val == m
        return window_and_whole_x_err_cm(
            score_arms[m], commands[..., mine, :, :], media[m].k, data.x_val[mine], data.window
        )

    busiest = per_seed * max(int(np.sum(data.medium_val == m)) for m in range(len(media)))
    at_once = max(1, min(len(media), -(-usable_cores() // max(busiest, 1))))
    if at_once == 1:
        scored = [one(m) for m in range(len(media))]
    else:
        with ThreadPoolExecutor(at_once) as pool:
            scored = list(pool.map(one, range(len(media))))
    head, whole = zip(*scored, strict=True)
    return np.stack(head, -1), np.stack(whole, -1)


def make_range_validation(
    translator: Translator, score_arms: list, media: list[Medium], data: RangeData
):
    """`validate(params [S, ...]) -> {"score", "window", "whole"} [S] cm, "by_medium" [S, M]`:
    every seed's commands for the held-out programs in one jitted call, each medium's scored in
    its arm; the score is the media's mean of 0.5 (window + whole)."""
    import jax

    @jax.jit
    def val_commands(params):
        return jax.vmap(lambda g: generator_commands(translator, g, data.s_val))(params)

    def validate(params) -> dict:
        head, whole = media_x_err_cm(score_arms, media, val_commands(params), data)
        by_medium = 0.5 * (head + whole)
        return {
            "score": by_medium.mean(-1),
            "window": head.mean(-1),
            "whole": whole.mean(-1),
            "by_medium": by_medium,
        }

    return validate


def start_history(score_arms: list, media: list[Medium], data: RangeData) -> dict:
    """The history before the first epoch, with the held-out score (cm, the media's mean and
    per medium) of the teacher and of stretch only (the D_s commands held each medium's k)."""
    head, whole = media_x_err_cm(score_arms, media, np.stack([data.c_val, data.p_val]), data)
    by_medium = 0.5 * (head + whole)
    return {
        "train_loss": [],
        "val": {},
        "teacher_val_x_err_cm": {"score": float(by_medium[0].mean())}
        | {"by_medium": by_medium[0].tolist()},
        "stretch_val_x_err_cm": {"score": float(by_medium[1].mean())}
        | {"by_medium": by_medium[1].tolist()},
        "media": [
            {"r": m.drag_ratio, "s": m.stiffness_scale, "t63_s": m.t63_s, "k": m.k} for m in media
        ],
        "complete": False,
    }
