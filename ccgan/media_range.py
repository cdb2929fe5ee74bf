"""The range of media a conditioned translator covers, its condition features and its k rule.

Issue 51: one translator for every medium of drag ratio r in [2, 30] (the medium's drag over
the source medium's; the paper's D_c is 10) and stiffness scale s in [0.6, 1] (the aged arm is
0.7), in the terms of `mjx_arm.media`. `MediaRange` is what a conditioned translator file
records of it:

- the range, and the chain's D_c viscosity scale, so that a target given as an `mjx_arm.Domain`
  can be read as (r, s) (`MediaRange.drag_and_stiffness`);
- the condition G_c is given (`MediaRange.condition`): (log r, log s), each mapped linearly from
  its range to [0, 1]. The DomainFamily's theta (log viscosity scale, log s) is the same up to
  an affine map (log viscosity scale = log r + a constant of the chain's fit), so the two hold
  the same information; (r, s) in the issue's terms keeps the file readable without the chain's
  fitted constant, logs because the medium's time scales go as r and about 1 / s (its 63% step
  time is 3.26 r s^-0.94 s on the chain), and [0, 1] as G_c's other inputs are;
- the hold factor k: chosen per medium by a rule, not learnt. `studies.k_by_medium` found
  stretch only's best k on held-out media at k = `K_PER_T63_S` x the medium's 63% step time
  (t63, s), rounded to the nearest of its grid (`K_GRID`): X_err regret 0 on 14 media held out
  in turn, and the rule gives the reference rod's own k where a model of it does not. A rule
  needs no GPU training and can be checked on any medium; a learnt k could not be checked
  without scoring every k. The t63 of a target comes from one step test on it where the caller
  has one (`t63_s=`), else from a log-linear model of t63 in (r, s) fitted on the training
  media's measured step times (`StepTimeModel`: within 1% of all 14 study media).
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np

from mjx_arm import domains, media

#: k per second of the medium's 63% step time (chamber 0 to 2 bar): fitted over 14 chain media
#: and scored leaving each out (studies/results/cpu/k_by_medium/k_by_medium.md); from the
#: reference rod's step times it gives the rod's best k in D_c and aged, where an arm identified
#: from the rod's babbling does not (studies/results/cpu/k_by_medium/rod.md).
K_PER_T63_S = 0.526
#: The hold factors the rule rounds to: the candidates `studies.k_by_medium` scored it on (5
#: apart to 30, then 10 and 20 apart), so its k is one whose X_err was measured.
K_GRID = (1, 5, 10, 15, 20, 25, 30, 40, 50, 60, 70, 80, 100, 120)
#: The issue's range: drag ratio r (source = 1, paper's D_c = 10) and stiffness scale s.
DRAG_RATIO_RANGE = (2.0, 30.0)
STIFFNESS_RANGE = (0.6, 1.0)
#: The target domain label (`ccgan.translator.LABELS`) of a translator over a range of media.
MEDIA_RANGE = "media_range"
#: Condition features: (log r, log s), each scaled to [0, 1] over the range.
N_CONDITION = 2
#: Relative slack at a range's ends (r = 30.000000001 is 30).
EDGE_TOLERANCE = 1e-9


def k_from_step_time(t63_s: float, candidates=K_GRID) -> int:
    """The candidate nearest (in log) to `K_PER_T63_S` x the 63% step time `t63_s` (s)."""
    k = K_PER_T63_S * t63_s
    return min(candidates, key=lambda c: abs(math.log(c) - math.log(k)))


@dataclasses.dataclass(frozen=True)
class StepTimeModel:
    """log t63 = a + b log r + c log s: a medium's 63% step time (s) from its drag ratio and
    stiffness scale, fitted (`fit`) on media whose step time was measured in the simulator."""

    coef: tuple[float, float, float]
    """(a, b, c)."""
    worst_log_residual: float
    """Largest |log(fitted / measured)| over the media it was fitted on."""

    @classmethod
    def fit(cls, drag_ratios, stiffness_scales, t63_s) -> StepTimeModel:
        """Least squares in log over N >= 3 media ([N] each; t63 in s).

        Raises:
          ValueError: fewer than 3 media, or a t63 that is not finite and > 0 (a medium whose
            tip did not move).
        """
        r, s, t = (np.asarray(v, np.float64) for v in (drag_ratios, stiffness_scales, t63_s))
        if len(t) < 3 or not (np.isfinite(t).all() and (t > 0).all()):
            raise ValueError(f"need >= 3 media with finite step times > 0, got {t.tolist()}")
        features = np.stack([np.ones_like(r), np.log(r), np.log(s)], -1)
        coef = np.linalg.lstsq(features, np.log(t), rcond=None)[0]
        worst = float(np.abs(features @ coef - np.log(t)).max())
        return cls(tuple(float(c) for c in coef), worst)

    def t63_s(self, drag_ratio: float, stiffness_scale: float) -> float:
        """The fitted 63% step time (s) of medium (r, s)."""
        a, b, c = self.coef
        return math.exp(a + b * math.log(drag_ratio) + c * math.log(stiffness_scale))


@dataclasses.dataclass(frozen=True)
class MediaRange:
    """The media a conditioned translator covers, and how it reads a target (module doc)."""

    drag_ratio_range: tuple[float, float]
    """(lowest, highest) drag ratio r."""
    stiffness_range: tuple[float, float]
    """(lowest, highest) stiffness scale s."""
    constrained_viscosity_scale: float
    """The chain's D_c viscosity scale (r = 10), to read a Domain's r (`mjx_arm.media`)."""
    step_time: StepTimeModel
    """The 63% step time of (r, s), fitted on the training media."""
    k_grid: tuple[int, ...] = K_GRID
    """The hold factors the rule rounds to."""
    training_media: tuple[tuple[float, float], ...] = ()
    """The (r, s) of the media it was taught on (a record: scoring says which media it saw)."""
    held_out_media: tuple[tuple[float, float], ...] = ()
    """The (r, s) of the media kept out of its teaching and of its choice of iterate."""

    def check(self, drag_ratio: float, stiffness_scale: float) -> tuple[float, float]:
        """(r, s) as floats when inside the range.

        Raises:
          TypeError: r or s not a real number (a bool included).
          ValueError: r or s not finite or outside the range; the message names the range.
        """
        out = []
        for name, value, (low, high) in (
            ("drag ratio", drag_ratio, self.drag_ratio_range),
            ("stiffness scale", stiffness_scale, self.stiffness_range),
        ):
            if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
                raise TypeError(f"the target's {name} must be a real number, got {value!r}")
            value = float(value)
            slack = EDGE_TOLERANCE * high
            if not (math.isfinite(value) and low - slack <= value <= high + slack):
                raise ValueError(
                    f"the target's {name} {value:g} is outside the range this translator was"
                    f" trained on, [{low:g}, {high:g}] (drag ratio {self.drag_ratio_range},"
                    f" stiffness scale {self.stiffness_range})"
                )
            out.append(min(max(value, low), high))
        return out[0], out[1]

    def drag_and_stiffness(self, target) -> tuple[float, float]:
        """The (r, s) of a target, checked to be inside the range (`check`).

        Args:
          target: an `mjx_arm.Domain` of the chain (its viscosity_scale read as r through
            `constrained_viscosity_scale`, None being D_c's r = 10; its stiffness_scale as s),
            or a pair (r, s).

        Raises:
          TypeError: neither a Domain nor a pair of numbers.
          ValueError: a Domain this range cannot read (an absolute viscosity, another mass), or
            (r, s) outside the range.
        """
        if isinstance(target, domains.Domain):
            if target.viscosity is not None or target.mass_scale != 1.0:
                raise ValueError(
                    f"target {target} sets viscosity or mass_scale: a translator over media"
                    " reads a Domain's viscosity_scale (drag) and stiffness_scale only"
                )
            scale = target.viscosity_scale or self.constrained_viscosity_scale
            r = media.drag_ratio_of(scale, self.constrained_viscosity_scale)
            return self.check(r, target.stiffness_scale)
        if isinstance(target, str | bytes) or not hasattr(target, "__len__") or len(target) != 2:
            raise TypeError(
                "target must be an mjx_arm.Domain or a pair (drag ratio r, stiffness scale s),"
                f" got {target!r}"
            )
        return self.check(*target)

    def condition(self, drag_ratio: float, stiffness_scale: float) -> np.ndarray:
        """G_c's condition features [2] (float32) of (r, s) inside the range: (log r, log s),
        each mapped linearly from its range to [0, 1]."""
        features = []
        for value, (low, high) in (
            (drag_ratio, self.drag_ratio_range),
            (stiffness_scale, self.stiffness_range),
        ):
            features.append(math.log(value / low) / math.log(high / low))
        return np.asarray(features, np.float32)

    def hold_factor(
        self, drag_ratio: float, stiffness_scale: float, t63_s: float | None = None
    ) -> int:
        """k of medium (r, s) by the rule (`k_from_step_time` on `k_grid`), from its measured
        63% step time `t63_s` (s) when given, else from the fitted `step_time`."""
        if t63_s is None:
            t63_s = self.step_time.t63_s(drag_ratio, stiffness_scale)
        elif not (isinstance(t63_s, numbers.Real) and math.isfinite(t63_s) and t63_s > 0):
            raise ValueError(f"t63_s must be a step time in s (finite, > 0), got {t63_s!r}")
        return k_from_step_time(float(t63_s), self.k_grid)

    def to_dict(self) -> dict:
        """JSON values (a translator file's "media_range" metadata)."""
        return json_ready(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, d: dict) -> MediaRange:
        """The range `to_dict` wrote.

        Raises:
          KeyError, TypeError, ValueError: a field missing or malformed.
        """
        pairs = lambda key: tuple(tuple(float(v) for v in m) for m in d.get(key, ()))  # noqa: E731
        model = d["step_time"]
        return cls(
            drag_ratio_range=tuple(float(v) for v in d["drag_ratio_range"]),
            stiffness_range=tuple(float(v) for v in d["stiffness_range"]),
            constrained_viscosity_scale=float(d["constrained_viscosity_scale"]),
            step_time=StepTimeModel(
                tuple(float(c) for c in model["coef"]), float(model["worst_log_residual"])
            ),
            k_grid=tuple(int(k) for k in d["k_grid"]),
            training_media=pairs("training_media"),
            held_out_media=pairs("held_out_media"),
        )


def json_ready(value):
    """Tuples as lists, recursively (what JSON gives back)."""
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_ready(v) for v in value]
    return value
