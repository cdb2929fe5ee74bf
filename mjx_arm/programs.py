"""Pressure programs: the paper's five test shapes and random programs of their signal types.

Pure functions of time (numpy, no simulation): each program is a [T, 3] array of chamber commands
(bar) at 10 Hz (T = 10 * duration_s), inside the valve range [0.2, 3.5] bar. They live in
`mjx_arm` so that every layer above it (`tracking`, `ccgan`'s fine-tunes, `eval`) can draw them;
`eval.shapes` re-exports them beside its command line.

The shapes are made in "bending space": a planar bending vector b(t) (dimensionless, |b| <= 1
keeps every chamber in range) is turned into chamber pressures by

    p_i(t) = P_MID + AMPLITUDE * (2/3) * 3/2 * (b(t) . u_i),  u_i = (cos theta_i, sin theta_i),

with theta_i = 0, 120, 240 deg the chamber angles. Since sum_i u_i u_i^T = 3/2 I, the mean of the
three pressures stays at P_MID (no net stretch) and the bending direction follows b(t); the tip
then traces a (rotated, lagged) copy of b(t)'s path in the XY plane. For the circle this is exactly
the paper's recipe: three sinusoids with phases 0/120/240 deg, period 30 s (two turns in 60 s).

Signal types, as in the paper's "sinusoid, ramp, staircase and phase changes":
  circle         sinusoids, phases 0/120/240 deg, period 30 s
  rectangle      piecewise-linear ramps along a 2:1 rectangle, one lap per 30 s
  damped_circle  sinusoids under an exponential envelope (a spiral inward), period 30 s
  ellipse        sinusoids of unequal amplitude and shifted phases (2:1 ellipse), period 30 s
  kite           staircase: the kite's edges quantised into 1 s steps, one lap per 30 s

`shape_like_program(s)` draws random programs of the same signal types (never a test shape), for
fine-tuning and validating translators; `validation_program` is the smooth program the
evaluation picks its stretch factor on.

The random step programs (random targets held for random times) live here too, one family each:
  babble_program(s)     the babbling datasets (`mjx_arm.babble`): each chamber
                        switches on its own, one NumPy stream per (domain, split, trajectory)
  random_held_programs  all three chambers switch together, drawn one after another from one
                        generator (`ccgan`'s tests and synthetic data, `bench.train`); with
                        `bench_programs` (`bench.throughput`, `studies.timestep`) and
                        `held_program` (the rod comparisons, `mjx_arm.fidelity` and `mjx_arm.fit`)
                        as fixed settings of it
  full_range_program    bang-bang between 0 and 3.5 bar (`mjx_arm.fidelity`'s stability runs)
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from mjx_arm import constants

#: Control rate of the programs (Hz).
CONTROL_HZ = constants.CONTROL_HZ
#: Valve range (bar): every program stays inside [P_LOW, P_HIGH].
P_LOW_BAR = constants.P_MIN_BAR
P_HIGH_BAR = constants.P_MAX_BAR
#: Mean chamber pressure of every program (bar): the middle of the valve range.
P_MID_BAR = 0.5 * (P_LOW_BAR + P_HIGH_BAR)
#: Pressure swing (bar) for |b| = 1; 0.98 of the half range keeps a margin to the valve limits.
AMPLITUDE_BAR = 0.98 * 0.5 * (P_HIGH_BAR - P_LOW_BAR)
#: Period of one lap of every shape (s): the paper's circle period.
PERIOD_S = 30.0
#: Chamber angles around the arm's axis (rad).
CHAMBER_ANGLES_RAD = np.deg2rad([0.0, 120.0, 240.0])


def times_s(duration_s: float) -> np.ndarray:
    """Command times [T] (s), T = round(10 * duration_s), starting at 0."""
    n = int(round(duration_s * CONTROL_HZ))
    if n <= 0:
        raise ValueError(f"duration_s must give at least one command, got {duration_s}")
    return np.arange(n) / CONTROL_HZ


def pressures_from_bend(bend: np.ndarray) -> np.ndarray:
    """Chamber commands [T, 3] (bar) for bending vectors [T, 2] with |b| <= 1.

    For |b| <= 1, |b . u_i| <= 1, so every command lies in P_MID +- AMPLITUDE, inside the range.
    """
    bend = np.asarray(bend, dtype=np.float64)
    u = np.stack([np.cos(CHAMBER_ANGLES_RAD), np.sin(CHAMBER_ANGLES_RAD)], axis=-1)  # [3, 2]
    return P_MID_BAR + AMPLITUDE_BAR * bend @ u.T


def _polygon_path(vertices: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Points [T, 2] at constant speed along a closed polygon [V, 2], phase in laps [T]."""
    closed = np.concatenate([vertices, vertices[:1]], axis=0)
    edges = np.linalg.norm(np.diff(closed, axis=0), axis=-1)
    cum = np.concatenate([[0.0], np.cumsum(edges)]) / edges.sum()
    s = np.mod(phase, 1.0)
    x = np.interp(s, cum, closed[:, 0])
    y = np.interp(s, cum, closed[:, 1])
    return np.stack([x, y], axis=-1)


