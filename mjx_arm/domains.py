"""Domains: the medium and body changes that distinguish one arm world from another.

A domain is data. It edits a compiled `mujoco.MjModel` (viscosity, stiffness, mass) so any MJCF that
passes validation can be put in any domain.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import numbers
import os
from pathlib import Path

import mujoco
import numpy as np

from mjx_arm import checks, constants, fitted

#: Explicit (Euler) fluid drag is stable while timestep * drag rate stays below 2; keep a margin.
DRAG_STEP_MARGIN = 0.5
#: Explicit joint springs are stable while timestep * natural frequency stays below 2.
SPRING_STEP_MARGIN = 1.0


@dataclasses.dataclass(frozen=True)
class Domain:
    """A world for the arm.

    The built-in domains are `source` (D_s, the model's own medium), `constrained` (D_c, the
    paper's medium with ten times the per-mass damping; on this chain that is the viscosity scale
    fitted to the reference rod by `python -m mjx_arm.fit`) and `aged` (stiffness x 0.7 in the
    constrained medium). Statics do not depend on viscosity, so source and constrained hold the
    same pose under a held pressure; only the dynamics differ.
    """

    name: str = "custom"
    """Label stored with datasets and results."""
    viscosity: float | None = None
    """Medium viscosity (Pa s); None keeps the MJCF's `<option viscosity>`."""
    viscosity_scale: float | None = 1.0
    """Multiplies the viscosity (after `viscosity` is applied). None: the model's own
    constrained medium, the `<custom>` numeric `constrained_viscosity_scale` that
    `python -m mjx_arm.fit` fitted for it (a model without one, such as the frozen
    `models/softarm_solid.xml`, gets the solid arm's fitted scale)."""
    stiffness_scale: float = 1.0
    """Multiplies every joint stiffness (e.g. 0.7 for an aged, softer arm)."""
    mass_scale: float = 1.0
    """Multiplies every body mass and inertia (a physical change: gravity loads change too)."""
    inertia_scale: float | None = None
    """Numerical mass scaling (not physical): multiplies masses, inertias and armature and divides
    gravity by the same factor, so gravity loads, statics and the overdamped response stay put
    while explicit fluid drag becomes stable at the model's timestep. None picks the smallest
    factor with timestep * drag rate <= DRAG_STEP_MARGIN and timestep * the stiffest joint's
    natural frequency <= SPRING_STEP_MARGIN. Use 1.0 to switch it off."""

    def __post_init__(self):
        """Refuses, before any model is touched, what no domain can have: a name that is not a
        string; for the numbers, a bool, a string or another non-real value (TypeError), or one
        that is not finite and > 0 (ValueError). Valid numbers of any real type (numpy scalars
        included) are kept as Python floats."""
        if not isinstance(self.name, str):
            raise TypeError(f"Domain.name must be a str, got {type(self.name).__name__}")
        for field in dataclasses.fields(self):
            if field.name == "name":
                continue
            value = getattr(self, field.name)
            if value is None and field.name in _MAY_BE_NONE:
                continue
            allowed = "a real number" + (" or None" if field.name in _MAY_BE_NONE else "")
            if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
                raise TypeError(
                    f"Domain.{field.name} must be {allowed} (finite, > 0), got {value!r} of type"
                    f" {type(value).__name__}"
                )
            if not math.isfinite(value) or value <= 0:
                raise ValueError(f"Domain.{field.name} must be finite and > 0, got {value}")
            object.__setattr__(self, field.name, float(value))


#: The Domain fields for which None means "the model's own" (see each field's doc).
_MAY_BE_NONE = ("viscosity", "viscosity_scale", "inertia_scale")


SOURCE = Domain(name="source")
CONSTRAINED = Domain(name="constrained", viscosity_scale=None)
AGED = Domain(name="aged", stiffness_scale=0.7, viscosity_scale=None)
DOMAINS = {d.name: d for d in (SOURCE, CONSTRAINED, AGED)}


def resolve(domain: str | Domain) -> Domain:
    """Returns the Domain named `domain`, or `domain` itself."""
    if isinstance(domain, Domain):
        return domain
    try:
        return DOMAINS[domain]
    except KeyError:
        raise ValueError(f"unknown domain {domain!r}; built-in: {sorted(DOMAINS)}") from None


