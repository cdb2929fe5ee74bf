"""Proportional pressure valves: saturation and first-order lag toward the command.

A command is held for one control period. Within it the chamber pressure moves toward the command
exponentially, with the rise time constant when the command is above the pressure and the drop
time constant when it is below; the sign cannot change inside one period, so the exact solution
is used at every physics substep.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from mjx_arm import constants


class ValveParams(NamedTuple):
    """Valve constants (all from the paper and its code)."""

    tau_rise_s: float = constants.VALVE_TAU_RISE_S
    tau_drop_s: float = constants.VALVE_TAU_DROP_S
    p_min_bar: float = constants.P_MIN_BAR
    p_max_bar: float = constants.P_MAX_BAR


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