def circle(duration_s: float = 60.0) -> np.ndarray:
    """Circle: p_i = P_MID + A sin(2 pi t / 30 s - phi_i), phi_i = 0, 120, 240 deg.

    Returns:
      [T, 3] commands (bar), T = 10 * duration_s; exactly periodic with period 30 s.
    """
    t = times_s(duration_s)
    w = 2.0 * math.pi * t / PERIOD_S
    return np.stack(
        [P_MID_BAR + AMPLITUDE_BAR * np.sin(w - phi) for phi in CHAMBER_ANGLES_RAD], axis=-1
    )


def rectangle(duration_s: float = 60.0) -> np.ndarray:
    """Rectangle (2:1): linear ramps of the bending vector between four corners, 30 s per lap.

    Returns:
      [T, 3] commands (bar), periodic with period 30 s.
    """
    t = times_s(duration_s)
    half = np.array([0.85, 0.425])
    corners = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * half
    return pressures_from_bend(_polygon_path(corners, t / PERIOD_S))


def damped_circle(duration_s: float = 60.0, decay_s: float = 45.0) -> np.ndarray:
    """Damped circle: the circle's sinusoids under the envelope exp(-t / decay_s) (inward spiral).

    Returns:
      [T, 3] commands (bar); not periodic (the radius shrinks by exp(-60/45) ~ 0.26 in 60 s).
    """
    t = times_s(duration_s)
    w = 2.0 * math.pi * t / PERIOD_S
    r = np.exp(-t / decay_s)
    bend = np.stack([r * np.cos(w), r * np.sin(w)], axis=-1)
    return pressures_from_bend(bend)


def ellipse(duration_s: float = 60.0) -> np.ndarray:
    """Ellipse (2:1, major axis at 30 deg): sinusoids of unequal amplitude and phase, 30 s period.

    Returns:
      [T, 3] commands (bar), periodic with period 30 s.
    """
    t = times_s(duration_s)
    w = 2.0 * math.pi * t / PERIOD_S
    a, b, tilt = 1.0, 0.5, math.radians(30.0)
    local = np.stack([a * np.cos(w), b * np.sin(w)], axis=-1)
    rot = np.array([[math.cos(tilt), -math.sin(tilt)], [math.sin(tilt), math.cos(tilt)]])
    return pressures_from_bend(local @ rot.T)


def kite(duration_s: float = 60.0, step_s: float = 1.0) -> np.ndarray:
    """Kite: a staircase (the path sampled and held every `step_s`) along a kite, 30 s per lap.

    Returns:
      [T, 3] commands (bar), periodic with period 30 s (30 stairs per lap).
    """
    t = times_s(duration_s)
    held = np.floor(t / step_s) * step_s
    vertices = np.array([[0.0, 0.95], [0.55, 0.3], [0.0, -0.95], [-0.55, 0.3]])
    return pressures_from_bend(_polygon_path(vertices, held / PERIOD_S))


