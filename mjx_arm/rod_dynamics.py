"""The reference rod's dynamics in pure JAX: loads, one position-Verlet step, static settling and
one program's rollout (`mjx_arm.cosserat` describes the law; `mjx_arm.rod_params` the constants).

Every function takes the discretisation's constants (`RodConstants`) first, so callers bind them
with `functools.partial` and jit the rest. Arrays keep the dtype of the state they are given.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_arm import rotations, valve
from mjx_arm.rod_params import RodConstants, RodState


def dilatations(rod: RodConstants, edges: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Stretch e [n] of each element and e_v [n] of each Voronoi domain (-).

    The base half-domain (clamp to the first element's centre) takes the first element's e;
    each interior domain spans half of each neighbour, so e_v = (l_{j-1} + l_j) / (2 l0).
    """
    e = jnp.linalg.norm(edges, axis=-1) / rod.rest_length
    e_voronoi = jnp.concatenate([e[:1], 0.5 * (e[:-1] + e[1:])])
    return e, e_voronoi


def loads(
    rod: RodConstants,
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
        stretch, stretch_voronoi = dilatations(rod, edges)
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


def step(
    rod: RodConstants,
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
    forces, torques, stretch = loads(rod, x, q, pressure_bar, tip_force_n, tip_couple_nm)
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


def settle(
    rod: RodConstants,
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
        return step(
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


def rollout_single(
    rod: RodConstants,
    n_substeps: int,
    valve_params: valve.ValveParams,
    rest: RodState,
    commands_bar: jnp.ndarray,
    unroll: int = 1,
) -> jnp.ndarray:
    """Commands [T, 3] (bar) -> poses [T, 6], read at the end of each control period.

    `unroll`: physics steps per iteration of the compiled loop over a period's `n_substeps`
    (`jax.lax.scan`'s unroll; the same arithmetic, fewer loop iterations). On a GPU a rod step is
    a few small kernels, so the loop's own overhead per iteration dominates at small batches
    (`bench.rod_unroll` measures it).
    """
    commands = valve.saturate(commands_bar, valve_params)
    zero = jnp.zeros(3, commands.dtype)

    def physics_step(st, pressure):
        return step(rod, st, pressure, zero, zero, rod.trans_damp, rod.rot_damp), None

    def control_step(carry, command):
        st, pressure = carry
        pressures = valve.substep_pressures(pressure, command, n_substeps, rod.dt, valve_params)
        st, _ = jax.lax.scan(physics_step, st, pressures, unroll=unroll)
        st = st._replace(q=rotations.orthonormalise(st.q))
        return (st, pressures[-1]), tip_pose(st)

    p0 = jnp.full((3,), valve_params.p_min_bar, commands.dtype)
    _, poses = jax.lax.scan(control_step, (rest, p0), commands)
    return poses
