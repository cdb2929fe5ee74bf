"""A differentiable family of domains: (log viscosity scale, log stiffness scale) -> MJX model.

`mjx_arm.domains.apply` edits a compiled `mujoco.MjModel` in NumPy; system identification needs
the same edit inside JAX, so that gradients reach the parameters (as MuJoCo Playground's domain
randomisation replaces model fields under `jax.vmap`). `DomainFamily` holds the base arm's fields
with the domain's scales divided out and rebuilds, for any parameters, what `apply` and `load`
would give:

  * viscosity_scale: `opt.viscosity` (MuJoCo's inertia-box drag, linear in it);
  * stiffness_scale: `jnt_stiffness`, the stretch softening's gains
    (`actuator_gainprm[soften, 1]`) and, in the controls, `stretch_per_bar` over it
    (`mjx_arm.stretch`); the rest state;
  * both, through the automatic inertia scale: `body_mass`, `body_inertia`,
    `body_subtreemass` and `dof_armature` times it, `opt.gravity` over it.

The automatic inertia scale is max(1, drag term, spring term), each linear in its parameter
(`domains.apply`), so it is rebuilt exactly; a base domain with a fixed `inertia_scale` keeps
it. The rest state (chambers at the valve floor) hangs straight, so only the axial slide springs
carry load there and they are linear: rest qpos = qpos_spring + (base rest - qpos_spring) x
(base stiffness / stiffness) (to 5e-9 m against `rest.settle` at x0.5-x1.5; `check_rest`
checks a family at x0.7, as the gradient method does before it starts). Mass scale is not a
parameter: it changes gravity loads and the rest state in ways that formula does not hold for.

`tangent_chunks` and `Windows` give the rollouts' derivatives by the parameters in forward
mode, chunk by chunk, for `mjx_arm.identify`'s gradient method.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from mjx_arm import arm as arm_lib
from mjx_arm import compile_notice, constants, domains, valve

#: The Domain fields a family can fit, in the order of its parameter vector.
FITTABLE = ("viscosity_scale", "stiffness_scale")
#: Largest rest-state difference (qpos units: m or rad) between the formula and `rest.settle`.
REST_TOLERANCE = 1e-6


def resolved_viscosity_scale(arm: arm_lib.Arm) -> float:
    """The arm's `Domain.viscosity_scale`, its None ("the model's constrained medium") resolved."""
    if arm.domain.viscosity_scale is not None:
        return float(arm.domain.viscosity_scale)
    solid = (
        constants.SOLID_MODEL_PATH.is_file()
        and arm.mjcf_text == constants.SOLID_MODEL_PATH.read_text()
    )
    return domains.model_viscosity_scale(arm.mj_model, solid=solid)


def base_values(arm: arm_lib.Arm) -> dict[str, float]:
    """The arm's value of every fittable field: {"viscosity_scale": v, "stiffness_scale": s}."""
    return {
        "viscosity_scale": resolved_viscosity_scale(arm),
        "stiffness_scale": float(arm.domain.stiffness_scale),
    }