def validation_program(duration_s: float = 20.0, seed: int = 1234) -> np.ndarray:
    """A smooth pseudo-random program [T, 3] (bar) for choosing the stretch factor k.

    Not one of the test shapes: a sum of three random sinusoids per bending axis with periods
    4-20 s, scaled so |b| <= 1. Used only to select k, never to report errors.
    """
    rng = np.random.default_rng(seed)
    t = times_s(duration_s)
    bend = np.zeros((t.size, 2))
    for axis in range(2):
        for _ in range(3):
            period = rng.uniform(4.0, 20.0)
            bend[:, axis] += rng.uniform(0.3, 1.0) * np.sin(
                2 * math.pi * t / period + rng.uniform(0, 2 * math.pi)
            )
    bend /= max(1.0, np.linalg.norm(bend, axis=-1).max())
    return pressures_from_bend(bend)


#: Kinds of `shape_like_program`.
SHAPE_LIKE_KINDS = ("ellipse", "polygon", "staircase", "phase_jumps")


def shape_like_program(
    rng: np.random.Generator, duration_s: float, full_scale: bool = False
) -> np.ndarray:
    """One random program [T, 3] (bar, float32) of the shapes' signal types, never a test shape.

    The bending vector follows a random closed path at a random lap period, from a random phase:
      ellipse      sinusoids: an ellipse of random axes and tilt, half of them under a decaying
                   envelope exp(-t / tau), tau in [20, 120] s (spirals)
      polygon      ramps at constant speed along a random polygon of 3-6 vertices
      staircase    the polygon path sampled and held every 0.5-3 s
      phase_jumps  a circle of random radius whose phase jumps 1-3 times by up to +-180 deg
    Lap periods are uniform in [10, 60] s, direction either way. Half of the programs add a
    common-mode offset m in [-0.3, 0.3] (all three chambers up or down); the path is scaled so
    |m| + |b| <= 1, which keeps every command in P_MID +- AMPLITUDE, inside the valve range.

    With `full_scale` the path is scaled up to that limit (its largest bend reaches
    1 - |m|), as the test shapes' programs are; the random draws are the same.

    Used to fine-tune and validate translators on programs like the test shapes (slow, smooth
    or stepped, starting away from rest) without ever using the five shapes themselves.
    """
    t = times_s(duration_s)
    kind = SHAPE_LIKE_KINDS[rng.integers(len(SHAPE_LIKE_KINDS))]
    period_s = rng.uniform(10.0, 60.0)
    laps = rng.choice([-1.0, 1.0]) * t / period_s + rng.uniform(0.0, 1.0)
    if kind == "ellipse":
        a = rng.uniform(0.3, 1.0)
        b = a * rng.uniform(0.0, 1.0)
        tilt = rng.uniform(0.0, math.pi)
        w = 2.0 * math.pi * laps
        local = np.stack([a * np.cos(w), b * np.sin(w)], axis=-1)
        rot = np.array([[math.cos(tilt), -math.sin(tilt)], [math.sin(tilt), math.cos(tilt)]])
        bend = local @ rot.T
        if rng.uniform() < 0.5:
            bend *= np.exp(-t / rng.uniform(20.0, 120.0))[:, None]
    elif kind in ("polygon", "staircase"):
        n = int(rng.integers(3, 7))
        gaps = rng.uniform(0.5, 1.5, size=n)
        angles = rng.uniform(0.0, 2.0 * math.pi) + 2.0 * math.pi * np.cumsum(gaps) / gaps.sum()
        radii = rng.uniform(0.4, 1.0, size=n)
        vertices = radii[:, None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)
        if kind == "staircase":
            step_s = rng.uniform(0.5, 3.0)
            held = np.floor(t / step_s) * step_s
            laps = np.interp(held, t, laps)
        bend = _polygon_path(vertices, laps)
    else:
        jumps = np.sort(rng.uniform(0.0, t[-1] + 1e-9, size=int(rng.integers(1, 4))))
        shift = rng.uniform(-0.5, 0.5, size=jumps.size)
        phase = laps + np.where(jumps[None, :] <= t[:, None], shift[None, :], 0.0).sum(axis=1)
        w = 2.0 * math.pi * phase
        bend = rng.uniform(0.3, 1.0) * np.stack([np.cos(w), np.sin(w)], axis=-1)
    offset = rng.uniform(-0.3, 0.3) if rng.uniform() < 0.5 else 0.0
    peak = np.linalg.norm(bend, axis=-1).max()
    bend *= (1.0 - abs(offset)) / (max(peak, 1e-9) if full_scale else max(1.0, peak))
    return (pressures_from_bend(bend) + AMPLITUDE_BAR * offset).astype(np.float32)


