"""Proportional pressure valves: saturation and first-order lag toward the command.

A command is held for one control period. Within it the chamber pressure moves toward the command
exponentially, with the rise time constant when the command is above the pressure and the drop
time constant when it is below; the sign cannot change inside one period, so the exact solution
is used at every physics substep.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import jax.numpy as jnp

from mjx_arm import constants


class ValveParams(NamedTuple):
    """Valve constants (all from the paper and its code)."""

    tau_rise_s: float = constants.VALVE_TAU_RISE_S
    tau_drop_s: float = constants.VALVE_TAU_DROP_S
    p_min_bar: float = constants.P_MIN_BAR
    p_max_bar: float = constants.P_MAX_BAR


def check(
    params: ValveParams,
    ctrl_range: tuple[float, float] | None = None,
    names: Mapping[str, str] | None = None,
) -> ValveParams:
    """Returns `params` if a valve can have them; raises otherwise, before any simulation.

    Args:
      params: the valve constants.
      ctrl_range: (low, high) ctrlrange (bar) of the chamber actuators when MuJoCo clamps their
        controls, else None. A p_max above `high` would be reported as the valve's maximum but
        clipped to `high` by MuJoCo; a p_min below `low` likewise.
      names: what to call each field in messages (e.g. the MJCF numeric that set it).

    Raises:
      ValueError: listing every problem: a non-finite constant, a time constant <= 0 (it divides
        the elapsed time in `substep_pressures`), p_min < 0 (gauge pressure cannot be negative),
        p_min >= p_max, or limits outside `ctrl_range`.
    """
    names = names or {}
    label = {
        field: f"{names.get(field, field)} = {value:g}" for field, value in params._asdict().items()
    }
    problems = [
        f"{label[k]} is not finite" for k, v in params._asdict().items() if not math.isfinite(v)
    ]
    problems += [
        f"{label[k]} s must be > 0"
        for k in ("tau_rise_s", "tau_drop_s")
        if not getattr(params, k) > 0
    ]
    if params.p_min_bar < 0:
        problems.append(f"{label['p_min_bar']} bar must be >= 0")
    if not params.p_min_bar < params.p_max_bar:
        problems.append(f"{label['p_min_bar']} bar must be below {label['p_max_bar']} bar")
    if ctrl_range is not None:
        low, high = ctrl_range
        if params.p_max_bar > high:
            problems.append(
                f"{label['p_max_bar']} bar is above the chamber actuators' ctrlrange, which MuJoCo"
                f" would clip it to {high:g} bar"
            )
        if params.p_min_bar < low:
            problems.append(
                f"{label['p_min_bar']} bar is below the chamber actuators' ctrlrange, which MuJoCo"
                f" would clip it to {low:g} bar"
            )
    if problems:
        raise ValueError("; ".join(problems))
    return params


def saturate(command_bar: jnp.ndarray, valve: ValveParams = ValveParams(), xp=jnp) -> jnp.ndarray:
    """Clips commands to what the valve can deliver.

    Commands outside [0, p_max] saturate at the range's ends, and a chamber never vents below
    p_min, so commands under p_min act as p_min.
    """
    return xp.clip(command_bar, valve.p_min_bar, valve.p_max_bar)


def substep_pressures(
    pressure_bar: jnp.ndarray,
    command_bar: jnp.ndarray,
    n_substeps: int,
    timestep_s: float,
    valve: ValveParams = ValveParams(),
    xp=jnp,
) -> jnp.ndarray:
    """Chamber pressures over one control period.

    Args:
      pressure_bar: [..., 3] chamber pressures at the start of the period (bar).
      command_bar: [..., 3] saturated commands held over the period (bar).
      n_substeps: physics steps per control period.
      timestep_s: physics timestep (s).
      xp: the array module, `jax.numpy` (default, traceable) or `numpy` (for MuJoCo C inputs).

    Returns:
      [n_substeps, ..., 3] pressure applied during each substep (bar); the last entry is the
      pressure at the end of the period.
    """
    tau = xp.where(command_bar >= pressure_bar, valve.tau_rise_s, valve.tau_drop_s)
    elapsed = timestep_s * xp.arange(1, n_substeps + 1, dtype=pressure_bar.dtype)
    elapsed = elapsed.reshape((n_substeps,) + (1,) * pressure_bar.ndim)
    decay = xp.exp(-elapsed / tau)
    return command_bar + (pressure_bar - command_bar) * decay
