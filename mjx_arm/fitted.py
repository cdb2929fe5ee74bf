"""Factors that `python -m mjx_arm.fit` fitted to the reference rod, one file per section.

`mjx_arm.model_gen.ArmParams` takes its stiffness, chamber gain and media from the fit of its
section (`models/softarm_fit.json` for the I-Support section, `models/softarm_solid_fit.json`
for the solid disc), and writes the constrained medium's scale into the MJCF, where
`mjx_arm.domains.CONSTRAINED` reads it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from mjx_arm import constants

#: Where `python -m mjx_arm.fit` stores the fitted factors of each section.
FIT_PATHS = {
    "isupport": constants.ROOT / "models" / "softarm_fit.json",
    "solid": constants.ROOT / "models" / "softarm_solid_fit.json",
}
#: The default section's fit file.
FIT_PATH = FIT_PATHS["isupport"]
#: Names of the fitted factors.
FIT_NAMES = (
    "stiffness_scale",
    "chamber_gain_scale",
    "medium_drag_ns_per_m2",
    "constrained_viscosity_scale",
)


def damper_drag_rate_per_s(damping_per_s: float, dt_s: float = constants.PAPER_TIMESTEP_S) -> float:
    """The linear drag rate (1/s) that the paper code's damper v <- v exp(-c dt) stands for.

    One step of v' = -b v with a forward (explicit) kick removes b dt of the speed; the damper
    keeps exp(-c dt) of it, i.e. removes as much as b = (exp(c dt) - 1) / dt does, applied to
    the post-kick speed. The ratio between two media therefore depends on dt: 800 and 8000 1/s
    at 2e-4 s give 867.6 and 19,765 1/s, 22.8x, not 10x.
    """
    return math.expm1(damping_per_s * dt_s) / dt_s


def unfitted(mass_per_length_kg_m: float) -> dict[str, float]:
    """Starting values with nothing fitted: the physical stiffness and chamber force, and the
    paper code's media as linear drags (per-mass rates times the mass per length)."""
    source = damper_drag_rate_per_s(constants.PAPER_DAMPING_PER_S["source"])
    constrained = damper_drag_rate_per_s(constants.PAPER_DAMPING_PER_S["constrained"])
    return {
        "stiffness_scale": 1.0,
        "chamber_gain_scale": 1.0,
        "medium_drag_ns_per_m2": source * mass_per_length_kg_m,
        "constrained_viscosity_scale": constrained / source,
    }


def load_fit(path: Path = FIT_PATH) -> dict[str, float] | None:
    """The fitted factors stored by `python -m mjx_arm.fit`, or None when there is no file.

    Raises:
      ValueError: the file exists but is not a fit result.
    """
    if not path.exists():
        return None
    try:
        values = json.loads(path.read_text())["fitted"]
        return {name: float(values[name]) for name in FIT_NAMES}
    except (ValueError, KeyError, TypeError) as err:
        raise ValueError(f"{path} is not a fit result of `python -m mjx_arm.fit`: {err}") from err