@dataclasses.dataclass(frozen=True, eq=False)
class DomainFamily:
    """The domains of one arm that differ from its own in the fitted fields only.

    Build it with `DomainFamily.of(arm, fit)`; `model`, `rest_qpos` and `rollout` are pure JAX
    functions of the log-parameters `theta` [P] (P = len(fit), natural logs of the Domain fields
    in `fit`'s order), so they jit, vmap and differentiate.
    """

    arm: arm_lib.Arm
    """The base arm (its MJCF, substeps and other Domain fields are kept)."""
    fit: tuple[str, ...]
    """The fitted Domain fields, a subsequence of `FITTABLE`."""
    base: dict
    """The base arm's value of every fittable field."""
    fields: dict
    """NumPy model fields with the base's scales divided out (see the module doc)."""
    base_model: mjx.Model
    """The base arm's `mjx_model`, put on the device here, outside any trace."""

    @classmethod
    def of(cls, arm: arm_lib.Arm, fit=FITTABLE) -> DomainFamily:
        """The family of `arm` over the fields `fit`.

        Raises:
          ValueError: `fit` is empty, repeats a field or names one not in `FITTABLE`.
        """
        fit = check_fit(fit)
        base = base_values(arm)
        m = arm.mj_model
        scale = float(arm.inertia_scale)
        viscosity_unit = float(m.opt.viscosity) / base["viscosity_scale"]
        stiffness = base["stiffness_scale"]
        controls = arm.chamber_controls
        soften = np.asarray(controls.soften_ids, dtype=np.int64)
        auto = arm.domain.inertia_scale is None
        # Per unit of each parameter, the two terms of the automatic inertia scale at scale 1.
        drag = m.opt.timestep * domains.drag_rate_per_s(m) * scale / domains.DRAG_STEP_MARGIN
        spring = (
            m.opt.timestep * domains.spring_frequency_rad_per_s(m) / domains.SPRING_STEP_MARGIN
        ) ** 2 * scale
        fields = {
            "viscosity_unit": viscosity_unit,
            "drag_per_viscosity": drag / float(m.opt.viscosity) if auto else 0.0,
            "spring_per_stiffness": spring / stiffness if auto else 0.0,
            "fixed_inertia_scale": 1.0 if auto else scale,
            "body_mass": m.body_mass / scale,
            "body_inertia": m.body_inertia / scale,
            "body_subtreemass": m.body_subtreemass / scale,
            "dof_armature": m.dof_armature / scale,
            "gravity": m.opt.gravity * scale,
            "jnt_stiffness": m.jnt_stiffness / stiffness,
            "soften_ids": soften,
            "soften_gain": m.actuator_gainprm[soften, 1] / stiffness,
            "stretch_per_bar": controls.stretch_per_bar * stiffness,
            "qpos_spring": m.qpos_spring.copy(),
            "rest_sag": (arm.rest_qpos - m.qpos_spring) * stiffness,
        }
        family = cls(arm=arm, fit=fit, base=base, fields=fields, base_model=arm.mjx_model)
        rebuilt = float(family.inertia_scale(family.base_theta()))
        if not math.isclose(rebuilt, scale, rel_tol=1e-5):  # float32
            raise AssertionError(f"inertia scale rebuilt as {rebuilt}, the arm has {scale}")
        return family

    # ------------------------------------------------------------------ parameters

    def base_theta(self) -> np.ndarray:
        """The base arm's log-parameters [P]."""
        return np.log([self.base[name] for name in self.fit])

    def values(self, theta) -> dict[str, jnp.ndarray]:
        """Every fittable field's value for log-parameters `theta` [P] (the base's where not
        fitted)."""
        values = {name: jnp.asarray(self.base[name]) for name in FITTABLE}
        for i, name in enumerate(self.fit):
            values[name] = jnp.exp(theta[i])
        return values

    def domain(self, theta, name: str = "identified") -> domains.Domain:
        """The `Domain` of log-parameters `theta` [P]: the base arm's with the fitted fields
        replaced (its inertia scale setting kept, so `load(domain=...)` builds this model)."""
        values = {k: float(v) for k, v in self.values(np.asarray(theta, np.float64)).items()}
        return dataclasses.replace(self.arm.domain, name=name, **values)

    def inertia_scale(self, theta) -> jnp.ndarray:
        """The inertia scale `domains.apply` picks for `theta` (or the base's fixed one)."""
        f, v = self.fields, self.values(theta)
        if not f["drag_per_viscosity"]:
            return jnp.asarray(f["fixed_inertia_scale"])
        drag = f["drag_per_viscosity"] * f["viscosity_unit"] * v["viscosity_scale"]
        spring = f["spring_per_stiffness"] * v["stiffness_scale"]
        return jnp.maximum(1.0, jnp.maximum(drag, spring))

    # ------------------------------------------------------------------ the model in JAX

    def model(self, theta, base_model: mjx.Model | None = None) -> mjx.Model:
        """The MJX model of log-parameters `theta` [P]: `load(domain=self.domain(theta))`'s
        fields, built in JAX from `base_model` (default: the base arm's `mjx_model`)."""
        m = self.base_model if base_model is None else base_model
        f, v = self.fields, self.values(theta)
        dtype = m.body_mass.dtype
        scale = self.inertia_scale(theta).astype(dtype)
        stiffness = v["stiffness_scale"].astype(dtype)
        gainprm = m.actuator_gainprm
        if f["soften_ids"].size:
            gainprm = gainprm.at[f["soften_ids"], 1].set(
                jnp.asarray(f["soften_gain"], dtype) * stiffness
            )
        opt = m.opt.replace(
            viscosity=(f["viscosity_unit"] * v["viscosity_scale"]).astype(dtype),
            gravity=jnp.asarray(f["gravity"], dtype) / scale,
        )
        return m.replace(
            opt=opt,
            body_mass=jnp.asarray(f["body_mass"], dtype) * scale,
            body_inertia=jnp.asarray(f["body_inertia"], dtype) * scale,
            body_subtreemass=jnp.asarray(f["body_subtreemass"], dtype) * scale,
            dof_armature=jnp.asarray(f["dof_armature"], dtype) * scale,
            jnt_stiffness=jnp.asarray(f["jnt_stiffness"], dtype) * stiffness,
            actuator_gainprm=gainprm,
        )

    def rest_qpos(self, theta) -> jnp.ndarray:
        """The rest state's qpos [nq] for `theta` (the module doc gives the formula)."""
        f, v = self.fields, self.values(theta)
        return jnp.asarray(f["qpos_spring"]) + jnp.asarray(f["rest_sag"]) / v["stiffness_scale"]

    def controls(self, theta):
        """The arm's chamber controls for `theta`: a softer arm's chambers stretch it further
        (`stretch_per_bar` over the stiffness scale, as `domains.apply` edits the numeric)."""
        controls = self.arm.chamber_controls
        if not controls.softens:
            return controls
        stiffness = self.values(theta)["stiffness_scale"]
        return controls._replace(stretch_per_bar=self.fields["stretch_per_bar"] / stiffness)

    def rest_state(self, theta) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
        """(qpos [nq], qvel [nv], chamber pressure [3] bar) at rest for `theta`: the state
        `rollout_chunk` carries (the arm has no actuator activations)."""
        p_min = jnp.full((3,), self.arm.valve.p_min_bar, jnp.float32)
        return self.rest_qpos(theta), jnp.zeros(self.arm.mj_model.nv), p_min

    def rollout_chunk(self, theta, state, commands_bar, base_model: mjx.Model | None = None):
        """Continues a rollout by C control periods in the domain of `theta` [P].

        Args:
          theta: [P] log-parameters.
          state: (qpos [nq], qvel [nv], pressure [3] bar), e.g. `rest_state(theta)` or the
            state an earlier chunk returned.
          commands_bar: [C, 3] valve commands (bar) at 10 Hz, saturated here.

        Returns:
          (state after the chunk, (poses [C, 6]: tip m then unit d3, ok [C])). Chunks chained
          from `rest_state` give `Arm.rollout_fn`'s poses (the physics needs only qpos, qvel and
          the pressures: no activations, contacts or warm starts).
        """
        model = self.model(theta, base_model)
        qpos, qvel, pressure = state
        dtype = commands_bar.dtype
        data = mjx.make_data(model).replace(qpos=qpos.astype(dtype), qvel=qvel.astype(dtype))
        kwargs = self.arm.period_kwargs() | {"controls": self.controls(theta)}
        step = arm_lib.control_period(model, **kwargs)
        commands = valve.saturate(commands_bar, self.arm.valve)
        (data, pressure, _), (poses, ok) = jax.lax.scan(
            step, (data, pressure.astype(dtype), jnp.array(True)), commands
        )
        return (data.qpos, data.qvel, pressure), (poses, ok)

    def rollout(self, theta, commands_bar, base_model: mjx.Model | None = None):
        """One program from rest in the domain of `theta` [P]: commands [T, 3] (bar) ->
        (poses [T, 6]: tip m then unit d3, ok [T]), as `Arm.rollout_fn` of that domain's arm."""
        _, out = self.rollout_chunk(theta, self.rest_state(theta), commands_bar, base_model)
        return out

    def check_rest(self, factor: float = 0.7) -> float:
        """Largest |formula - settled| rest qpos difference at stiffness x`factor` (m or rad),
        settled by `mjx_arm.load`.

        Raises:
          ValueError: it exceeds `REST_TOLERANCE` (the arm's rest does not hang straight, so
            the family cannot fit its stiffness).
        """
        theta = np.log(
            [self.base[n] * (factor if n == "stiffness_scale" else 1.0) for n in FITTABLE]
        )
        family = dataclasses.replace(self, fit=FITTABLE)
        source = (
            {"path": self.arm.path} if self.arm.path is not None else {"xml": self.arm.mjcf_text}
        )
        settled = arm_lib.load(
            domain=family.domain(theta), substeps=self.arm.n_substeps, **source
        ).rest_qpos
        gap = float(np.abs(np.asarray(family.rest_qpos(theta)) - settled).max())
        if gap > REST_TOLERANCE:
            raise ValueError(
                f"the arm's rest moves {gap:.3g} from the linear formula at stiffness x{factor}:"
                " its rest does not hang straight, so its stiffness cannot be identified here"
            )
        return gap


