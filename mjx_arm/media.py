"""Media in the issue's terms: drag ratio r and stiffness scale s, and the 63% step time.

Issue 51 names a medium by its drag ratio r (the medium's drag over the source medium's; the
paper's D_c is r = 10) and the body's stiffness scale s. The chain's D_c
(`Domain(viscosity_scale=None)`) resolves to the viscosity scale fitted to the reference rod at
the paper's 10x (20.117 for models/softarm.xml), so r maps to the chain's viscosity scale as
r x that scale / 10 (`viscosity_scale_of`). The map is exact at r = 10 only, where it was
fitted; elsewhere it is a linear note, not a fit to the rod (r = 1 gives 2.01, not the source's
1.0).

The 63% step time (`step_t63_s`) says how slow a medium is: the time the tip's deflection takes
to reach 63% of its final value after chamber 0 is commanded from the floor to 2 bar. The hold
factor k of a translator follows it (`ccgan.media.K_PER_T63_S`, measured by
`studies.k_by_medium`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_arm import constants, domains
from mjx_arm.arm import time_constant_63

#: The paper's D_c drag ratio, at which the chain's constrained viscosity scale was fitted.
PAPER_DRAG_RATIO = 10.0
#: The step's command on chamber 0 (bar); the other chambers stay at the valve's floor.
STEP_PRESSURE_BAR = 2.0
#: The step response is held this long per unit of r / s (s): 200 s at D_c, over 5 of its 63%
#: times (33 s), so the deflection at the end is its final value.
STEP_HOLD_S_PER_RATIO = 20.0


def viscosity_scale_of(drag_ratio: float, constrained_scale: float) -> float:
    """The chain's viscosity scale for drag ratio r: r x D_c's scale / `PAPER_DRAG_RATIO`.

    Args:
      drag_ratio: r, the medium's drag over the source medium's (D_c: 10).
      constrained_scale: the chain's D_c viscosity scale
        (`mjx_arm.identify_family.resolved_viscosity_scale` of its constrained arm).
    """
    return drag_ratio * constrained_scale / PAPER_DRAG_RATIO


def drag_ratio_of(viscosity_scale: float, constrained_scale: float) -> float:
    """The drag ratio r of a chain viscosity scale (the inverse of `viscosity_scale_of`)."""
    return viscosity_scale * PAPER_DRAG_RATIO / constrained_scale


def medium_domain(
    drag_ratio: float, stiffness_scale: float, constrained_scale: float, name: str | None = None
) -> domains.Domain:
    """The `Domain` of medium (r, s): D_c's with its viscosity scale for r and stiffness s.

    Args:
      drag_ratio: r (D_c: 10).
      stiffness_scale: s (D_c: 1, the aged arm: 0.7).
      constrained_scale: as `viscosity_scale_of`.
      name: the Domain's name (default "r<r>_s<s>", e.g. "r10_s0.7").
    """
    return dataclasses.replace(
        domains.CONSTRAINED,
        name=name or f"r{drag_ratio:g}_s{stiffness_scale:g}",
        viscosity_scale=viscosity_scale_of(drag_ratio, constrained_scale),
        stiffness_scale=stiffness_scale,
    )


def step_hold_s(drag_ratio: float, stiffness_scale: float) -> float:
    """How long (s) `step_t63_s` holds the step in medium (r, s): `STEP_HOLD_S_PER_RATIO` r / s,
    some 6 of the medium's 63% times (they grow as r and as about 1 / s)."""
    return STEP_HOLD_S_PER_RATIO * drag_ratio / stiffness_scale


def step_t63_s(arm, hold_s: float, backend: str = "c") -> float:
    """63% time (s) of the tip's xy deflection after chamber 0 is commanded to 2 bar (through
    the valve, the others at the floor), sampled each 0.1 s control period on `backend`
    (MuJoCo C for an `mjx_arm.Arm`; "rod" for a `mjx_arm.RodArm`, its own simulator).

    Args:
      arm: the arm in its medium.
      hold_s: how long the step is held (s); `step_hold_s` for a chain medium.
      backend: the simulator.

    Returns:
      the time (s, a multiple of the 0.1 s period) at which the deflection first reaches 63.2%
      of its value at the end of the hold; NaN when the tip does not move.
    """
    n = int(round(hold_s * constants.CONTROL_HZ))
    command = np.full((n, 3), arm.valve.p_min_bar)
    command[:, 0] = STEP_PRESSURE_BAR
    poses = arm.rollout(command, backend=backend)
    rest = arm.rollout(np.full((1, 3), arm.valve.p_min_bar), backend=backend)[0]
    deflection = np.linalg.norm(poses[:, :2] - rest[:2], axis=-1)
    return time_constant_63(np.arange(1, n + 1) / constants.CONTROL_HZ, deflection)
