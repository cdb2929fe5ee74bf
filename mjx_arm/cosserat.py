"""A reference discrete Cosserat rod of the arm, in JAX.

The rod follows the discretisation of Gazzola et al. (2018) that PyElastica implements, written
here from the equations: n + 1 nodes carry positions and velocities; n elements carry directors
(a rotation matrix whose rows are d1, d2, d3 in world components) and an angular velocity in
their own frame. Each element has stretch and shear strain sigma = Q (x_{j+1} - x_j) / l0 - e3;
each Voronoi point between two elements has bend and twist curvature kappa = log(Q_prev Q_next^T)
/ D. With S = diag(a G A, a G A, E A) and B = diag(E I, E I, G J), the default law
(`law="gazzola"`, the paper's simulator, PyElastica) divides by the local stretch, as an
incompressible section thins and softens when it lengthens:

  n = Q^T S (sigma - sigma0) / e,   m = B (kappa - kappa0) / e_v^3,

with e = |x_{j+1} - x_j| / l0 per element and e_v the same ratio of each Voronoi domain; the
rotational dynamics carry the matching terms (J / e is the stretched element's inertia, so
d omega / dt = e J^-1 tau - J^-1 (omega x J omega) + omega de/dt / e). `law="linear"` is the
earlier law without these factors (n = Q^T S (sigma - sigma0), m = B (kappa - kappa0)), kept for
comparison: it is what the chain's constant joint springs follow at any stretch.

Choices (each differs from PyElastica only where it says so):
  * The base is clamped by a fixed frame at the base node and a half-length Voronoi domain
    between it and the first element, so the first element bends too. (PyElastica freezes the
    first element, which moves the effective clamp half an element up and makes the cantilever
    error first order in 1 / n; this clamp keeps it second order.)
  * Curvature is per rest length and the strains are linear in the positions, as PyElastica's.
  * Couples pass between neighbours as world vectors in the frame halfway between them, so
    internal couples cancel exactly (PyElastica adds kappa x B kappa for the same effect).
  * Each pressurised chamber adds an internal (active) resultant on the span it covers: an axial
    force -F d3 and a couple F (d3 x r) with r its offset, as the fluid in the lumen pushes the
    distal end cap. It enters as rest strains, sigma0 = F / (E A) e3 and kappa0 = -F (d3 x r) /
    B, so the stretch factors scale it with the elastic terms (PyElastica writes active loads
    the same way). A free rod then stretches by F / EA and bends with curvature F |r| / EI away
    from the chamber under either law, the same sign as the MuJoCo model.
  * Damping is PyElastica's analytical linear damper, as the paper code used it: after each
    step v <- v exp(-c dt) and omega <- omega exp(-c_rot dt m_e / J), unconditionally stable.
    It removes as much speed as a linear drag of rate (exp(c dt) - 1) / dt would
    (`mjx_arm.fitted.damper_drag_rate_per_s`), so the medium depends on dt; the rod runs at
    the paper code's 2e-4 s.
  * The section (`mjx_arm.section`) sets A, I and J, and the element's rotational inertia is its
    mass times the section's radius of gyration squared (I / A, J / A): mass spread like the
    load-carrying area.

Time integration is position Verlet (half drift, kick, half drift), explicit, in float64 (the
public functions run under `jax.enable_x64`). The timestep is the paper code's 2e-4 s, checked
against a stability bound on the fastest element mode (`CosseratParams.max_frequency_rad_s`).

Pose: tip node position (m) then d3 of the last element (its unit tangent). The arm hangs along
-z from a base at the origin; at rest d1 = +x, d2 = -y, d3 = -z, and chamber k sits at angle
2 pi k / 3 from +x in the world xy plane.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mjx_arm import checks, constants, rotations, valve
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


class _Rod(NamedTuple):
    """Constants of one discretisation, as float64 numpy arrays (closed over by jitted code)."""

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


#: Rest directors: d1 = +x, d2 = -y, d3 = -z.
_CLAMP = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])


def _overlap(lo: np.ndarray, hi: np.ndarray, span: float) -> np.ndarray:
    """Length of [lo, hi] inside [0, span]."""
    return np.clip(np.minimum(hi, span) - np.maximum(lo, 0.0), 0.0, None)


def _make_rod(params: CosseratParams) -> _Rod:
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
    offsets_local = offsets_world @ _CLAMP.T
    couple_dir = np.cross(np.array([0.0, 0.0, 1.0]), offsets_local)
    return _Rod(
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
        clamp=_CLAMP,
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
    return RodState(x=x, v=np.zeros((n + 1, 3)), q=np.tile(_CLAMP, (n, 1, 1)), w=np.zeros((n, 3)))


# ---------------------------------------------------------------------- physics


def _dilatations(rod: _Rod, edges: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Stretch e [n] of each element and e_v [n] of each Voronoi domain (-).

    The base half-domain (clamp to the first element's centre) takes the first element's e;
    each interior domain spans half of each neighbour, so e_v = (l_{j-1} + l_j) / (2 l0).
    """
    e = jnp.linalg.norm(edges, axis=-1) / rod.rest_length
    e_voronoi = jnp.concatenate([e[:1], 0.5 * (e[:-1] + e[1:])])
    return e, e_voronoi


