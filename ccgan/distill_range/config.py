"""The media of a distillation over a range (`RangeConfig`), checked when made."""

from __future__ import annotations

import dataclasses
import math

from ccgan.media_range import DRAG_RATIO_RANGE, STIFFNESS_RANGE
from tracking.config import ConfigError

__all__ = ["ConfigError", "RangeConfig"]

#: Media kept out of teaching and of the choice of iterate, (r, s) flat: the range's four
#: corners, the paper's D_c (10, 1) and aged arm (10, 0.7), where per-pair translators exist to
#: compare with, and two inside (4, 0.8) and (20, 0.65).
HELD_OUT = (2.0, 0.6, 2.0, 1.0, 30.0, 0.6, 30.0, 1.0, 10.0, 1.0, 10.0, 0.7, 4.0, 0.8, 20.0, 0.65)


@dataclasses.dataclass(frozen=True)
class RangeConfig:
    """The media a conditioned translator is taught over."""

    drag_ratio_range: tuple[float, float] = DRAG_RATIO_RANGE
    """Drag ratios r covered (source medium = 1, the paper's D_c = 10)."""
    stiffness_range: tuple[float, float] = STIFFNESS_RANGE
    """Stiffness scales s covered (D_c = 1, the aged arm = 0.7)."""
    n_media: int = 24
    """Training media, sampled in the range (a Latin hypercube in (log r, log s))."""
    media_seed: int = 0
    """Seed of the training media's sample."""
    held_out: tuple[float, ...] = HELD_OUT
    """Held-out media as r s pairs, flat (r1 s1 r2 s2 ...): never taught, never pick an
    iterate; scored by `eval.media_range`."""
    min_separation: float = 0.08
    """Least distance of a training medium from any held-out one, in the condition's [0, 1]
    units (`ccgan.media_range.MediaRange.condition`): a training medium that close would make
    the held-out one seen."""

    def __post_init__(self):
        for name in ("drag_ratio_range", "stiffness_range"):
            low, high = getattr(self, name)
            if not (0 < low < high and math.isfinite(high)):
                raise ConfigError(name, f"must be two numbers 0 < low < high, got {(low, high)}")
        if self.n_media < 3:
            raise ConfigError("n_media", f"must be >= 3 (k's step-time fit), got {self.n_media}")
        if len(self.held_out) % 2:
            raise ConfigError("held_out", f"must be r s pairs, got {len(self.held_out)} numbers")
        for r, s in self.held_out_media:
            inside_r = self.drag_ratio_range[0] <= r <= self.drag_ratio_range[1]
            inside_s = self.stiffness_range[0] <= s <= self.stiffness_range[1]
            if not (inside_r and inside_s):
                raise ConfigError("held_out", f"medium ({r:g}, {s:g}) is outside the range")
        if not 0 <= self.min_separation < 0.5:
            raise ConfigError("min_separation", f"must be in [0, 0.5), got {self.min_separation}")

    @property
    def held_out_media(self) -> tuple[tuple[float, float], ...]:
        """The held-out (r, s) pairs."""
        flat = [float(v) for v in self.held_out]
        return tuple(zip(flat[::2], flat[1::2], strict=True))