def check_fit(fit) -> tuple[str, ...]:
    """`fit` as a tuple of fittable field names, in `FITTABLE`'s order.

    Raises:
      ValueError: empty, repeated, or a name not in `FITTABLE`.
    """
    if isinstance(fit, str):
        fit = (fit,)
    fit = tuple(fit)
    unknown = [name for name in fit if name not in FITTABLE]
    if not fit or unknown or len(set(fit)) != len(fit):
        raise ValueError(
            f"fit must name one or more distinct fields of {FITTABLE}, got {fit!r}"
            + (f" (unknown: {unknown})" if unknown else "")
        )
    return tuple(name for name in FITTABLE if name in fit)


def tangent_chunks(family: DomainFamily, chunk: int):
    """Forward-mode derivatives of rollouts, one compiled chunk of `chunk` periods at a time.

    With P = 1-2 parameters, forward mode (one primal and P tangents, as `jax.jacfwd`) keeps no
    tape, so a 60 s program needs no more memory than one chunk, and it compiles in a fraction
    of reverse mode's time (45 s against 245 s for the 3-segment arm on the 2-core CPU). The
    state and its tangents pass from chunk to chunk, so one compilation serves every window
    length that is a multiple of `chunk`.

    Returns:
      (start, step), both jitted and batched over B programs:
      `start(theta [P], batch) -> (state, tangents)`, the rest state and its derivative;
      `step(theta, state, tangents, commands [B, chunk, 3] bar) -> (state, tangents, poses
      [B, chunk, 6], dposes [B, P, chunk, 6], ok [B, chunk])`, dposes the derivative of the
      poses by each log-parameter (m or unit d3 per unit log).
    """
    n_params = len(family.fit)
    eye = jnp.eye(n_params)

    def start_one(theta):
        state = family.rest_state(theta)
        tangents = jax.vmap(lambda e: jax.jvp(family.rest_state, (theta,), (e,))[1])(eye)
        return state, tangents

    def step_one(theta, state, tangents, commands):
        def run(th, st):
            new_state, (poses, ok) = family.rollout_chunk(th, st, commands)
            return (new_state, poses), ok

        def directional(e, tangent):
            primal, dual, ok = jax.jvp(run, (theta, state), (e, tangent), has_aux=True)
            return primal, dual, ok

        primal, dual, ok = jax.vmap(directional)(eye, tangents)
        (new_state, poses) = jax.tree.map(lambda x: x[0], primal)
        dstate, dposes = dual
        return new_state, dstate, poses, dposes, ok[0]

    def start(theta, batch: int):
        state, tangents = start_one(theta)
        return jax.tree.map(lambda x: jnp.broadcast_to(x, (batch,) + x.shape), (state, tangents))

    step = jax.vmap(step_one, in_axes=(None, 0, 0, 0))
    return jax.jit(start, static_argnums=1), jax.jit(step)


