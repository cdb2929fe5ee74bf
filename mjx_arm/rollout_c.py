"""MuJoCo C rollouts of an arm: batched simulation states and chunked `mujoco.rollout` calls.

`Arm.rollout(backend="c")`, `Arm.rollout_with_qpos` and `Arm.rollout_c_from` call these; each
takes the `mjx_arm.arm.Arm` whose model, valve and controls it simulates.
"""

from __future__ import annotations

import operator
from typing import Any, NamedTuple

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from mjx_arm import constants, valve
from mjx_arm.constants import POSE_DIM
from mjx_arm.machine import usable_cores

#: An `mjx_arm.arm.Arm` (not imported: the arm imports this module).
Arm = Any

#: Trajectories per MuJoCo C `mujoco.rollout` call in `Arm.rollout`: each call holds every
#: substep's full state of a 5 s slice ([chunk, 1250, nstate] float64, with its copies and the
#: controls, 43 per substep with stretch softening). Measured peak for the committed arm:
#: 3.3-3.8 MB per trajectory, 0.84 GB for a chunk of 256 (`python -m bench.c_chunk_memory`,
#: bench/results/cpu/c_chunk_memory.md; 2.6 MB and 0.67 GB for the linear-law arm's 3
#: controls); 256 still fills every core.
C_CHUNK = 256
#: Control periods simulated per `mujoco.rollout` call (50 = 5 s): bounds the substep states held.
CHUNK_PERIODS = 50


class SimState(NamedTuple):
    """Batched MuJoCo C simulation states between control periods."""

    physics: np.ndarray
    """[B, nstate] MuJoCo full-physics states (`mjSTATE_FULLPHYSICS`: time, qpos, qvel, ...)."""
    pressure_bar: np.ndarray
    """[B, 3] chamber pressures (bar), which the valves move on from."""
    diverged: np.ndarray | None = None
    """[B] bool: the trajectory diverged on its way to this state. MuJoCo C resets a diverged
    state to the model's reference pose, so `physics` alone cannot tell; `Arm.rollout_c_from`
    reports every later period of such a trajectory as not ok. None (a state built by hand)
    means none diverged."""

    def take(self, rows) -> SimState:
        """The states of the given batch rows (an index array or a slice)."""
        diverged = None if self.diverged is None else self.diverged[rows]
        return SimState(self.physics[rows], self.pressure_bar[rows], diverged)


class SimulationDivergedError(RuntimeError):
    """A rollout produced a non-finite or exploding state."""

    def __init__(self, message: str, trajectories: np.ndarray, first_step: np.ndarray):
        super().__init__(message)
        self.trajectories = trajectories
        self.first_step = first_step


def raise_if_diverged(ok: np.ndarray) -> None:
    """ok: [B, T] flags."""
    bad = ~ok[:, -1]
    if bad.any():
        trajectories = np.flatnonzero(bad)
        first_step = np.array([np.argmin(ok[b]) for b in trajectories])
        raise SimulationDivergedError(
            f"simulation diverged (non-finite or exploding state) in {len(trajectories)}"
            f" trajectory(ies): {trajectories[:10].tolist()}, first at control step(s)"
            f" {first_step[:10].tolist()}. Lower the timestep or raise Domain.inertia_scale.",
            trajectories,
            first_step,
        )


def check_chunk(chunk) -> int:
    """`chunk` as an int, checked before any work.

    Raises:
      TypeError: not a whole number (a float such as 2.5, a string, None, a bool).
      ValueError: < 1.
    """
    if isinstance(chunk, bool | np.bool_):
        raise TypeError(f"chunk must be an int >= 1 (trajectories per call), got {chunk!r}")
    try:
        chunk = operator.index(chunk)
    except TypeError:
        raise TypeError(
            f"chunk must be an int >= 1 (trajectories per call), got {chunk!r}"
            f" of type {type(chunk).__name__}"
        ) from None
    if chunk < 1:
        raise ValueError(f"chunk must be an int >= 1 (trajectories per call), got {chunk}")
    return chunk