def _loads(
    rod: _Rod,
    x: jnp.ndarray,
    q: jnp.ndarray,
    pressure_bar: jnp.ndarray,
    tip_force_n: jnp.ndarray,
    tip_couple_nm: jnp.ndarray,
) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """Node forces [n + 1, 3] (N, world), element torques [n, 3] (N m, element frame) and the
    element stretches e [n] (-, ones under the linear law)."""
    e3 = jnp.array([0.0, 0.0, 1.0], dtype=x.dtype)
    chamber_force = pressure_bar * rod.force_per_bar  # [3] (N)

    edges = x[1:] - x[:-1]
    if rod.stretch_factors:
        stretch, stretch_voronoi = _dilatations(rod, edges)
    else:
        stretch = stretch_voronoi = jnp.ones(edges.shape[0], x.dtype)
    sigma = jnp.einsum("nij,nj->ni", q, edges) / rod.rest_length - e3
    n_local = sigma * rod.shear_diag - (chamber_force.sum() * rod.chamber_elem)[:, None] * e3
    n_local = n_local / stretch[:, None]
    n_world = jnp.einsum("nji,nj->ni", q, n_local)

    q_prev = jnp.concatenate([jnp.asarray(rod.clamp, x.dtype)[None], q[:-1]], axis=0)
    theta = rotations.log_so3(q_prev @ jnp.swapaxes(q, -1, -2))  # [n, 3] in the frame of q_prev
    kappa = theta / rod.voronoi_length[:, None]
    active = rod.chamber_voronoi[:, None] * (chamber_force @ rod.chamber_couple_dir)[None]
    m_local = (kappa * rod.bend_diag + active) / stretch_voronoi[:, None] ** 3
    m_mid = jnp.einsum("nij,nj->ni", rotations.exp_so3(0.5 * theta), m_local)
    m_world = jnp.einsum("nji,nj->ni", q_prev, m_mid)

    zero = jnp.zeros((1, 3), x.dtype)
    forces = jnp.concatenate([n_world, zero]) - jnp.concatenate([zero, n_world])
    forces = forces + rod.node_mass[:, None] * rod.gravity
    forces = forces.at[-1].add(tip_force_n)

    torque_world = jnp.concatenate([m_world[1:], zero]) - m_world + jnp.cross(edges, n_world)
    torque_world = torque_world.at[-1].add(tip_couple_nm)
    return forces, jnp.einsum("nij,nj->ni", q, torque_world), stretch


def _step(
    rod: _Rod,
    state: RodState,
    pressure_bar: jnp.ndarray,
    tip_force_n: jnp.ndarray,
    tip_couple_nm: jnp.ndarray,
    trans_damp,
    rot_damp,
) -> RodState:
    """One position-Verlet step: half drift, kick with damping, half drift; base node fixed.

    Under the "gazzola" law an element stretched by e has the rotational inertia J / e of its
    thinner section, and a stretching element slows its spin as its inertia changes:
    d omega / dt = (e tau - omega x J omega) / J + omega (de/dt) / e.
    """
    h = 0.5 * rod.dt
    x = (state.x + h * state.v).at[0].set(0.0)
    q = rotations.exp_so3(-h * state.w) @ state.q
    forces, torques, stretch = _loads(rod, x, q, pressure_bar, tip_force_n, tip_couple_nm)
    w = state.w
    spin = (torques * stretch[:, None] - jnp.cross(w, rod.inertia * w)) / rod.inertia
    if rod.stretch_factors:
        edges = x[1:] - x[:-1]
        tangents = edges / jnp.linalg.norm(edges, axis=-1, keepdims=True)
        stretch_rate = jnp.sum(tangents * (state.v[1:] - state.v[:-1]), -1) / rod.rest_length
        spin = spin + w * (stretch_rate / stretch)[:, None]
    v = state.v + rod.dt * forces / rod.node_mass[:, None]
    v = (v * trans_damp).at[0].set(0.0)
    w = w + rod.dt * spin
    w = w * rot_damp
    x = (x + h * v).at[0].set(0.0)
    q = rotations.exp_so3(-h * w) @ q
    return RodState(x, v, q, w)