def model_viscosity_scale(
    mj_model: mujoco.MjModel, source: str = "the MJCF", solid: bool = False
) -> float:
    """The constrained medium's viscosity over the source's, as the model records it.

    The committed solid-disc arm (`solid`), whose file predates the numeric, takes its fit's.

    Raises:
      ModelValidationError: another model that records none: its constrained medium is unknown.
    """
    stored = checks.custom_numeric(mj_model, constants.CUSTOM_CONSTRAINED_SCALE, math.nan)
    if math.isnan(stored) and solid:
        return fitted.load_fit(fitted.FIT_PATHS["solid"])["constrained_viscosity_scale"]
    if math.isnan(stored):
        raise checks.ModelValidationError(
            f"{source} records no constrained medium (<custom><numeric"
            f' name="{constants.CUSTOM_CONSTRAINED_SCALE}">), so a domain with'
            " viscosity_scale=None has no scale to take: pass a mjx_arm.Domain with"
            " viscosity_scale (or viscosity) set, e.g. mjx_arm.Domain(name='constrained',"
            " viscosity_scale=20.0)"
        )
    return stored


def drag_rate_per_s(mj_model: mujoco.MjModel) -> float:
    """Largest translational viscous drag rate (1/s) of any body under MuJoCo's inertia-box model.

    The box of each body is the one with the body's inertia; the viscous force is
    3 pi mu d v with d the mean box side, so the velocity relaxes at 3 pi mu d / m.
    """
    rates = [0.0]
    for body in range(1, mj_model.nbody):
        mass = mj_model.body_mass[body]
        if mass <= 0:
            continue
        ixx, iyy, izz = mj_model.body_inertia[body]
        sides = np.sqrt(
            np.maximum(
                6.0 / mass * np.array([iyy + izz - ixx, ixx + izz - iyy, ixx + iyy - izz]), 0.0
            )
        )
        diameter = float(sides.mean())
        rates.append(3.0 * math.pi * mj_model.opt.viscosity * diameter / mass)
    return max(rates)


def spring_frequency_rad_per_s(mj_model: mujoco.MjModel) -> float:
    """Largest sqrt(stiffness / joint-space inertia) over the joints, at the reference pose."""
    data = mujoco.MjData(mj_model)
    mujoco.mj_forward(mj_model, data)
    inertia = np.zeros((mj_model.nv, mj_model.nv))
    mujoco.mj_fullM(mj_model, data, inertia)
    diagonal = np.diag(inertia)
    frequencies = [0.0]
    for joint in range(mj_model.njnt):
        dof = mj_model.jnt_dofadr[joint]
        width = {0: 6, 1: 3, 2: 1, 3: 1}[int(mj_model.jnt_type[joint])]
        smallest = diagonal[dof : dof + width].min()
        if mj_model.jnt_stiffness[joint] > 0 and smallest > 0:
            frequencies.append(math.sqrt(mj_model.jnt_stiffness[joint] / smallest))
    return max(frequencies)


def _scale_stretch_softening(m: mujoco.MjModel, stiffness_scale: float) -> None:
    """A softer arm's hinge softening (`mjx_arm.stretch`) follows its springs: each softening
    gain is its hinge's stiffness, and the chambers stretch a softer body further."""
    soften = [i for i in range(m.nu) if m.actuator(i).name.startswith(constants.SOFTEN_PREFIX)]
    if not soften or stiffness_scale == 1.0:
        return
    m.actuator_gainprm[soften, 1] *= stiffness_scale
    numeric = m.numeric(constants.CUSTOM_STRETCH_PER_BAR)
    m.numeric_data[m.numeric_adr[numeric.id]] /= stiffness_scale


def apply(
    mj_model: mujoco.MjModel, domain: Domain, source: str = "the MJCF", solid: bool = False
) -> float:
    """Edits `mj_model` in place to put it in `domain` (`source`, `solid`: as
    `model_viscosity_scale`).

    Returns:
      The inertia scale applied (1.0 when none).
    """
    m = mj_model
    if domain.viscosity is not None:
        m.opt.viscosity = domain.viscosity
    m.opt.viscosity *= (
        model_viscosity_scale(m, source, solid)
        if domain.viscosity_scale is None
        else (domain.viscosity_scale)
    )
    if m.opt.viscosity <= 0 and m.opt.density <= 0:
        raise ValueError("the domain's medium has zero viscosity and density: MJX drops fluid code")
    m.jnt_stiffness[:] *= domain.stiffness_scale
    _scale_stretch_softening(m, domain.stiffness_scale)
    m.body_mass[:] *= domain.mass_scale
    m.body_inertia[:] *= domain.mass_scale

    scale = domain.inertia_scale
    if scale is None:
        drag = m.opt.timestep * drag_rate_per_s(m) / DRAG_STEP_MARGIN
        spring = (m.opt.timestep * spring_frequency_rad_per_s(m) / SPRING_STEP_MARGIN) ** 2
        scale = max(1.0, drag, spring)
    if scale != 1.0:
        m.body_mass[:] *= scale
        m.body_inertia[:] *= scale
        m.dof_armature[:] *= scale
        m.opt.gravity[:] /= scale
        # Actuator and spring forces are unchanged, so statics are unchanged; gravity compensates.
    return float(scale)


#: The name of every Domain read from a file (`read_domain_file`): a teaching arm fitted to a
#: target's data, never a built-in medium.
IDENTIFIED = "identified"


