"""Load an arm model, put it in a domain, and roll out pressure programs in MJX or MuJoCo C.

A pressure program is a sequence of chamber commands (bar) at 10 Hz. Each command is held for one
control period; the valves lag toward it (`mjx_arm.valve`); the pose is read once per period. Both
backends start from the same rest state and apply identical per-substep pressures.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import math
import operator
import os
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx
from mujoco import rollout as mj_rollout

from mjx_arm import checks, constants, domains, stretch, valve
from mjx_arm.checks import check_pressures, validate_model
from mjx_arm.constants import POSE_DIM
from mjx_arm.machine import usable_cores

#: A trajectory whose joint speed exceeds this (rad/s or m/s) is treated as diverged.
MAX_JOINT_SPEED = 1.0e3
#: jax_default_matmul_precision of every MJX physics step and of the MJX tracker
#: (`mjx_precision`; None: JAX's default, TensorFloat32 on NVIDIA GPUs, for benchmarks).
MJX_MATMUL_PRECISION = "highest"
#: Trajectories per MuJoCo C `mujoco.rollout` call in `Arm.rollout`: each call holds every
#: substep's full state of a 5 s slice ([chunk, 1250, nstate] float64, with its copies and the
#: controls, 43 per substep with stretch softening). Measured peak for the committed arm:
#: 3.3-3.8 MB per trajectory, 0.84 GB for a chunk of 256 (`python -m bench.c_chunk_memory`,
#: bench/results/cpu/c_chunk_memory.md; 2.6 MB and 0.67 GB for the linear-law arm's 3
#: controls); 256 still fills every core.
C_CHUNK = 256
#: A rest state still moving faster than this (rad/s or m/s) after `_settle`'s time is unsettled.
SETTLED_SPEED = 1.0e-3
#: MuJoCo warnings raised when it meets a non-finite or huge state and resets the data.
_INSTABILITY_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)


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


@dataclasses.dataclass
class Arm:
    """An arm model in one domain, with MJX and MuJoCo C rollouts.

    Attributes:
      mj_model: the MuJoCo model with the domain applied.
      domain: the domain.
      path: where the MJCF came from (None for a string).
      n_substeps: physics steps per 0.1 s control period.
      valve: the valve constants (read from the MJCF's <custom> numerics when present).
      rest_qpos, rest_qvel: the rest state every rollout starts from (chambers at p_min).
      inertia_scale: the numerical mass scaling the domain applied (1.0 when none).
      model_hash: sha256 of the MJCF text (16 hex digits); a planning copy's adds "-s<n>".
      mjcf_text: the MJCF text, which `planning_copy` compiles again.
    """

    mj_model: mujoco.MjModel
    domain: domains.Domain
    path: Path | None
    n_substeps: int
    valve: valve.ValveParams
    rest_qpos: np.ndarray
    rest_qvel: np.ndarray
    inertia_scale: float
    model_hash: str
    mjcf_text: str = dataclasses.field(default="", repr=False, compare=False)
    _copies: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)

    @functools.cached_property
    def mjx_model(self) -> mjx.Model:
        """The device model, on this process's first device (in a multi-process job the first
        global device may belong to another process). Sensors are off: MJX rollouts read the tip
        site directly."""
        m = copy.copy(self.mj_model)
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
        return mjx.put_model(m, device=jax.local_devices()[0])

    @property
    def timestep_s(self) -> float:
        return float(self.mj_model.opt.timestep)

    def planning_copy(self, substeps: int) -> Arm:
        """This arm with `substeps` physics steps per 0.1 s control period (a longer timestep),
        for planners only: `load(..., substeps=substeps)` of the same MJCF and domain, made once
        per step count and kept. 0 gives this arm itself (the settings' "no copy").

        The D_c media are so damped that the arm barely feels its timestep: at 5 steps of 20 ms
        the tip of a held 60 s program moves 0.01 mm from the 4 ms arm's on average (0.2 mm at
        most; `studies.planning_arm`). A receding-horizon planner or the oracle run five times
        fewer sequential steps in such a copy; their commands are scored in this arm. Another
        arm may feel its step more (the 3-segment test arm does): measure a copy first
        (`python -m studies.planning_arm --model ...`).

        Raises:
          ValueError: substeps < 1. SimulationDivergedError: as `load`, e.g. a domain with a
          fixed `inertia_scale` too small for the longer step.
        """
        if substeps == 0:
            return self
        if substeps not in self._copies:
            source = {"path": self.path} if self.path is not None else {"xml": self.mjcf_text}
            self._copies[substeps] = load(domain=self.domain, substeps=substeps, **source)
        return self._copies[substeps]

    @property
    def tip_site_id(self) -> int:
        return self.mj_model.site(constants.TIP_SITE).id

    @property
    def actuator_ids(self) -> np.ndarray:
        return np.array([self.mj_model.actuator(n).id for n in constants.CHAMBER_ACTUATORS])

    @functools.cached_property
    def chamber_controls(self) -> stretch.ChamberControls:
        """How chamber pressures become this model's controls (`mjx_arm.stretch`): the chamber
        actuators, plus the hinges' stretch softening where the model has it."""
        return stretch.from_model(self.mj_model)

    # ------------------------------------------------------------------ rollouts

    def rollout(self, pressures_bar, backend: str = "mjx", chunk: int = C_CHUNK) -> np.ndarray:
        """Simulates pressure programs from rest and returns the tip pose after each command.

        Commands outside [0, 3.5] bar saturate like a real valve; commands under the valve floor
        (0.2 bar) act as the floor. The pose of each period is the one MuJoCo computes in the
        forward pass of the period's last physics step, i.e. of the state one timestep (4 ms)
        before the period ends; both backends read it at that same instant.

        Args:
          pressures_bar: [T, 3] or [B, T, 3] chamber commands (bar) at 10 Hz.
          backend: "mjx" (JAX, jitted, vmapped over B) or "c" (MuJoCo C `mujoco.rollout`,
            multi-threaded over B).
          chunk: "c" only: trajectories per `mujoco.rollout` call, which bounds memory (see
            `C_CHUNK`); the poses do not depend on it. MJX runs the whole batch in one call
            (one compilation per batch size).

        Returns:
          [T, 6] or [B, T, 6] float64 poses: tip position (m) then unit d3.

        Raises:
          ValueError: bad shape (an empty batch included), non-finite pressures, or chunk < 1.
          SimulationDivergedError: a trajectory's state became non-finite or exploded.
        """
        batched = check_pressures(pressures_bar)
        if backend == "mjx":
            poses, ok = self._rollout_mjx(batched)
        elif backend == "c":
            poses, ok = self._rollout_c(batched, chunk=chunk)
        else:
            raise ValueError(f"backend must be 'mjx' or 'c', got {backend!r}")
        _raise_if_diverged(ok)
        return poses if np.ndim(pressures_bar) == 3 else poses[0]

    def rollout_with_qpos(
        self, pressures_bar, chunk: int = C_CHUNK
    ) -> tuple[np.ndarray, np.ndarray]:
        """`rollout` on MuJoCo C that also returns the joint positions, e.g. to render the arm.

        Returns:
          (qpos [T, nq] or [B, T, nq], poses [T, 6] or [B, T, 6]), both at the instant `rollout`
          reads the pose.
        """
        batched = check_pressures(pressures_bar)
        poses, ok, qpos = self._rollout_c(batched, with_qpos=True, chunk=chunk)
        _raise_if_diverged(ok)
        return (qpos, poses) if np.ndim(pressures_bar) == 3 else (qpos[0], poses[0])

    def rollout_fn(self):
        """The pure JAX rollout: `fn(mjx_model, commands [T, 3] bar) -> (poses [T, 6], ok [T])`.

        Jit it, vmap it over programs (or over model fields), differentiate through it. `ok[t]` is
        False once the state is non-finite or exploding; callers must check it.
        """
        return functools.partial(
            rollout_program,
            rest_qpos=jnp.asarray(self.rest_qpos),
            rest_qvel=jnp.asarray(self.rest_qvel),
            **self.period_kwargs(),
        )

    def period_fn(self, mjx_model: mjx.Model):
        """`control_period` bound to this arm: one control period of `mjx_model` (this arm's,
        or a traced copy inside a jitted function) from any state."""
        return control_period(mjx_model, **self.period_kwargs())

    def period_kwargs(self) -> dict:
        """The keyword arguments `control_period` and `rollout_program` take from this arm."""
        return {
            "tip_site": self.tip_site_id,
            "actuators": tuple(int(i) for i in self.actuator_ids),
            "n_substeps": self.n_substeps,
            "valve_params": self.valve,
            "controls": self.chamber_controls,
        }

    @functools.cached_property
    def _jit_batched(self):
        return jax.jit(jax.vmap(self.rollout_fn(), in_axes=(None, 0)))

    def _rollout_mjx(self, batched: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        commands = jnp.asarray(batched, dtype=jnp.float32)
        poses, ok = self._jit_batched(self.mjx_model, commands)
        return np.asarray(poses, dtype=np.float64), np.asarray(ok)

    def rest_state(self, batch: int = 1) -> SimState:
        """The rest state every rollout starts from, `batch` (an int >= 1) times (MuJoCo C
        layout), none diverged.

        Raises:
          ValueError: `batch` is not a whole number >= 1.
        """
        try:
            batch = operator.index(batch)
        except TypeError:
            raise ValueError(f"batch must be an int >= 1, got {batch!r}") from None
        if batch < 1:
            raise ValueError(f"batch must be an int >= 1, got {batch}")
        data = mujoco.MjData(self.mj_model)
        data.qpos[:], data.qvel[:] = self.rest_qpos, self.rest_qvel
        data.act[:] = 0.0
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        physics = np.zeros(mujoco.mj_stateSize(self.mj_model, spec))
        mujoco.mj_getState(self.mj_model, data, physics, spec)
        return SimState(
            physics=np.tile(physics, (batch, 1)),
            pressure_bar=np.full((batch, 3), self.valve.p_min_bar),
            diverged=np.zeros(batch, dtype=bool),
        )

    def rollout_c_from(
        self,
        start: SimState,
        pressures_bar,
        pool: mj_rollout.Rollout | None = None,
        chunk: int = C_CHUNK,
    ) -> tuple[np.ndarray, np.ndarray, SimState]:
        """MuJoCo C rollouts of programs from given states, e.g. to continue a rollout.

        Args:
          start: B states to start from (`rest_state`, or the end state of an earlier call).
          pressures_bar: [B, T, 3] chamber commands (bar) at 10 Hz; saturated like `rollout`'s.
          pool: a `mujoco.rollout.Rollout` to reuse across many short calls (one is made per
            call otherwise).
          chunk: trajectories per `mujoco.rollout` call (bounds memory, see `C_CHUNK`).

        Returns:
          (poses [B, T, 6] read as `rollout` reads them, ok [B, T] flags, the end states). Chained
          calls give the same poses as one call over the joined program, and the same flags: a
          trajectory that diverged in an earlier call (its end state's `diverged`), or starts
          from a non-finite state, is not ok at any period.
        """
        commands = valve.saturate(check_pressures(pressures_bar), self.valve, xp=np)
        if np.ndim(pressures_bar) != 3 or start.physics.shape[0] != commands.shape[0]:
            raise ValueError(
                f"need [B, T, 3] commands for {start.physics.shape[0]} states, got"
                f" {np.shape(pressures_bar)}"
            )
        if pool is None:
            with self._pool(commands.shape[0], chunk) as own_pool:
                poses, ok, end, _ = self._rollout_c_batch(start, commands, own_pool, False, chunk)
        else:
            poses, ok, end, _ = self._rollout_c_batch(start, commands, pool, False, chunk)
        return poses, ok, end

    @staticmethod
    def _pool(n_batch: int, chunk: int) -> mj_rollout.Rollout:
        """A thread pool for MuJoCo C rollouts of `n_batch` trajectories, `chunk` at a time."""
        return mj_rollout.Rollout(nthread=min(usable_cores(), n_batch, max(chunk, 1)))

    def _rollout_c(self, batched: np.ndarray, with_qpos: bool = False, chunk: int = C_CHUNK):
        commands = valve.saturate(batched, self.valve, xp=np)
        with self._pool(batched.shape[0], chunk) as pool:
            start = self.rest_state(batched.shape[0])
            poses, ok, _, qpos = self._rollout_c_batch(start, commands, pool, with_qpos, chunk)
        return (poses, ok, qpos) if with_qpos else (poses, ok)

    def _rollout_c_batch(
        self,
        start: SimState,
        commands: np.ndarray,
        pool: mj_rollout.Rollout,
        with_qpos: bool,
        chunk: int,
    ):
        """`_rollout_c_chunks` over the batch, `chunk` trajectories at a time.

        Trajectories are independent and MuJoCo C is deterministic per trajectory, so the
        results equal one call over the whole batch; only the peak memory differs.
        """
        if operator.index(chunk) < 1:
            raise ValueError(f"chunk must be >= 1, got {chunk}")
        n_batch = commands.shape[0]
        if n_batch <= chunk:
            return self._rollout_c_chunks(start, commands, pool, with_qpos)
        parts = [
            self._rollout_c_chunks(start.take(rows), commands[rows], pool, with_qpos)
            for rows in (slice(b, b + chunk) for b in range(0, n_batch, chunk))
        ]
        poses, ok, ends, qpos = zip(*parts, strict=True)
        end = SimState(*(np.concatenate(fields) for fields in zip(*ends, strict=True)))
        qpos = np.concatenate(qpos) if with_qpos else None
        return np.concatenate(poses), np.concatenate(ok), end, qpos

    def _rollout_c_chunks(
        self,
        start: SimState,
        commands: np.ndarray,
        pool: mj_rollout.Rollout,
        with_qpos: bool,
        chunk_periods: int = 50,
    ):
        """Saturated commands [B, T, 3] from `start` -> (poses, ok, end state, qpos or None).

        The batch goes to `pool` whole; chunk_periods (50 = 5 s) bounds the substep states held.
        """
        m = self.mj_model
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
        sensor_pos = _tip_pose_sensor_adr(m)
        for begin in range(0, n_periods, chunk_periods):
            stop = min(begin + chunk_periods, n_periods)
            ctrl = _chunk_controls(pressure, commands[:, begin:stop], self, m.nu)
            pressure = ctrl[:, -1, self.actuator_ids]
            out_state, sensordata = pool.rollout(
                m,
                datas,
                state,
                ctrl,
                nstep=ctrl.shape[1],
                control_spec=mujoco.mjtState.mjSTATE_CTRL,
            )
            times = out_state[:, :, 0]
            expected = state[:, :1] + self.timestep_s * np.arange(1, ctrl.shape[1] + 1)
            fine = np.isfinite(out_state).all(-1) & np.isclose(times, expected, atol=1e-6)
            ok[:, begin:stop] &= fine[:, self.n_substeps - 1 :: self.n_substeps]
            # Sensors see the state before each step's integration; so do these states.
            before = np.concatenate([state[:, None], out_state[:, :-1]], axis=1)
            before = before[:, self.n_substeps - 1 :: self.n_substeps]
            if sensor_pos is not None:
                sd = sensordata[:, self.n_substeps - 1 :: self.n_substeps]
                poses[:, begin:stop] = sd[..., sensor_pos : sensor_pos + POSE_DIM]
            else:
                poses[:, begin:stop] = self._poses_from_states(before)
            if with_qpos:
                qpos[:, begin:stop] = before[..., 1 : 1 + m.nq]  # full state: time, qpos, ...
            state = out_state[:, -1].copy()
        # Once diverged, stay diverged (MuJoCo C resets the state after a bad step).
        ok = np.logical_and.accumulate(ok, axis=1)
        end = SimState(physics=state, pressure_bar=pressure, diverged=~ok[:, -1])
        return poses, ok, end, qpos

    def _poses_from_states(self, states: np.ndarray) -> np.ndarray:
        """Poses [..., 6] of full-physics states [..., nstate], via forward kinematics."""
        m = self.mj_model
        data = mujoco.MjData(m)
        flat = states.reshape(-1, states.shape[-1])
        out = np.zeros((flat.shape[0], POSE_DIM))
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        for i, s in enumerate(flat):
            mujoco.mj_setState(m, data, s, spec)
            mujoco.mj_kinematics(m, data)
            out[i, :3] = data.site_xpos[self.tip_site_id]
            out[i, 3:] = data.site_xmat[self.tip_site_id].reshape(3, 3)[:, 2]
        return out.reshape(states.shape[:-1] + (POSE_DIM,))

    def rest_pose(self) -> np.ndarray:
        """The tip pose [6] at rest."""
        data = mujoco.MjData(self.mj_model)
        data.qpos[:] = self.rest_qpos
        mujoco.mj_kinematics(self.mj_model, data)
        return np.concatenate(
            [data.site_xpos[self.tip_site_id], data.site_xmat[self.tip_site_id].reshape(3, 3)[:, 2]]
        )


def _tip_pose_sensor_adr(m: mujoco.MjModel) -> int | None:
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


def _chunk_controls(pressure, commands, arm: Arm, nu: int) -> np.ndarray:
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


def rollout_program(
    mjx_model: mjx.Model,
    commands_bar: jnp.ndarray,
    *,
    tip_site: int,
    actuators: tuple[int, ...],
    n_substeps: int,
    valve_params: valve.ValveParams,
    rest_qpos: jnp.ndarray,
    rest_qvel: jnp.ndarray,
    warp_host_model: mujoco.MjModel | None = None,
    controls: stretch.ChamberControls | None = None,
    unroll: int = 1,
):
    """One program [T, 3] (bar) -> poses [T, 6] and ok flags [T], in pure JAX.

    `Arm.rollout_fn` binds the keyword arguments to one arm; call this directly to pass the rest
    state as data (e.g. one compiled function for several domains, as `mjx_arm.babble` does).

    Args:
      mjx_model: the MJX model (its domain already applied).
      commands_bar: [T, 3] valve commands (bar) at the control rate.
      tip_site, actuators: ids of the tip site and the three chamber actuators.
      n_substeps: physics steps per control period.
      valve_params: the valve model.
      rest_qpos, rest_qvel: the state every rollout starts from.
      controls: how pressures become the model's controls (`Arm.chamber_controls`, needed
        for a model with stretch softening); None sets only the chamber actuators.
      warp_host_model: for an MJX-Warp `mjx_model` (`put_model(..., impl="warp")`), the host
        `mujoco.MjModel` it came from: MJX-Warp's `make_data` refuses an `mjx.Model`. It only
        sizes the data (any domain of the arm will do); qpos and qvel become the rest state.
      unroll: physics steps per iteration of the loop over a period's steps (`control_period`).
    """
    dtype = commands_bar.dtype
    if warp_host_model is None:
        data = mjx.make_data(mjx_model)
    else:
        data = mjx.make_data(warp_host_model, impl="warp")
    data = data.replace(qpos=rest_qpos.astype(dtype), qvel=rest_qvel.astype(dtype))
    p0 = jnp.full((3,), valve_params.p_min_bar, dtype)
    commands = valve.saturate(commands_bar, valve_params)
    control_step = control_period(
        mjx_model,
        tip_site=tip_site,
        actuators=actuators,
        n_substeps=n_substeps,
        valve_params=valve_params,
        controls=controls,
        unroll=unroll,
    )
    _, (poses, ok) = jax.lax.scan(control_step, (data, p0, jnp.array(True)), commands)
    return poses, ok


def mjx_precision():
    """The matrix-product precision of MJX code, as a context: `MJX_MATMUL_PRECISION`, read
    here, when the code is traced, so that `bench.teacher` can set the module attribute."""
    return jax.default_matmul_precision(MJX_MATMUL_PRECISION)


def control_period(
    mjx_model: mjx.Model,
    *,
    tip_site: int,
    actuators: tuple[int, ...],
    n_substeps: int,
    valve_params: valve.ValveParams,
    controls: stretch.ChamberControls | None = None,
    unroll: int = 1,
):
    """One control period in pure JAX, as a `jax.lax.scan` body:
    `step((data, pressure [3] bar, healthy), command [3] bar) -> ((data, pressure, healthy),
    (pose [6], healthy))`, the command already saturated (`valve.saturate`).

    `rollout_program` scans it from rest; `tracking.mpc_mjx` scans it from any state, to plan
    from the middle of a program. The arguments are `rollout_program`'s; `unroll` physics steps
    run per iteration of the loop over the period's steps (the same numbers to float32 rounding;
    on a GPU, fewer and longer loop iterations: `bench.step_latency` measures what that changes).
    """
    actuators = jnp.asarray(actuators)
    timestep = mjx_model.opt.timestep

    def physics_step(data, pressure):
        # Full float32 matrix products: JAX's default lets XLA use TensorFloat32 (10-bit
        # mantissa) on NVIDIA GPUs, which made the k = 20 tracker 9.4x coarser than MuJoCo C on
        # an H100 at no gain in speed (bench/results/h100/teacher_k20.md). No effect on CPUs.
        with mjx_precision():
            if controls is None:
                data = data.replace(ctrl=data.ctrl.at[actuators].set(pressure))
            else:
                data = data.replace(ctrl=controls.jax(data.ctrl, pressure))
            return mjx.step(mjx_model, data), None

    def control_step(carry, command):
        data, pressure, healthy = carry
        pressures = valve.substep_pressures(pressure, command, n_substeps, timestep, valve_params)
        data, _ = jax.lax.scan(physics_step, data, pressures, unroll=unroll)
        pose = jnp.concatenate([data.site_xpos[tip_site], data.site_xmat[tip_site][:, 2]])
        finite = jnp.isfinite(data.qpos).all() & jnp.isfinite(data.qvel).all()
        healthy = healthy & finite & (jnp.abs(data.qvel).max() < MAX_JOINT_SPEED)
        return (data, pressures[-1], healthy), (pose, healthy)

    return control_step


def _raise_if_diverged(ok: np.ndarray) -> None:
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


def _settle(
    m: mujoco.MjModel, p_min: float, max_time_s: float = 60.0
) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Rest state: chambers at the valve floor, stepped until the arm stops moving.

    Returns:
      (rest qpos [nq], rest qvel [nv] (zeros), None), or a description of why the model has no
      rest in place of None: it diverged (MuJoCo met a bad state and reset the data, or a speed
      passed MAX_JOINT_SPEED), still moves faster than SETTLED_SPEED after `max_time_s`, or
      rests absurdly far (its tip moved more than twice the arm's length from the reference
      pose; an explicit drag instability can stretch a slide joint by kilometres while every
      number stays finite).
    """
    data = mujoco.MjData(m)
    data.ctrl[:] = stretch.from_model(m).numpy(np.full(3, p_min))
    steps_per_check = max(1, int(0.1 / m.opt.timestep))
    speed = 0.0
    for _ in range(int(max_time_s / 0.1)):
        mujoco.mj_step(m, data, nstep=steps_per_check)
        speed = float(np.abs(data.qvel).max(initial=0.0))
        reset = sum(data.warning[w].number for w in _INSTABILITY_WARNINGS)
        if reset or not np.isfinite(data.qpos).all() or not speed < MAX_JOINT_SPEED:
            return data.qpos.copy(), np.zeros(m.nv), "it diverged while settling"
        if speed < 1e-7:
            break
    if speed > SETTLED_SPEED:
        return (
            data.qpos.copy(),
            np.zeros(m.nv),
            f"it still moves at {speed:.3g} after {max_time_s} s",
        )
    # Tip displacement from the reference pose against the base-to-tip distance there.
    tip_body = m.site_bodyid[m.site(constants.TIP_SITE).id]
    reference = mujoco.MjData(m)
    mujoco.mj_kinematics(m, reference)
    site = m.site(constants.TIP_SITE).id
    length = np.linalg.norm(reference.site_xpos[site] - reference.xpos[m.body_rootid[tip_body]])
    mujoco.mj_kinematics(m, data)
    moved = float(np.linalg.norm(data.site_xpos[site] - reference.site_xpos[site]))
    if moved > 2.0 * length:
        return (
            data.qpos.copy(),
            np.zeros(m.nv),
            f"its tip rests {moved:.3g} m from the reference pose, over twice the arm's length"
            f" ({length:.3g} m)",
        )
    return data.qpos.copy(), np.zeros(m.nv), None


def load(
    path: str | os.PathLike | None = None,
    domain: str | domains.Domain = "source",
    *,
    xml: str | None = None,
    substeps: int | None = None,
) -> Arm:
    """Loads an arm model and puts it in a domain.

    Args:
      path: an MJCF file; None loads the committed `models/softarm.xml`.
      domain: "source", "constrained", "aged", or a `Domain`.
      xml: MJCF text instead of a path (give one or the other, not both).
      substeps: physics steps per 0.1 s control period, replacing the MJCF's timestep (None:
        the MJCF's own, 25 steps of 4 ms in `models/softarm.xml`); the domain's automatic
        inertia scale follows the new timestep. For planners (`Arm.planning_copy`), not for
        scoring: the arm's hash records it.

    Returns:
      An `Arm`, settled at rest.

    Raises:
      ValueError: both `path` and `xml` are given, or substeps < 1.
      FileNotFoundError: no file at `path`.
      ModelValidationError: the path is not an MJCF text file, the MJCF does not parse or
        compile, does not name the chamber actuators and the tip site, its options do not suit
        the API, or its <custom> valve numerics are unusable (tau <= 0, p_min < 0,
        p_min >= p_max, or p_max above the actuators' ctrlrange, which would clip it), or its
        timestep is not positive; a domain that takes the model's constrained medium
        (viscosity_scale=None) when the MJCF records none (pass a `Domain` with a scale).
      SimulationDivergedError: the arm has no stable rest in the domain (diverges, keeps moving,
        or rests absurdly far away), e.g. with a `Domain.inertia_scale` too small for the
        timestep; the message names the scale.
    """
    domain = domains.resolve(domain)
    if substeps is not None and (
        isinstance(substeps, bool) or int(substeps) != substeps or substeps < 1
    ):
        raise ValueError(f"substeps must be an integer >= 1, got {substeps!r}")
    mj_model, model_path, source, text = checks.read_model(path, xml)
    validate_model(mj_model, source)
    model_hash = hashlib.sha256(text.encode()).hexdigest()[:16]
    if substeps is not None:
        mj_model.opt.timestep = constants.CONTROL_PERIOD_S / int(substeps)
        model_hash += f"-s{int(substeps)}"
    solid = constants.SOLID_MODEL_PATH.is_file() and text == constants.SOLID_MODEL_PATH.read_text()
    inertia_scale = domains.apply(mj_model, domain, source, solid)
    mujoco.mj_setConst(mj_model, mujoco.MjData(mj_model))
    valve_params = checks.valve_params(mj_model, source)
    rest_qpos, rest_qvel, problem = _settle(mj_model, valve_params.p_min_bar)
    if problem is not None:
        how = "picked automatically" if domain.inertia_scale is None else "set by the domain"
        raise SimulationDivergedError(
            f"{source} has no stable rest in domain {domain.name!r}: {problem}. Explicit Euler"
            f" integration of its drag and springs is unstable at timestep"
            f" {mj_model.opt.timestep:g} s with Domain.inertia_scale={inertia_scale:g} ({how});"
            " leave Domain.inertia_scale=None (automatic) or raise it, or lower the timestep.",
            np.array([0]),
            np.array([0]),
        )
    return Arm(
        mj_model=mj_model,
        domain=domain,
        path=model_path,
        n_substeps=int(round(constants.CONTROL_PERIOD_S / mj_model.opt.timestep)),
        valve=valve_params,
        rest_qpos=rest_qpos,
        rest_qvel=rest_qvel,
        inertia_scale=inertia_scale,
        model_hash=model_hash,
        mjcf_text=text,
    )


def time_constant_63(times_s: np.ndarray, deflection: np.ndarray) -> float:
    """Time (s) at which a monotone-ish step response first reaches 63.2% of its final value."""
    final = deflection[-1]
    if final <= 0 or not math.isfinite(final):
        return float("nan")
    return float(times_s[np.argmax(deflection >= (1 - math.exp(-1)) * final)])