def shape_like_programs(
    n: int, duration_s: float, seed: int = 0, split: str = "train", full_scale: bool = False
) -> np.ndarray:
    """[n, T, 3] `shape_like_program`s (bar, float32); program i of a split draws from
    ``np.random.default_rng([seed, stream_id("shape_like", split), i])``, whatever n is."""
    stream = stream_id("shape_like", split)
    return np.stack(
        [
            shape_like_program(np.random.default_rng([seed, stream, i]), duration_s, full_scale)
            for i in range(n)
        ]
    )


def shape_like_kinds(n: int, seed: int = 0, split: str = "train") -> list[str]:
    """The kind (`SHAPE_LIKE_KINDS`) of each of the first n programs of `shape_like_programs(n,
    ..., seed, split)`, whatever their duration or scale: the first draw of each program's
    stream. What a study reports error per program family by."""
    stream = stream_id("shape_like", split)
    return [
        SHAPE_LIKE_KINDS[np.random.default_rng([seed, stream, i]).integers(len(SHAPE_LIKE_KINDS))]
        for i in range(n)
    ]


#: Shape name -> program function(duration_s=60.0) -> [T, 3] commands (bar).
SHAPES: dict[str, Callable[..., np.ndarray]] = {
    "circle": circle,
    "rectangle": rectangle,
    "damped_circle": damped_circle,
    "ellipse": ellipse,
    "kite": kite,
}
#: Shapes whose programs repeat every PERIOD_S.
PERIODIC_SHAPES = ("circle", "rectangle", "ellipse", "kite")


# ---------------------------------------------------------------------------- random step programs


def stream_id(family: str, split: str) -> int:
    """A stable 31-bit id of a random stream: crc32 of ``"<family>/<split>"``.

    Seeding each program with ``[seed, stream_id(...), i]`` makes program i of a stream the same
    whatever else is drawn beside it (batch, chunk, device count).
    """
    return zlib.crc32(f"{family}/{split}".encode()) & 0x7FFFFFFF


class BabbleSpec(Protocol):
    """What a babbling program needs of its run's settings; `mjx_arm.babble.BabbleConfig` has it
    (a protocol: `mjx_arm.babble` imports this module, so this one cannot import it back)."""

    @property
    def seed(self) -> int: ...  # root seed of every program

    @property
    def n_steps(self) -> int: ...  # control periods per program (T)

    @property
    def hold_min_steps(self) -> int: ...  # shortest hold (control periods)

    @property
    def hold_max_steps(self) -> int: ...  # longest hold (control periods)

    @property
    def p_low_bar(self) -> float: ...  # lowest target (bar)

    @property
    def p_high_bar(self) -> float: ...  # highest target (bar)


def babble_program(rng: np.random.Generator, spec: BabbleSpec) -> np.ndarray:
    """One babbling program [T, 3] (bar, float32), T = spec.n_steps.

    Each chamber on its own jumps to a uniform target in [p_low_bar, p_high_bar] and holds it for
    a uniform whole number of periods in [hold_min_steps, hold_max_steps]; the chambers switch at
    different times, so the programs visit the whole pressure cube.
    """
    n_steps, lo, hi = spec.n_steps, spec.hold_min_steps, spec.hold_max_steps
    n_holds = n_steps // lo + 1  # enough holds to cover T even if every one is the shortest
    holds = rng.integers(lo, hi + 1, size=(3, n_holds))
    targets = rng.uniform(spec.p_low_bar, spec.p_high_bar, size=(3, n_holds))
    steps = np.arange(n_steps)
    which = np.stack([np.searchsorted(end, steps, side="right") for end in holds.cumsum(1)])
    return np.take_along_axis(targets, which, axis=1).T.astype(np.float32)


