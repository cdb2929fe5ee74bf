"""The reference rod's parameters, state and per-discretisation constants (`mjx_arm.cosserat`).

`CosseratParams` holds the physics and numerics of one rod; `make_rod` turns them into the
constants the jitted dynamics (`mjx_arm.rod_dynamics`) close over. The law and the modelling
choices are described in `mjx_arm.cosserat`'s docstring.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from mjx_arm import constants
from mjx_arm.model_gen import ArmParams

_ARM = ArmParams()

#: Translational damping constants (1/s) of the paper's two domains [paper code]: per unit mass,
#: so the medium's force per length is c times the mass per length.
DOMAIN_DAMPING_PER_S = constants.PAPER_DAMPING_PER_S

#: Constitutive laws: "gazzola" divides force by the stretch e and couple by e_v^3 (Gazzola et
#: al. 2018, PyElastica, the paper's simulator); "linear" leaves those factors out (the earlier
#: reference, and the law of the chain's constant joint springs).
LAWS = ("gazzola", "linear")


@dataclasses.dataclass(frozen=True)
class CosseratParams:
    """Physical and numerical parameters of the reference rod.

    Geometry, section, mass and elasticity default to `mjx_arm.model_gen.ArmParams`'s physical
    values (never its fitted factors; `from_arm` takes another arm's), damping to the paper's
    source domain, the timestep to the paper code's.
    """

    length_m: float = _ARM.length_m
    """Rod length (m)."""
    area_m2: float = _ARM.area_m2
    """Load-carrying area A of the section (m^2), for E A and a G A."""
    second_moment_m4: float = _ARM.second_moment_m4
    """Second moment of area I of the section (m^4), for E I."""
    polar_moment_m4: float = _ARM.polar_moment_m4
    """Polar second moment J of the section (m^4), for G J."""
    mass_kg: float = _ARM.mass_kg
    """Total mass (kg), spread uniformly [paper: 183 g]."""
    youngs_modulus_pa: float = _ARM.youngs_modulus_pa
    """Young's modulus E (Pa)."""
    shear_modulus_pa: float = _ARM.shear_modulus_pa
    """Shear modulus G (Pa), E / 3 for Poisson ratio 0.5."""
    shear_coefficient: float = 4.0 / 3.0
    """Factor a on the shear stiffness a G A (-) [PyElastica's default]."""
    chamber_length_m: float = _ARM.chamber_length_m
    """Chamber span from the base (m)."""
    chamber_offset_m: float = _ARM.chamber_offset_m
    """Chamber centre distance from the axis (m)."""
    chamber_area_m2: float = _ARM.chamber_area_m2
    """Effective chamber area on which pressure pushes the end cap (m^2)."""
    gravity_mps2: float = _ARM.gravity_mps2
    """Gravity along -z (m/s^2); 0 switches it off."""
    n_elements: int = 20
    """Elements of the rod (-) [paper: 20]."""
    damping_per_s: float = DOMAIN_DAMPING_PER_S["source"]
    """Translational damping constant c: v <- v exp(-c dt) (1/s) [paper: 800 / 8000]."""
    rotational_damping: float = 1e-4
    """Rotational damping constant c_rot: omega <- omega exp(-c_rot dt m_e / J) (1/s) [paper]."""
    dt_s: float | None = constants.PAPER_TIMESTEP_S
    """Timestep (s) [paper code: 2e-4 s, which also sets what its damper means]; None picks the
    largest that divides the 0.1 s control period and stays below `cfl` times the stability
    limit."""
    cfl: float = 0.7
    """Fraction of the explicit stability limit used when `dt_s` is None (-)."""
    settle_damping_per_s: float | None = None
    """Damping (1/s, translational and rotational) of static solves; None uses twice the first
    bending frequency, which settles the slowest mode about critically."""
    settle_tol_mps: float = 1e-7
    """Static solves stop once every node and element-rim speed is below this (m/s)."""
    settle_max_s: float = 10.0
    """Upper limit on the simulated time of one static solve (s)."""
    law: str = "gazzola"
    """Constitutive law (`LAWS`): "gazzola" with the stretch factors [paper's simulator], or
    "linear" without them [the earlier reference, kept for comparison]."""

    # ------------------------------------------------------------------ derived quantities

    @property
    def element_length_m(self) -> float:
        return self.length_m / self.n_elements

    @property
    def element_mass_kg(self) -> float:
        return self.mass_kg / self.n_elements

    @property
    def gyration_radius_m(self) -> float:
        """sqrt(I / A) (m): an element's rotational inertia is its mass times this squared."""
        return math.sqrt(self.second_moment_m4 / self.area_m2)

    @property
    def density_kg_m3(self) -> float:
        return self.mass_kg / (self.area_m2 * self.length_m)

    @property
    def bend_stiffness_nm2(self) -> float:
        """E I (N m^2)."""
        return self.youngs_modulus_pa * self.second_moment_m4

    @property
    def axial_stiffness_n(self) -> float:
        """E A (N)."""
        return self.youngs_modulus_pa * self.area_m2

    @property
    def shear_stiffness_n(self) -> float:
        """a G A (N)."""
        return self.shear_coefficient * self.shear_modulus_pa * self.area_m2

    @property
    def first_bending_rad_s(self) -> float:
        """First cantilever bending frequency 1.875^2 sqrt(EI / (rho A L^4)) (rad/s)."""
        rho_a = self.mass_kg / self.length_m
        return 1.8751**2 * math.sqrt(self.bend_stiffness_nm2 / (rho_a * self.length_m**4))

    @property
    def max_frequency_rad_s(self) -> float:
        """Upper estimate of the fastest element mode (rad/s).

        Axial (and bending) waves alternate between neighbours at 2 c / l with c = sqrt(E / rho);
        an element's rotation against shear adds a G / (rho g^2) to the square, g the radius of
        gyration (4 a G / (rho r^2) for a solid disc).
        """
        rho, ell = self.density_kg_m3, self.element_length_m
        axial = 4.0 * self.youngs_modulus_pa / (rho * ell**2)
        shear = self.shear_coefficient * self.shear_modulus_pa / (rho * self.gyration_radius_m**2)
        return math.sqrt(axial + shear)

    @property
    def critical_dt_s(self) -> float:
        """Position Verlet is stable for dt < 2 / omega_max (s)."""
        return 2.0 / self.max_frequency_rad_s

    @property
    def n_substeps(self) -> int:
        """Physics steps per 0.1 s control period."""
        if self.dt_s is not None:
            return int(round(constants.CONTROL_PERIOD_S / self.dt_s))
        return math.ceil(constants.CONTROL_PERIOD_S / (self.cfl * self.critical_dt_s))

    @property
    def timestep_s(self) -> float:
        """The timestep used (s): the control period over `n_substeps`."""
        return constants.CONTROL_PERIOD_S / self.n_substeps

    @property
    def settle_rate_per_s(self) -> float:
        if self.settle_damping_per_s is not None:
            return self.settle_damping_per_s
        return 2.0 * self.first_bending_rad_s

    def validate(self) -> None:
        """Raises ValueError for parameters that cannot make a stable rod."""
        if self.n_elements < 2:
            raise ValueError(f"n_elements must be >= 2, got {self.n_elements}")
        if self.law not in LAWS:
            raise ValueError(f"unknown law {self.law!r}; known: {LAWS}")
        if not 0.0 < self.chamber_length_m <= self.length_m:
            raise ValueError("chamber_length_m must lie in (0, length_m]")
        if self.dt_s is not None:
            period = constants.CONTROL_PERIOD_S / self.dt_s
            if abs(period - round(period)) > 1e-6:
                raise ValueError(f"dt_s={self.dt_s} does not divide the 0.1 s control period")
        if self.timestep_s >= self.critical_dt_s:
            raise ValueError(
                f"timestep {self.timestep_s:.3g} s is above the stability limit"
                f" {self.critical_dt_s:.3g} s for {self.n_elements} elements"
            )

    @classmethod
    def for_domain(cls, domain: str, **overrides) -> CosseratParams:
        """Parameters with the damping constant of domain "source" or "constrained"."""
        if domain not in DOMAIN_DAMPING_PER_S:
            raise ValueError(f"unknown domain {domain!r}; known: {sorted(DOMAIN_DAMPING_PER_S)}")
        return cls(damping_per_s=DOMAIN_DAMPING_PER_S[domain], **overrides)

    @classmethod
    def from_arm(cls, arm: ArmParams, domain: str = "source", **overrides) -> CosseratParams:
        """The rod of `arm`'s geometry, section, mass and material in a paper domain."""
        fields = dict(
            length_m=arm.length_m,
            area_m2=arm.area_m2,
            second_moment_m4=arm.second_moment_m4,
            polar_moment_m4=arm.polar_moment_m4,
            mass_kg=arm.mass_kg,
            youngs_modulus_pa=arm.youngs_modulus_pa,
            shear_modulus_pa=arm.shear_modulus_pa,
            chamber_length_m=arm.chamber_length_m,
            chamber_offset_m=arm.chamber_offset_m,
            chamber_area_m2=arm.chamber_area_m2,
            gravity_mps2=arm.gravity_mps2,
        )
        return cls.for_domain(domain, **(fields | overrides))


class RodState(NamedTuple):
    """State of the rod (n elements).

    Attributes:
      x: [n + 1, 3] node positions (m), world frame, base node at the origin.
      v: [n + 1, 3] node velocities (m/s).
      q: [n, 3, 3] directors; row k of q[j] is d_{k+1} of element j in world components.
      w: [n, 3] angular velocities (rad/s) in each element's own frame.
    """

    x: jnp.ndarray
    v: jnp.ndarray
    q: jnp.ndarray
    w: jnp.ndarray


class RodConstants(NamedTuple):
    """Constants of one discretisation, as float64 numpy arrays (closed over by jitted code;
    `astype` casts them)."""

    rest_length: float  # l0 (m)
    dt: float  # (s)
    node_mass: np.ndarray  # [n + 1] (kg)
    inertia: np.ndarray  # [n, 3] element mass moments of inertia in the element frame (kg m^2)
    shear_diag: np.ndarray  # [3] diag of S (N)
    bend_diag: np.ndarray  # [3] diag of B (N m^2)
    voronoi_length: np.ndarray  # [n] base half-domain then interior domains (m)
    chamber_elem: np.ndarray  # [n] fraction of each element inside the chamber span
    chamber_voronoi: np.ndarray  # [n] fraction of each Voronoi domain inside it
    chamber_couple_dir: np.ndarray  # [3 chambers, 3] d3 x r_k in the element frame (m)
    force_per_bar: float  # chamber force per bar (N)
    clamp: np.ndarray  # [3, 3] base frame
    gravity: np.ndarray  # [3] (m/s^2)
    rot_damp: np.ndarray  # [n, 3] per-step factor on omega (dynamics)
    trans_damp: float  # per-step factor on v (dynamics)
    settle_damp: float  # per-step factor on v and omega (static solves)
    stretch_factors: bool  # the "gazzola" law's 1 / e and 1 / e_v^3 (a static branch)

    def astype(self, dtype) -> RodConstants:
        """These constants with every array in `dtype` (e.g. float32 for a float32 rollout: a
        float64 constant would promote the state under x64). Scalars stay Python floats, which
        take the state's dtype."""
        return RodConstants(
            *(np.asarray(v, dtype) if isinstance(v, np.ndarray) else v for v in self)
        )


#: Rest directors: d1 = +x, d2 = -y, d3 = -z.
CLAMP = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])