def tip_pose(state: RodState) -> jnp.ndarray:
    """Pose [6]: tip node position (m) then d3 of the last element."""
    return jnp.concatenate([state.x[-1], state.q[-1, 2]])


def _settle(
    rod: _Rod,
    n_chunk: int,
    max_chunks: int,
    tol: float,
    radius: float,
    state: RodState,
    pressure_bar: jnp.ndarray,
    tip_force_n: jnp.ndarray,
    tip_couple_nm: jnp.ndarray,
) -> tuple[RodState, jnp.ndarray]:
    """Heavily damped dynamics until every speed is below `tol`; returns (state, steps)."""

    def chunk(st, _):
        return _step(
            rod, st, pressure_bar, tip_force_n, tip_couple_nm, rod.settle_damp, rod.settle_damp
        ), None

    def cond(carry):
        _, k, speed = carry
        return (k < max_chunks) & (speed > tol)

    def body(carry):
        st, k, _ = carry
        st, _ = jax.lax.scan(chunk, st, None, length=n_chunk)
        st = st._replace(q=rotations.orthonormalise(st.q))
        speed = jnp.maximum(jnp.abs(st.v).max(), radius * jnp.abs(st.w).max())
        return st, k + 1, speed

    init = (state, jnp.array(0), jnp.array(jnp.inf, dtype=state.x.dtype))
    state, k, _ = jax.lax.while_loop(cond, body, init)
    return state, k * n_chunk


def _rollout_single(
    rod: _Rod,
    n_substeps: int,
    valve_params: valve.ValveParams,
    rest: RodState,
    commands_bar: jnp.ndarray,
) -> jnp.ndarray:
    """Commands [T, 3] (bar) -> poses [T, 6], read at the end of each control period."""
    commands = valve.saturate(commands_bar, valve_params)
    zero = jnp.zeros(3, commands.dtype)

    def physics_step(st, pressure):
        return _step(rod, st, pressure, zero, zero, rod.trans_damp, rod.rot_damp), None

    def control_step(carry, command):
        st, pressure = carry
        pressures = valve.substep_pressures(pressure, command, n_substeps, rod.dt, valve_params)
        st, _ = jax.lax.scan(physics_step, st, pressures)
        st = st._replace(q=rotations.orthonormalise(st.q))
        return (st, pressures[-1]), tip_pose(st)

    p0 = jnp.full((3,), valve_params.p_min_bar, commands.dtype)
    _, poses = jax.lax.scan(control_step, (rest, p0), commands)
    return poses


# ---------------------------------------------------------------------- public API


@functools.lru_cache(maxsize=32)
def _settle_fn(params: CosseratParams):
    rod = _make_rod(params)
    n_chunk = 100
    max_chunks = max(1, math.ceil(params.settle_max_s / (n_chunk * rod.dt)))
    return jax.jit(
        functools.partial(
            _settle, rod, n_chunk, max_chunks, params.settle_tol_mps, params.gyration_radius_m
        )
    )


def static_state(
    pressures_bar,
    params: CosseratParams = CosseratParams(),
    tip_force_n=(0.0, 0.0, 0.0),
    tip_couple_nm=(0.0, 0.0, 0.0),
    initial: RodState | None = None,
) -> tuple[RodState, int]:
    """Equilibrium of the rod under chamber pressures and optional tip loads.

    Solved by heavily damped dynamics (`CosseratParams.settle_damping_per_s`), which leaves the
    equilibrium unchanged. Pressures are used as given (no valve saturation), so tests can load
    the rod with any pressure.

    Args:
      pressures_bar: [3] chamber pressures (bar).
      params: the rod.
      tip_force_n: [3] force on the tip node (N, world frame).
      tip_couple_nm: [3] couple on the last element (N m, world frame).
      initial: start state; None starts from the straight rod.

    Returns:
      (state, steps): the settled `RodState` as float64 numpy arrays, and the physics steps taken.
    """
    start = straight_state(params) if initial is None else initial
    with jax.enable_x64(True):
        state, steps = _settle_fn(params)(
            RodState(*(jnp.asarray(a, jnp.float64) for a in start)),
            jnp.asarray(pressures_bar, jnp.float64),
            jnp.asarray(tip_force_n, jnp.float64),
            jnp.asarray(tip_couple_nm, jnp.float64),
        )
        return RodState(*(np.asarray(a) for a in state)), int(steps)