def check_state(start, what: str = "start") -> SimState:
    """`start` checked as a `SimState` (`Arm.rest_state`, or an end state of `rollout_c_from`).

    Raises:
      TypeError: anything else, e.g. a tuple or a bare array.
      ValueError: fields of mismatched shapes.
    """
    if not isinstance(start, SimState):
        raise TypeError(
            f"{what} must be a mjx_arm.SimState (Arm.rest_state(B), or the end state an earlier"
            f" Arm.rollout_c_from returned), got {type(start).__name__}"
        )
    physics, pressure = np.asarray(start.physics), np.asarray(start.pressure_bar)
    if physics.ndim != 2 or pressure.shape != (physics.shape[0], 3):
        raise ValueError(
            f"{what}: SimState needs physics [B, nstate] and pressure_bar [B, 3], got"
            f" {physics.shape} and {pressure.shape}"
        )
    return start


def rest_state(arm: Arm, batch: int) -> SimState:
    """`Arm.rest_state`: `arm`'s rest state, `batch` times, none diverged."""
    data = mujoco.MjData(arm.mj_model)
    data.qpos[:], data.qvel[:] = arm.rest_qpos, arm.rest_qvel
    data.act[:] = 0.0
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    physics = np.zeros(mujoco.mj_stateSize(arm.mj_model, spec))
    mujoco.mj_getState(arm.mj_model, data, physics, spec)
    return SimState(
        physics=np.tile(physics, (batch, 1)),
        pressure_bar=np.full((batch, 3), arm.valve.p_min_bar),
        diverged=np.zeros(batch, dtype=bool),
    )


def make_pool(n_batch: int, chunk: int) -> mj_rollout.Rollout:
    """A thread pool for MuJoCo C rollouts of `n_batch` trajectories, `chunk` at a time."""
    return mj_rollout.Rollout(nthread=min(usable_cores(), n_batch, max(chunk, 1)))


def rollout_batch(
    arm: Arm,
    start: SimState,
    commands: np.ndarray,
    pool: mj_rollout.Rollout,
    with_qpos: bool,
    chunk: int,
):
    """`rollout_chunks` over the batch, `chunk` trajectories at a time.

    Trajectories are independent and MuJoCo C is deterministic per trajectory, so the
    results equal one call over the whole batch; only the peak memory differs.
    """
    chunk = check_chunk(chunk)
    n_batch = commands.shape[0]
    if n_batch <= chunk:
        return rollout_chunks(arm, start, commands, pool, with_qpos)
    parts = [
        rollout_chunks(arm, start.take(rows), commands[rows], pool, with_qpos)
        for rows in (slice(b, b + chunk) for b in range(0, n_batch, chunk))
    ]
    poses, ok, ends, qpos = zip(*parts, strict=True)
    end = SimState(*(np.concatenate(fields) for fields in zip(*ends, strict=True)))
    qpos = np.concatenate(qpos) if with_qpos else None
    return np.concatenate(poses), np.concatenate(ok), end, qpos