def _overlap(lo: np.ndarray, hi: np.ndarray, span: float) -> np.ndarray:
    """Length of [lo, hi] inside [0, span]."""
    return np.clip(np.minimum(hi, span) - np.maximum(lo, 0.0), 0.0, None)


def make_rod(params: CosseratParams) -> RodConstants:
    params.validate()
    n, ell = params.n_elements, params.element_length_m
    dt = params.timestep_s
    m_e = params.element_mass_kg
    node_mass = np.full(n + 1, m_e)
    node_mass[[0, -1]] = 0.5 * m_e
    per_mass = np.array([params.second_moment_m4, params.second_moment_m4, params.polar_moment_m4])
    inertia = np.tile(m_e * per_mass / params.area_m2, (n, 1))
    g_j = params.shear_modulus_pa * params.polar_moment_m4
    starts = np.arange(n) * ell
    elem_frac = _overlap(starts, starts + ell, params.chamber_length_m) / ell
    vor_lo = np.concatenate([[0.0], starts[1:] - 0.5 * ell])
    vor_hi = np.concatenate([[0.5 * ell], starts[1:] + 0.5 * ell])
    voronoi = vor_hi - vor_lo
    vor_frac = _overlap(vor_lo, vor_hi, params.chamber_length_m) / voronoi
    angles = 2.0 * np.pi * np.arange(3) / 3.0
    offsets_world = params.chamber_offset_m * np.stack(
        [np.cos(angles), np.sin(angles), np.zeros(3)], axis=-1
    )
    offsets_local = offsets_world @ CLAMP.T
    couple_dir = np.cross(np.array([0.0, 0.0, 1.0]), offsets_local)
    return RodConstants(
        rest_length=ell,
        dt=dt,
        node_mass=node_mass,
        inertia=inertia,
        shear_diag=np.array(
            [params.shear_stiffness_n, params.shear_stiffness_n, params.axial_stiffness_n]
        ),
        bend_diag=np.array([params.bend_stiffness_nm2, params.bend_stiffness_nm2, g_j]),
        voronoi_length=voronoi,
        chamber_elem=elem_frac,
        chamber_voronoi=vor_frac,
        chamber_couple_dir=couple_dir,
        force_per_bar=constants.BAR_TO_PA * params.chamber_area_m2,
        clamp=CLAMP,
        gravity=np.array([0.0, 0.0, -params.gravity_mps2]),
        rot_damp=np.exp(-params.rotational_damping * dt * m_e / inertia),
        trans_damp=math.exp(-params.damping_per_s * dt),
        settle_damp=math.exp(-params.settle_rate_per_s * dt),
        stretch_factors=params.law == "gazzola",
    )


def straight_state(params: CosseratParams) -> RodState:
    """The undeformed rod hanging straight down, at rest (float64 numpy arrays)."""
    n = params.n_elements
    z = -np.linspace(0.0, params.length_m, n + 1)
    x = np.stack([np.zeros(n + 1), np.zeros(n + 1), z], axis=-1)
    return RodState(x=x, v=np.zeros((n + 1, 3)), q=np.tile(CLAMP, (n, 1, 1)), w=np.zeros((n, 3)))