@dataclasses.dataclass(frozen=True)
class DomainFile:
    """A Domain read from a JSON file (`read_domain_file`), with what its callers record.

    Attributes:
      domain: the Domain, named `IDENTIFIED`.
      path: the file, as given.
      sha256: hex digest of the file's bytes: which identification a run was taught on.
      method: the identification method whose fit it is (an identify.json), or None (a plain
        ``{"domain": {...}}`` file).
    """

    domain: Domain
    path: str
    sha256: str
    method: str | None

    def record(self) -> dict:
        """A JSON-ready record: {"path", "sha256", "method", "domain": every Domain field}."""
        return {
            "path": self.path,
            "sha256": self.sha256,
            "method": self.method,
            "domain": dataclasses.asdict(self.domain),
        }


def read_domain_file(path: str | os.PathLike, keep_name: bool = False) -> DomainFile:
    """Reads a Domain from a JSON file: `python -m mjx_arm.identify`'s identify.json (the fitted
    domain of its one method; of several, the one with the lowest held-out tip RMS, the
    identification's own score on the target's held-out programs), or a plain
    ``{"domain": {<Domain fields>}}`` (fields left out keep their defaults; null where a field
    allows None). The Domain is renamed `IDENTIFIED` whatever the file calls it, so that a
    teaching arm is never taken for a built-in medium; with `keep_name` it keeps the name the
    file must give (a medium babbled as a truth, `mjx_arm.babble --domain-file`, whose files
    and program streams carry its name).

    Raises:
      FileNotFoundError: no file at `path`.
      ValueError: one line naming the file and the problem: not JSON, neither layout, an
        identify.json without results, an unknown Domain field, or a value `Domain` refuses
        (not a real number, not finite and > 0); with `keep_name`, a Domain without a name.
    """
    raw_path = Path(path)
    if not raw_path.is_file():
        raise FileNotFoundError(f"domain file {path}: no such file")
    data = raw_path.read_bytes()
    try:
        content = json.loads(data)
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"domain file {path} is not JSON ({err})") from None
    if not isinstance(content, dict):
        kind = type(content).__name__
        raise ValueError(f"domain file {path}: expected a JSON object, got {kind}")
    method = None
    if "results" in content:  # identify.json
        results = content["results"]
        if not isinstance(results, dict) or not results:
            raise ValueError(f"domain file {path}: an identify.json without results")
        bad = [m for m, r in results.items() if not isinstance(r, dict) or "domain" not in r]
        if bad:
            raise ValueError(f"domain file {path}: results {bad} hold no fitted domain")
        method = next(iter(results))
        if len(results) > 1:
            method = min(results, key=lambda m: _held_out_rms(results[m], path, m))
        fields = results[method]["domain"]
    elif "domain" in content:
        fields = content["domain"]
    else:
        raise ValueError(
            f'domain file {path}: neither an identify.json (results) nor {{"domain": {{...}}}}'
        )
    if not isinstance(fields, dict):
        raise ValueError(f"domain file {path}: its domain is not a JSON object")
    known = {f.name for f in dataclasses.fields(Domain)}
    unknown = sorted(set(fields) - known)
    if unknown:
        raise ValueError(
            f"domain file {path}: unknown Domain fields {unknown}; known: {sorted(known)}"
        )
    if keep_name and not isinstance(fields.get("name"), str):
        raise ValueError(f'domain file {path}: its domain needs a "name"')
    try:
        domain = Domain(**(fields if keep_name else fields | {"name": IDENTIFIED}))
    except (TypeError, ValueError) as err:
        raise ValueError(f"domain file {path}: {err}") from None
    digest = hashlib.sha256(data).hexdigest()
    return DomainFile(domain=domain, path=str(path), sha256=digest, method=method)


def _held_out_rms(result: dict, path, method: str) -> float:
    """An identify.json result's held-out tip RMS (cm), which ranks several methods' fits."""
    value = result.get("val_rms_cm")
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"domain file {path}: result {method!r} has no held-out tip RMS")
    return float(value)


def physical_values(mj_model: mujoco.MjModel, source_mj_model: mujoco.MjModel, domain: Domain):
    """What a domain changes physically, comparable across ways of writing it: {"viscosity_scale":
    the medium's viscosity over the source medium's (`source_mj_model`: the same MJCF in
    "source"), "stiffness_scale", "mass_scale"}, for `mj_model` loaded in `domain`. A Domain
    with viscosity_scale None (the model's own constrained medium) and one with the fitted
    number give the same values, so an identified arm can be set beside the truth."""
    return {
        "viscosity_scale": float(mj_model.opt.viscosity / source_mj_model.opt.viscosity),
        "stiffness_scale": domain.stiffness_scale,
        "mass_scale": domain.mass_scale,
    }