def rollout_chunks(
    arm: Arm,
    start: SimState,
    commands: np.ndarray,
    pool: mj_rollout.Rollout,
    with_qpos: bool,
    chunk_periods: int = CHUNK_PERIODS,
):
    """Saturated commands [B, T, 3] from `start` -> (poses, ok, end state, qpos or None).

    The batch goes to `pool` whole; `chunk_periods` bounds the substep states held.
    """
    m = arm.mj_model
    n_batch, n_periods, _ = commands.shape
    state = np.array(start.physics, dtype=np.float64)
    pressure = np.array(start.pressure_bar, dtype=np.float64)
    poses = np.zeros((n_batch, n_periods, POSE_DIM))
    ok = np.ones((n_batch, n_periods), dtype=bool)
    # A trajectory that diverged earlier (or starts non-finite) stays diverged: MuJoCo C would
    # reset it and carry on from the reference pose as if nothing had happened.
    ok[:, 0] = np.isfinite(state).all(-1)
    if start.diverged is not None:
        ok[:, 0] &= ~np.asarray(start.diverged, dtype=bool)
    qpos = np.zeros((n_batch, n_periods, m.nq)) if with_qpos else None
    datas = [mujoco.MjData(m) for _ in range(max(pool.nthread, 1))]
    sensor_pos = tip_pose_sensor_adr(m)
    for begin in range(0, n_periods, chunk_periods):
        stop = min(begin + chunk_periods, n_periods)
        ctrl = chunk_controls(pressure, commands[:, begin:stop], arm, m.nu)
        pressure = ctrl[:, -1, arm.actuator_ids]
        out_state, sensordata = pool.rollout(
            m,
            datas,
            state,
            ctrl,
            nstep=ctrl.shape[1],
            control_spec=mujoco.mjtState.mjSTATE_CTRL,
        )
        times = out_state[:, :, 0]
        expected = state[:, :1] + arm.timestep_s * np.arange(1, ctrl.shape[1] + 1)
        fine = np.isfinite(out_state).all(-1) & np.isclose(times, expected, atol=1e-6)
        ok[:, begin:stop] &= fine[:, arm.n_substeps - 1 :: arm.n_substeps]
        # Sensors see the state before each step's integration; so do these states.
        before = np.concatenate([state[:, None], out_state[:, :-1]], axis=1)
        before = before[:, arm.n_substeps - 1 :: arm.n_substeps]
        if sensor_pos is not None:
            sd = sensordata[:, arm.n_substeps - 1 :: arm.n_substeps]
            poses[:, begin:stop] = sd[..., sensor_pos : sensor_pos + POSE_DIM]
        else:
            poses[:, begin:stop] = poses_from_states(arm, before)
        if with_qpos:
            qpos[:, begin:stop] = before[..., 1 : 1 + m.nq]  # full state: time, qpos, ...
        state = out_state[:, -1].copy()
    # Once diverged, stay diverged (MuJoCo C resets the state after a bad step).
    ok = np.logical_and.accumulate(ok, axis=1)
    end = SimState(physics=state, pressure_bar=pressure, diverged=~ok[:, -1])
    return poses, ok, end, qpos


def poses_from_states(arm: Arm, states: np.ndarray) -> np.ndarray:
    """Poses [..., 6] of full-physics states [..., nstate], via forward kinematics."""
    m = arm.mj_model
    data = mujoco.MjData(m)
    flat = states.reshape(-1, states.shape[-1])
    out = np.zeros((flat.shape[0], POSE_DIM))
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    for i, s in enumerate(flat):
        mujoco.mj_setState(m, data, s, spec)
        mujoco.mj_kinematics(m, data)
        out[i, :3] = data.site_xpos[arm.tip_site_id]
        out[i, 3:] = data.site_xmat[arm.tip_site_id].reshape(3, 3)[:, 2]
    return out.reshape(states.shape[:-1] + (POSE_DIM,))


def tip_pose_sensor_adr(m: mujoco.MjModel) -> int | None:
    """Address in sensordata of the tip pose, if the model has framepos + framezaxis sensors of the
    tip site named tip_pos and tip_d3, adjacent; None otherwise (poses then come from states)."""
    try:
        pos, d3 = m.sensor("tip_pos"), m.sensor("tip_d3")
    except KeyError:
        return None
    adjacent = (
        pos.type[0] == mujoco.mjtSensor.mjSENS_FRAMEPOS
        and d3.type[0] == mujoco.mjtSensor.mjSENS_FRAMEZAXIS
        and d3.adr[0] == pos.adr[0] + 3
        and pos.objid[0] == m.site(constants.TIP_SITE).id
        and d3.objid[0] == pos.objid[0]
    )
    return int(pos.adr[0]) if adjacent else None


def chunk_controls(pressure, commands, arm: Arm, nu: int) -> np.ndarray:
    """Per-substep controls [B, periods * n_substeps, nu] for held commands [B, periods, 3]."""
    n_batch, periods, _ = commands.shape
    sub = np.zeros((n_batch, periods, arm.n_substeps, 3))
    p = np.asarray(pressure, dtype=np.float64)
    for k in range(periods):
        sub[:, k] = np.moveaxis(
            valve.substep_pressures(
                p, commands[:, k], arm.n_substeps, arm.timestep_s, arm.valve, xp=np
            ),
            0,
            1,
        )
        p = sub[:, k, -1]
    ctrl = arm.chamber_controls.numpy(sub.reshape(n_batch, -1, 3))
    assert ctrl.shape[-1] == nu
    return ctrl
