"""Factors that `python -m mjx_arm.fit` fitted to the reference rod (`models/softarm_fit.json`).

`mjx_arm.model_gen.ArmParams` takes its stiffness, chamber gain and drag defaults from `FIT`, and
`mjx_arm.domains.CONSTRAINED` its viscosity scale.
"""

from __future__ import annotations

import json
from pathlib import Path

from mjx_arm import constants

#: Where `python -m mjx_arm.fit` stores the fitted factors that the defaults below read.
FIT_PATH = constants.ROOT / "models" / "softarm_fit.json"
#: Values used when no fit is stored: the physical values, nothing fitted.
UNFITTED = {
    "stiffness_scale": 1.0,
    "chamber_gain_scale": 1.0,
    "medium_drag_ns_per_m2": 2057.0,
    "constrained_viscosity_scale": 10.0,
}


def load_fit(path: Path = FIT_PATH) -> dict[str, float]:
    """The fitted factors stored by `python -m mjx_arm.fit` (`UNFITTED` when there is no file).

    Raises:
      ValueError: the file exists but is not a fit result.
    """
    if not path.exists():
        return dict(UNFITTED)
    try:
        values = json.loads(path.read_text())["fitted"]
        return {name: float(values[name]) for name in UNFITTED}
    except (ValueError, KeyError, TypeError) as err:
        raise ValueError(f"{path} is not a fit result of `python -m mjx_arm.fit`: {err}") from err


FIT = load_fit()
