"""Checks of what users hand the arm API: MJCF models, the valve constants in them, programs.

Each raises before any simulation, with a message that names what is wrong and where, so a bad
file or program never costs a compile or a rollout.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from mjx_arm import constants, valve


class ModelValidationError(ValueError):
    """An MJCF lacks what the arm API needs."""


def custom_numeric(mj_model: mujoco.MjModel, name: str, default: float) -> float:
    """The value of the MJCF's `<custom><numeric name=...>`, or `default` where absent."""
    for i in range(mj_model.nnumeric):
        if mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_NUMERIC, i) == name:
            return float(mj_model.numeric_data[mj_model.numeric_adr[i]])
    return default


def validate_model(mj_model: mujoco.MjModel, source: str = "model") -> None:
    """Checks that `mj_model` names what the API needs.

    Raises:
      ModelValidationError: listing every missing or unusable element.
    """
    problems = []
    actuators = {mj_model.actuator(i).name for i in range(mj_model.nu)}
    missing = [name for name in constants.CHAMBER_ACTUATORS if name not in actuators]
    if missing:
        problems.append(f"actuators {missing}")
    sites = {mj_model.site(i).name for i in range(mj_model.nsite)}
    if constants.TIP_SITE not in sites:
        problems.append(f"site {constants.TIP_SITE!r}")
    if problems:
        raise ModelValidationError(
            f"{source} is missing " + " and ".join(problems) + ". An arm model must name the"
            f" chamber actuators {list(constants.CHAMBER_ACTUATORS)} and the tip site"
            f" {constants.TIP_SITE!r}."
        )
    if not mj_model.opt.timestep > 0:
        raise ModelValidationError(
            f"{source}: timestep {mj_model.opt.timestep} s must be positive (each step moves"
            f" time forward); give <option timestep> > 0 that divides the"
            f" {constants.CONTROL_PERIOD_S} s control period"
        )
    period = constants.CONTROL_PERIOD_S / mj_model.opt.timestep
    if abs(period - round(period)) > 1e-6:
        raise ModelValidationError(
            f"{source}: timestep {mj_model.opt.timestep} s does not divide the"
            f" {constants.CONTROL_PERIOD_S} s control period"
        )
    if mj_model.opt.integrator not in (
        mujoco.mjtIntegrator.mjINT_EULER,
        mujoco.mjtIntegrator.mjINT_RK4,
    ):
        raise ModelValidationError(
            f"{source}: MJX supports fluid drag only with the Euler or RK4 integrator"
        )


def check_pressures(pressures_bar) -> np.ndarray:
    """Checks a pressure program's shape and finiteness.

    Args:
      pressures_bar: [T, 3] or [B, T, 3] commands (bar).

    Returns:
      The program as a float array [B, T, 3] (B = 1 for a single program).

    Raises:
      TypeError: values that are not real numbers in bar: bools (a mask passed by mistake would
        otherwise run as 0 and 1 bar), strings, complex numbers.
      ValueError: wrong shape (an empty batch or program included: it would fail later, in a
        reshape or after seconds of MJX compilation), or a non-finite value (the message names
        where).
    """
    raw = np.asarray(pressures_bar)
    if raw.dtype.kind not in "iuf":
        raise TypeError(
            f"pressures_bar must be real numbers in bar (int or float), got an array of"
            f" {raw.dtype} ({'bools' if raw.dtype.kind == 'b' else raw.dtype.kind!r})"
        )
    p = raw.astype(np.float64, copy=False)
    if p.ndim not in (2, 3) or p.shape[-1] != 3 or p.shape[-2] == 0 or p.shape[0] == 0:
        raise ValueError(f"pressures_bar must be [T, 3] or [B, T, 3] with B, T > 0, got {p.shape}")
    batched = p if p.ndim == 3 else p[None]
    bad = ~np.isfinite(batched)
    if bad.any():
        where = np.argwhere(bad)
        b, t, c = where[0]
        at = f"trajectory {b}, " if p.ndim == 3 else ""
        raise ValueError(
            f"pressures_bar has {len(where)} non-finite value(s); first at {at}step {t},"
            f" chamber {c} (value {batched[b, t, c]})"
        )
    return batched


def read_model(path, xml: str | None) -> tuple[mujoco.MjModel, Path | None, str, str]:
    """Compiles the MJCF of `load`'s arguments.

    Returns:
      (model, its path or None, a name for messages, the MJCF text that `Arm.model_hash` hashes).

    Raises:
      ValueError: both a path and `xml` are given.
      FileNotFoundError: no file at `path`.
      ModelValidationError: the path is not an MJCF text file (a folder, a binary file such as
        an .npz), or the MJCF does not parse or compile.
    """
    if xml is not None:
        if path is not None:
            raise ValueError(f"give an MJCF path or xml text, not both (path={str(path)!r})")
        source, text, model_path = "MJCF string", xml, None
    else:
        model_path = Path(path) if path is not None else constants.DEFAULT_MODEL_PATH
        source = str(model_path)
        if not model_path.exists():
            raise FileNotFoundError(f"no MJCF at {model_path}")
        if not model_path.is_file():
            raise ModelValidationError(f"{model_path} is not a file; an MJCF file is needed")
        try:
            text = model_path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            raise ModelValidationError(f"{model_path} is not an MJCF text file ({err})") from err
    try:
        if model_path is None:
            mj_model = mujoco.MjModel.from_xml_string(text)
        else:  # from the path, so that includes and assets resolve relative to the file
            mj_model = mujoco.MjModel.from_xml_path(str(model_path))
    except ValueError as err:
        raise ModelValidationError(f"{source} does not parse or compile as MJCF: {err}") from err
    return mj_model, model_path, source, text


def valve_params(m: mujoco.MjModel, source: str) -> valve.ValveParams:
    """The valve constants of the MJCF's <custom> numerics (defaults where absent), checked
    against the chamber actuators' ctrlrange.

    Raises:
      ModelValidationError: constants a valve cannot have (see `valve.check`).
    """
    params = valve.ValveParams(
        **{
            field: custom_numeric(m, name, constants.CUSTOM_VALVE_FIELDS[name])
            for field, name in VALVE_NUMERICS.items()
        }
    )
    ids = [m.actuator(n).id for n in constants.CHAMBER_ACTUATORS]
    limited = m.actuator_ctrllimited[ids].astype(bool)
    ranges = m.actuator_ctrlrange[ids][limited]
    ctrl_range = (float(ranges[:, 0].max()), float(ranges[:, 1].min())) if limited.any() else None
    try:
        return valve.check(params, ctrl_range, names=VALVE_NUMERICS)
    except ValueError as err:
        raise ModelValidationError(f"{source}: bad <custom> valve numerics: {err}") from err


#: ValveParams field -> the MJCF <custom><numeric> that sets it.
VALVE_NUMERICS = {
    "tau_rise_s": "valve_tau_rise",
    "tau_drop_s": "valve_tau_drop",
    "p_min_bar": "valve_p_min",
    "p_max_bar": "valve_p_max",
}
