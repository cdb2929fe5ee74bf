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

The rod lives in three modules: `mjx_arm.rod_params` (`CosseratParams`, `RodState`, the constants
of a discretisation), `mjx_arm.rod_dynamics` (loads, the step, settling, one program's rollout, in
pure JAX) and this one, the public float64 API that the fidelity report, the fit and the
PyElastica cross-check call (its names are re-exported here). `mjx_arm.rod_arm` runs the same
rollout as an arm with `Arm.rollout`'s interface, in the chain's domains.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from mjx_arm import checks, constants, valve
from mjx_arm.rod_dynamics import rollout_single, settle, step, tip_pose
from mjx_arm.rod_params import (
    DOMAIN_DAMPING_PER_S,
    LAWS,
    CosseratParams,
    RodState,
    make_rod,
    straight_state,
)

__all__ = [
    "DOMAIN_DAMPING_PER_S",
    "LAWS",
    "CosseratParams",
    "RodState",
    "rest_state",
    "rollout",
    "rollout_fn",
    "static_pose",
    "static_state",
    "straight_state",
    "tip_each_step",
    "tip_pose",
]


@functools.lru_cache(maxsize=32)
def _settle_fn(params: CosseratParams):
    rod = make_rod(params)
    n_chunk = 100
    max_chunks = max(1, math.ceil(params.settle_max_s / (n_chunk * rod.dt)))
    return jax.jit(
        functools.partial(
            settle, rod, n_chunk, max_chunks, params.settle_tol_mps, params.gyration_radius_m
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
    rod = make_rod(params)
    with jax.enable_x64(True):
        rest = RodState(*(jnp.asarray(a, jnp.float64) for a in rest_state(params)))
    single = functools.partial(rollout_single, rod, params.n_substeps, valve.ValveParams(), rest)
    return jax.jit(jax.vmap(single))


def rollout_fn(params: CosseratParams = CosseratParams()):
    """The pure rollout `fn(commands [T, 3] bar) -> poses [T, 6]` for one program.

    Jit and vmap it yourself; call it under `jax.enable_x64(True)` with float64 commands.
    """
    rod = make_rod(params)
    rest = RodState(*(jnp.asarray(a) for a in rest_state(params)))
    return functools.partial(rollout_single, rod, params.n_substeps, valve.ValveParams(), rest)


@functools.lru_cache(maxsize=8)
def _tip_each_step_fn(params: CosseratParams):
    rod = make_rod(params)

    def run(rest, pressures):
        zero = jnp.zeros(3, pressures.dtype)

        def body(st, p):
            st = step(rod, st, p, zero, zero, rod.trans_damp, rod.rot_damp)
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
