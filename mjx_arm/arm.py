"""Load an arm model, put it in a domain, and roll out pressure programs in MJX or MuJoCo C.

A pressure program is a sequence of chamber commands (bar) at 10 Hz. Each command is held for one
control period; the valves lag toward it (`mjx_arm.valve`); the pose is read once per period. Both
backends start from the same rest state and apply identical per-substep pressures.

This module holds the `Arm`, `load` and the pure MJX rollout (`rollout_program`,
`control_period`); the MuJoCo C rollouts live in `mjx_arm.rollout_c`, the rest state in
`mjx_arm.rest`. Their public names are re-exported here, where callers have always found them.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import functools
import hashlib
import math
import operator
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx
from mujoco import rollout as mj_rollout

from mjx_arm import checks, compile_notice, constants, domains, rest, rollout_c, stretch, valve
from mjx_arm.checks import check_pressures, validate_model
from mjx_arm.constants import MAX_JOINT_SPEED, POSE_DIM  # noqa: F401  (re-exported)
from mjx_arm.rest import SETTLED_SPEED  # noqa: F401  (re-exported)
from mjx_arm.rollout_c import (  # noqa: F401  (re-exported)
    C_CHUNK,
    SimState,
    SimulationDivergedError,
    raise_if_diverged,
)

#: jax_default_matmul_precision of every MJX physics step and of the MJX tracker
#: (`mjx_precision`; None: the caller's, by default JAX's: TensorFloat32 on NVIDIA GPUs, for
#: benchmarks).
MJX_MATMUL_PRECISION = "highest"


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
          chunk: "c" only: trajectories per `mujoco.rollout` call (an int >= 1), which bounds
            memory (see `C_CHUNK`); the poses do not depend on it. MJX runs the whole batch in
            one call (one compilation per batch size, announced on stderr the first time:
            `mjx_arm.compile_notice`).

        Returns:
          [T, 6] or [B, T, 6] float64 poses: tip position (m) then unit d3.

        Raises:
          ValueError: bad shape (an empty batch included), non-finite pressures, chunk < 1, or
            an unknown backend.
          TypeError: pressures that are not real numbers (bools, strings), or a chunk that is
            not an int (2.5, '8', None).
          SimulationDivergedError: a trajectory's state became non-finite or exploded.
        """
        if backend not in ("mjx", "c"):
            raise ValueError(f"backend must be 'mjx' or 'c', got {backend!r}")
        chunk = rollout_c.check_chunk(chunk)
        batched = check_pressures(pressures_bar)
        if backend == "mjx":
            poses, ok = self._rollout_mjx(batched)
        elif backend == "c":
            poses, ok = self._rollout_c(batched, chunk=chunk)
        else:
            raise ValueError(f"backend must be 'mjx' or 'c', got {backend!r}")
        raise_if_diverged(ok)
        return poses if np.ndim(pressures_bar) == 3 else poses[0]

    def rollout_with_qpos(
        self, pressures_bar, chunk: int = C_CHUNK
    ) -> tuple[np.ndarray, np.ndarray]:
        """`rollout` on MuJoCo C that also returns the joint positions, e.g. to render the arm.

        Returns:
          (qpos [T, nq] or [B, T, nq], poses [T, 6] or [B, T, 6]), both at the instant `rollout`
          reads the pose.
        """
        chunk = rollout_c.check_chunk(chunk)
        batched = check_pressures(pressures_bar)
        poses, ok, qpos = self._rollout_c(batched, with_qpos=True, chunk=chunk)
        raise_if_diverged(ok)
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
        jitted = self._jit_batched
        compile_notice.announce_compile((id(jitted), commands.shape), *commands.shape[:2])
        poses, ok = jitted(self.mjx_model, commands)
        return np.asarray(poses, dtype=np.float64), np.asarray(ok)

    def rest_state(self, batch: int = 1) -> SimState:
        """The rest state every rollout starts from, `batch` (an int >= 1) times (MuJoCo C
        layout), none diverged.

        Raises:
          ValueError: `batch` is not a whole number >= 1.
        """
        if isinstance(batch, bool | np.bool_):
            raise ValueError(f"batch must be an int >= 1, got {batch!r}")
        try:
            batch = operator.index(batch)
        except TypeError:
            raise ValueError(f"batch must be an int >= 1, got {batch!r}") from None
        if batch < 1:
            raise ValueError(f"batch must be an int >= 1, got {batch}")
        return rollout_c.rest_state(self, batch)

    def rollout_c_from(
        self,
        start: SimState,
        pressures_bar,
        pool: mj_rollout.Rollout | None = None,
        chunk: int = C_CHUNK,
    ) -> tuple[np.ndarray, np.ndarray, SimState]:
        """MuJoCo C rollouts of programs from given states, e.g. to continue a rollout.

        Args:
          start: B states to start from, a `SimState` (`rest_state`, or the end state of an
            earlier call).
          pressures_bar: [B, T, 3] chamber commands (bar) at 10 Hz; saturated like `rollout`'s.
          pool: a `mujoco.rollout.Rollout` to reuse across many short calls (one is made per
            call otherwise).
          chunk: trajectories per `mujoco.rollout` call (bounds memory, see `C_CHUNK`).

        Returns:
          (poses [B, T, 6] read as `rollout` reads them, ok [B, T] flags, the end states). Chained
          calls give the same poses as one call over the joined program, and the same flags: a
          trajectory that diverged in an earlier call (its end state's `diverged`), or starts
          from a non-finite state, is not ok at any period.

        Raises:
          TypeError: `start` is not a `SimState`, or `chunk` not an int. ValueError: bad
          pressures (as `rollout`), or their batch differs from the states'.
        """
        start = rollout_c.check_state(start)
        chunk = rollout_c.check_chunk(chunk)
        commands = valve.saturate(check_pressures(pressures_bar), self.valve, xp=np)
        if np.ndim(pressures_bar) != 3 or start.physics.shape[0] != commands.shape[0]:
            raise ValueError(
                f"need [B, T, 3] commands for {start.physics.shape[0]} states, got"
                f" {np.shape(pressures_bar)}"
            )
        if pool is None:
            with rollout_c.make_pool(commands.shape[0], chunk) as own_pool:
                poses, ok, end, _ = rollout_c.rollout_batch(
                    self, start, commands, own_pool, False, chunk
                )
        else:
            poses, ok, end, _ = rollout_c.rollout_batch(self, start, commands, pool, False, chunk)
        return poses, ok, end

    def _rollout_c(self, batched: np.ndarray, with_qpos: bool = False, chunk: int = C_CHUNK):
        commands = valve.saturate(batched, self.valve, xp=np)
        with rollout_c.make_pool(batched.shape[0], chunk) as pool:
            start = self.rest_state(batched.shape[0])
            poses, ok, _, qpos = rollout_c.rollout_batch(
                self, start, commands, pool, with_qpos, chunk
            )
        return (poses, ok, qpos) if with_qpos else (poses, ok)

    def rest_pose(self) -> np.ndarray:
        """The tip pose [6] at rest."""
        data = mujoco.MjData(self.mj_model)
        data.qpos[:] = self.rest_qpos
        mujoco.mj_kinematics(self.mj_model, data)
        return np.concatenate(
            [data.site_xpos[self.tip_site_id], data.site_xmat[self.tip_site_id].reshape(3, 3)[:, 2]]
        )


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
    here, when the code is traced, so that `bench.teacher` can set the module attribute. None
    sets nothing: the caller's precision holds (JAX's default when the caller sets none);
    `jax.default_matmul_precision(None)` would instead reset a caller's setting."""
    if MJX_MATMUL_PRECISION is None:
        return contextlib.nullcontext()
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
    rest_qpos, rest_qvel, problem = rest.settle(mj_model, valve_params.p_min_bar)
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