def babble_programs(
    spec: BabbleSpec, indices: Sequence[int], *, domain: str = "source", split: str = "train"
) -> np.ndarray:
    """Babbling programs of the given trajectory indices.

    Trajectory i draws from ``np.random.default_rng([seed, stream_id(domain, split), i])``, so it
    is the same whatever else is generated with it.

    Args:
      spec: babbling options (seed, duration, pressure range, hold durations), e.g. a
        `mjx_arm.babble.BabbleConfig`.
      indices: [B] int trajectory indices (>= 0) within the (domain, split) stream.
      domain, split: name the random stream.

    Returns:
      [B, T, 3] float32 chamber commands (bar), T = spec.n_steps.
    """
    stream = stream_id(domain, split)
    out = np.empty((len(indices), spec.n_steps, 3), np.float32)
    for row, i in enumerate(indices):
        out[row] = babble_program(np.random.default_rng([spec.seed, stream, int(i)]), spec)
    return out


def random_held_programs(
    rng: np.random.Generator,
    n: int,
    steps: int,
    max_hold: int = 5,
    p_max_bar: float = P_HIGH_BAR,
    *,
    min_hold: int = 1,
    p_min_bar: float = 0.0,
) -> np.ndarray:
    """Random programs whose three chambers switch together: uniform targets held for random times.

    Programs are drawn one after another from `rng`, so program i depends on the ones before it
    but not on `n`: the first programs of two calls with the same seed are the same.

    Args:
      rng: numpy generator.
      n: programs.
      steps: T, control steps per program (10 Hz).
      max_hold: longest hold (control steps).
      p_max_bar: top target (bar).
      min_hold: shortest hold (control steps).
      p_min_bar: bottom target (bar); targets under the 0.2 bar valve floor act as the floor.

    Returns:
      [n, steps, 3] float64 commands (bar).
    """
    out = np.zeros((n, steps, 3))
    for i in range(n):
        t = 0
        while t < steps:
            hold = int(rng.integers(min_hold, max_hold + 1))
            out[i, t : t + hold] = rng.uniform(p_min_bar, p_max_bar, 3)
            t += hold
    return out


def bench_programs(batch: int, periods: int, seed: int = 0) -> np.ndarray:
    """The timing runs' programs [batch, periods, 3] (bar, float64): targets in [0, 3.5] bar held
    0.5-2 s (`random_held_programs`, 5-20 periods).

    Row b does not depend on `batch`, so the first rows of any two batches are the same programs.
    """
    rng = np.random.default_rng(seed)
    return random_held_programs(rng, batch, periods, max_hold=20, p_max_bar=P_HIGH_BAR, min_hold=5)


def held_program(seed: int, seconds: float, hold_periods: tuple[int, int]) -> np.ndarray:
    """One program [T, 3] (bar, float64) of its own seed, T = 10 * seconds: uniform targets in the
    valve range [0.2, 3.5] bar, all three chambers held together for a random number of control
    periods in `hold_periods` (inclusive), then redrawn.

    The programs the chain is compared with the reference rod on (`mjx_arm.fidelity`) and fitted
    to it on (`mjx_arm.fit`), each from its own seed.
    """
    n_periods = int(round(seconds * CONTROL_HZ))
    rng = np.random.default_rng(seed)
    low, high = hold_periods
    return random_held_programs(
        rng, 1, n_periods, max_hold=high, p_max_bar=P_HIGH_BAR, min_hold=low, p_min_bar=P_LOW_BAR
    )[0]


def full_range_program(seed: int, seconds: float, hold_periods: tuple[int, int]) -> np.ndarray:
    """Commands [T, 3] (bar, float64), T = 10 * seconds, that jump each chamber between the valve's
    ends (0 and 3.5 bar) every `hold_periods` control periods (inclusive), all three together:
    the hardest program for an explicit integrator (`mjx_arm.fidelity`'s stability runs)."""
    rng = np.random.default_rng(seed)
    n_periods = int(round(seconds * CONTROL_HZ))
    program = np.empty((n_periods, 3))
    t = 0
    while t < n_periods:
        hold = int(rng.integers(hold_periods[0], hold_periods[1] + 1))
        program[t : t + hold] = rng.choice([0.0, P_HIGH_BAR], 3)
        t += hold
    return program