class Windows:
    """Forward-mode rollouts of programs over prefixes of whole chunks, against target poses.

    Built from a family, programs [N, T, 3] (bar) and target poses [N, T, 6]; programs are
    padded to whole chunks by holding their last command, and the padding is masked out."""

    def __init__(self, family: DomainFamily, programs, targets, chunk: int):
        self.family, self.chunk = family, chunk
        n, t = programs.shape[:2]
        padded = -(-t // chunk) * chunk
        hold = np.repeat(programs[:, -1:], padded - t, axis=1)
        self.programs = np.concatenate([programs, hold], 1).astype(np.float32)
        self.targets = np.concatenate([targets, np.repeat(targets[:, -1:], padded - t, 1)], 1)
        self.mask = (np.arange(padded) < t).astype(np.float64)
        self.start, self.step = tangent_chunks(family, chunk)
        self.n, self.periods = n, padded

    def __call__(self, theta, periods: int):
        """(loss m^2, gradient [P], residuals [N, W, 3], jacobian [N, P, W, 3]) over the first
        `periods` (a multiple of the chunk) of every program; loss inf if a rollout diverged."""
        theta = jnp.asarray(theta, jnp.float32)
        compile_notice.announce_compile(
            ("identify", id(self.step), self.n, self.chunk),
            self.n,
            self.chunk,
            what="the identification's forward-mode MJX chunk",
        )
        state, tangents = self.start(theta, self.n)
        res, jac = [], []
        for c in range(0, periods, self.chunk):
            commands = jnp.asarray(self.programs[:, c : c + self.chunk])
            state, tangents, poses, dposes, ok = self.step(theta, state, tangents, commands)
            if not bool(np.all(ok)):
                return math.inf, None, None, None
            mask = self.mask[c : c + self.chunk, None]
            res.append(
                (np.asarray(poses, np.float64)[..., :3] - self.targets[:, c : c + self.chunk, :3])
                * mask
            )
            jac.append(np.asarray(dposes, np.float64)[..., :3] * mask)
        r, j = np.concatenate(res, 1), np.concatenate(jac, 2)
        count = self.n * self.mask[:periods].sum()
        loss = float(np.sum(r**2) / count)
        grad = 2.0 * np.einsum("ntc,nptc->p", r, j) / count
        return loss, grad, r, j
