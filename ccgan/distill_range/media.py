"""The training media of a distillation over a range: sampled, each with its step time and k.

Training media are a Latin hypercube in the condition's unit square ((log r, log s) scaled to
[0, 1], `ccgan.media_range.MediaRange.condition`), so that they spread over the range in the
coordinates G_c sees, none closer than `RangeConfig.min_separation` to a held-out medium. Each
medium's 63% step time is measured in MuJoCo C (`mjx_arm.media.step_t63_s`, the arm at its own
timestep, as `studies.k_by_medium` measured the rule) and its k is the rule's
(`ccgan.media_range.k_from_step_time`). The step times also fit the translator's model of t63
(`StepTimeModel`), which gives k for media it was not taught on.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

import mjx_arm
from ccgan.distill_range.config import RangeConfig
from ccgan.media_range import K_GRID, MediaRange, StepTimeModel, k_from_step_time
from mjx_arm import media
from mjx_arm.identify_family import resolved_viscosity_scale

#: Hypercubes drawn before the sample is refused (a held-out set that leaves no room at this
#: separation), and draws of a point in its cell before its hypercube is drawn again.
MAX_DRAWS = 1000
CELL_DRAWS = 20


@dataclasses.dataclass(frozen=True)
class Medium:
    """A training medium: drag ratio r, stiffness scale s, its measured 63% step time (s) and
    the rule's k for it."""

    drag_ratio: float
    stiffness_scale: float
    t63_s: float
    k: int

    @property
    def name(self) -> str:
        """ "r4.37_s0.812" (the Domain's name)."""
        return f"r{self.drag_ratio:.3g}_s{self.stiffness_scale:.3g}"


def unit_position(cfg: RangeConfig, drag_ratio: float, stiffness_scale: float) -> np.ndarray:
    """(r, s) as the condition's [0, 1] coordinates [2] (log-scaled over the range)."""
    return np.array(
        [
            math.log(drag_ratio / cfg.drag_ratio_range[0])
            / math.log(cfg.drag_ratio_range[1] / cfg.drag_ratio_range[0]),
            math.log(stiffness_scale / cfg.stiffness_range[0])
            / math.log(cfg.stiffness_range[1] / cfg.stiffness_range[0]),
        ]
    )


def sample_training_media(cfg: RangeConfig) -> list[tuple[float, float]]:
    """`cfg.n_media` (r, s) pairs: a Latin hypercube in the unit square of `unit_position` (one
    point in each of n rows and each of n columns), each at least `cfg.min_separation` from
    every held-out medium. A point too close is drawn again in its cell; a cell with no room
    (a held-out medium's neighbourhood covers it) redraws the whole hypercube. The same for the
    same settings.

    Raises:
      ValueError: no hypercube in MAX_DRAWS keeps away from the held-out media.
    """
    rng = np.random.default_rng([cfg.media_seed, cfg.n_media])
    held = np.array([unit_position(cfg, r, s) for r, s in cfg.held_out_media]).reshape(-1, 2)
    n = cfg.n_media

    def far(u: np.ndarray) -> bool:
        return not len(held) or np.linalg.norm(held - u, axis=-1).min() >= cfg.min_separation

    for _ in range(MAX_DRAWS):
        cells = np.stack([rng.permutation(n), rng.permutation(n)], -1)
        units = []
        for cell in cells:
            tries = ((cell + rng.random(2)) / n for _ in range(CELL_DRAWS))
            u = next((u for u in tries if far(u)), None)
            if u is None:
                break
            units.append(u)
        else:
            break
    else:
        raise ValueError(
            f"no {n}-point hypercube keeps {cfg.min_separation} from the held-out media in"
            f" {MAX_DRAWS} draws: lower min_separation or move them"
        )
    low_r, high_r = cfg.drag_ratio_range
    low_s, high_s = cfg.stiffness_range
    return [
        (float(low_r * (high_r / low_r) ** u[0]), float(low_s * (high_s / low_s) ** u[1]))
        for u in units
    ]


def medium_arm(arm_c, drag_ratio: float, stiffness_scale: float) -> mjx_arm.Arm:
    """The arm of `arm_c`'s MJCF (a file or text) in medium (r, s), at its own timestep."""
    source = {"path": arm_c.path} if arm_c.path is not None else {"xml": arm_c.mjcf_text}
    domain = media.medium_domain(drag_ratio, stiffness_scale, resolved_viscosity_scale(arm_c))
    return mjx_arm.load(domain=domain, **source)


def measure_media(arm_c, points: list[tuple[float, float]], log=print) -> list[Medium]:
    """Each (r, s) of `points` with its 63% step time, measured in MuJoCo C on the arm of
    `arm_c`'s MJCF in that medium (`medium_arm`), and the rule's k (`k_from_step_time` on
    `K_GRID`).

    Raises:
      ValueError: a medium whose tip does not move (no step time).
    """
    from concurrent.futures import ThreadPoolExecutor

    from mjx_arm.machine import usable_cores

    def one(point: tuple[float, float]) -> float:
        r, s = point
        return media.step_t63_s(medium_arm(arm_c, r, s), media.step_hold_s(r, s))

    out = []
    t0 = time.perf_counter()
    # One trajectory per medium: the media at once, a thread each (MuJoCo C releases the GIL;
    # the same rollouts, so the same step times, as one after another).
    with ThreadPoolExecutor(max(1, min(usable_cores(), len(points)))) as pool:
        times = list(pool.map(one, points))
    for (r, s), t63 in zip(points, times, strict=True):
        if not (math.isfinite(t63) and t63 > 0):
            raise ValueError(f"medium r={r:g}, s={s:g}: the tip did not move in the step test")
        out.append(Medium(r, s, t63, k_from_step_time(t63, K_GRID)))
    log(
        f"media: {len(out)} step times in {time.perf_counter() - t0:.0f} s; k "
        + ", ".join(f"{m.name}: {m.k}" for m in out)
    )
    return out


def media_range_of(
    cfg: RangeConfig, training: list[Medium], constrained_scale: float
) -> MediaRange:
    """The `MediaRange` a translator taught on `training` records: `cfg`'s range and held-out
    media, the training media, and the step-time model fitted on their measured step times."""
    step_time = StepTimeModel.fit(
        [m.drag_ratio for m in training],
        [m.stiffness_scale for m in training],
        [m.t63_s for m in training],
    )
    return MediaRange(
        drag_ratio_range=tuple(cfg.drag_ratio_range),
        stiffness_range=tuple(cfg.stiffness_range),
        constrained_viscosity_scale=float(constrained_scale),
        step_time=step_time,
        k_grid=K_GRID,
        training_media=tuple((m.drag_ratio, m.stiffness_scale) for m in training),
        held_out_media=cfg.held_out_media,
    )