def static_pose(
    pressures_bar,
    params: CosseratParams = CosseratParams(),
    tip_force_n=(0.0, 0.0, 0.0),
    tip_couple_nm=(0.0, 0.0, 0.0),
) -> np.ndarray:
    """Equilibrium tip pose [6] (m, then unit d3) under held pressures [3] (bar); see
    `static_state`."""
    state, _ = static_state(pressures_bar, params, tip_force_n, tip_couple_nm)
    return np.concatenate([state.x[-1], state.q[-1, 2]])


@functools.lru_cache(maxsize=32)
def rest_state(params: CosseratParams = CosseratParams()) -> RodState:
    """The state every rollout starts from: settled under gravity, chambers at the valve floor."""
    state, _ = static_state(np.full(3, constants.P_MIN_BAR), params)
    return state


@functools.lru_cache(maxsize=32)
def _rollout_jit(params: CosseratParams):
    rod = _make_rod(params)
    with jax.enable_x64(True):
        rest = RodState(*(jnp.asarray(a, jnp.float64) for a in rest_state(params)))
    single = functools.partial(_rollout_single, rod, params.n_substeps, valve.ValveParams(), rest)
    return jax.jit(jax.vmap(single))


def rollout_fn(params: CosseratParams = CosseratParams()):
    """The pure rollout `fn(commands [T, 3] bar) -> poses [T, 6]` for one program.

    Jit and vmap it yourself; call it under `jax.enable_x64(True)` with float64 commands.
    """
    rod = _make_rod(params)
    rest = RodState(*(jnp.asarray(a) for a in rest_state(params)))
    return functools.partial(_rollout_single, rod, params.n_substeps, valve.ValveParams(), rest)


@functools.lru_cache(maxsize=8)
def _tip_each_step_fn(params: CosseratParams):
    rod = _make_rod(params)

    def run(rest, pressures):
        zero = jnp.zeros(3, pressures.dtype)

        def body(st, p):
            st = _step(rod, st, p, zero, zero, rod.trans_damp, rod.rot_damp)
            return st, st.x[-1]

        return jax.lax.scan(body, rest, pressures)[1]

    return jax.jit(run)


def tip_each_step(pressures_bar, params: CosseratParams = CosseratParams()) -> np.ndarray:
    """Tip node positions [N, 3] (m) after each physics step, from rest, under chamber pressures
    [N, 3] (bar) given per physics step (no valve: the caller shapes them), for step responses
    sampled finer than the control period."""
    rest = rest_state(params)
    with jax.enable_x64(True):
        tips = _tip_each_step_fn(params)(
            RodState(*(jnp.asarray(a, jnp.float64) for a in rest)),
            jnp.asarray(pressures_bar, jnp.float64),
        )
        return np.asarray(tips)


def rollout(pressures_bar, params: CosseratParams = CosseratParams()) -> np.ndarray:
    """Simulates pressure programs from rest and returns the tip pose after each command.

    Each 10 Hz command saturates to the valve's range ([0.2, 3.5] bar) and is held for 0.1 s while
    the chamber pressures lag toward it (`mjx_arm.valve`); the pose is read at the end of each
    period. Batches run as one jitted, vmapped call (compiled once per params and shape).

    Args:
      pressures_bar: [T, 3] or [B, T, 3] chamber commands (bar).
      params: the rod; `CosseratParams.for_domain("constrained")` for the constrained domain.

    Returns:
      [T, 6] or [B, T, 6] float64 poses: tip position (m) then unit d3.
    """
    batched = checks.check_pressures(pressures_bar)
    fn = _rollout_jit(params)
    with jax.enable_x64(True):
        poses = np.asarray(fn(jnp.asarray(batched, jnp.float64)))
    return poses if np.ndim(pressures_bar) == 3 else poses[0]
