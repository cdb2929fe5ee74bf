"""Receding-horizon tracking in the MJX simulator: `tracking.mpc.track`'s one-step planner as one
jitted program, batched over thousands of programs on the GPU.

`tracking.mpc` plans in MuJoCo C, one source step at a time, on the host's cores. Its cost grows
with the number of programs; that of this version barely does: every program's candidates of a
step are one vmapped MJX rollout, and the source steps are a `jax.lax.scan`. Its wall time is
set by the latency of the 2 x iterations sequential k-period rollouts per source step, so it
pays where the programs are many (`bench.teacher` measures both on one host).

The planner is `mpc`'s with `horizon_steps = 1`: damped Gauss-Newton on the residuals
[100 (x_c - x_s), w (d3_c - d3_s)] of the pose after the held command, the Jacobian by forward
differences (backward near the upper valve limit), commands that the cost pushes beyond a limit
pinned there, and a line search over `mpc.LINE_STEPS` after clipping. One difference in the
bookkeeping, none in the result: the state after the applied command is the chosen line-search
candidate's end state (`mpc` rolls it out once more). MJX runs in float32, MuJoCo C in float64,
so the two trackers' commands differ by the rounding that the Jacobian sees
(tests/test_mpc_mjx.py bounds the difference of their tracking).

Media (issue 51): `track(..., media=(family, theta [S, P]))` plans program s in the medium
`family.model(theta[s])` (`mjx_arm.identify_family.DomainFamily`), from that medium's rest, in
the same jitted program: the planner is vmapped over the model as over the programs, as MuJoCo
Playground randomises domains. Without media every program shares `arm_c`'s model, as before.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mjx_arm import arm as mjx_arm_arm
from mjx_arm.arm import Arm
from mjx_arm.atomic import write_atomically
from mjx_arm.compile_notice import announce_compile
from tracking.mpc import LINE_STEPS, MpcConfig, _batched

#: Source steps per jitted call: each call's progress is shown, and the compile does not grow
#: with the program's length.
CHUNK_STEPS = 25


def _planner(arm_c: Arm, k: int, cfg: MpcConfig, family=None):
    """`advance(medium, carry, x0 [S, n, 3], target [S, n, 6]) -> (carry, applied [S, n, 3],
    cost [S, n], healthy [S])` over n source steps of S programs (jitted).

    medium: without `family`, the MJX model every program shares (`arm_c.mjx_model`); with a
    `DomainFamily`, its log-parameters theta [S, P], one medium per program. carry: (MJX data
    [S], valve pressure [S, 3] bar, healthy [S]); x0: where each step's plan starts (bar);
    target: the pose to reach after each held step (m, unit d3).
    """
    import jax
    import jax.numpy as jnp

    from mjx_arm.arm import control_period

    if family is None:
        period_of = arm_c.period_fn
    else:
        period_kwargs = arm_c.period_kwargs()

        def period_of(theta):
            """One control period in the medium of theta [P]: its model fields and its chamber
            controls (a softer arm's chambers stretch it further)."""
            controls = family.controls(theta)
            return control_period(family.model(theta), **(period_kwargs | {"controls": controls}))

    lo, hi = arm_c.valve.p_min_bar, arm_c.valve.p_max_bar
    w = cfg.orientation_weight_cm_per_rad
    line = jnp.asarray(LINE_STEPS, jnp.float32)
    eye = jnp.eye(3, dtype=jnp.float32)

    def residuals(poses, target):
        return jnp.concatenate(
            [100.0 * (poses[..., :3] - target[:3]), w * (poses[..., 3:] - target[3:])], -1
        )

    def plan_one(medium, carry, x0, target):
        """One source step of one program: the new carry, the applied command, its cost."""
        period = period_of(medium)

        def hold(command):
            """The end carry and pose of `command` held k periods from `carry`."""
            end, (poses, _) = jax.lax.scan(lambda c, _: period(c, command), carry, None, length=k)
            return end, poses[-1]

        def fd_candidates(x):
            """The plan and its forward-difference neighbours [4, 3], and their steps [3]."""
            fd = jnp.where(x + cfg.fd_step_bar > hi, -cfg.fd_step_bar, cfg.fd_step_bar)
            return x[None] + jnp.concatenate([jnp.zeros((1, 3), x.dtype), jnp.diag(fd)]), fd

        def line_candidates(x, fd, r):
            """The damped Gauss-Newton step's line-search candidates [4, 3] from the residuals
            r [4, 6] of `fd_candidates(x)`."""
            jac = (r[1:] - r[:1]) / fd[:, None]  # [3, 6]
            slope = jac @ r[0]
            pinned = ((x <= lo + 1e-6) & (slope > 0)) | ((x >= hi - 1e-6) & (slope < 0))
            jac = jnp.where(pinned[:, None], 0.0, jac)
            hess = jac @ jac.T
            scale = jnp.trace(hess) / 3.0
            delta = -jnp.linalg.solve(hess + (cfg.damping * scale + 1e-12) * eye, jac @ r[0])
            delta = jnp.where(pinned, 0.0, delta)
            return jnp.clip(x[None] + line[:, None] * delta[None], lo, hi)

        def phase(state, is_line):
            """One batch of 4 held rollouts: the Jacobian's (is_line False) or the line
            search's (True). Written as one scan body, so that the rollout compiles once."""
            x, trial, best_end, best_cost = state
            fd_cand, fd = fd_candidates(x)
            cand = jnp.where(is_line, trial, fd_cand)
            ends, poses = jax.vmap(hold)(cand)
            r = residuals(poses, target)
            cost = (r**2).sum(-1)
            best = jnp.argmin(cost)
            x = jnp.where(is_line, cand[best], x)
            trial = jnp.where(is_line, trial, line_candidates(x, fd, r))
            best_end = jax.tree.map(
                lambda old, new: jnp.where(is_line, new[best], old), best_end, ends
            )
            best_cost = jnp.where(is_line, cost[best], best_cost)
            return (x, trial, best_end, best_cost), None

        phases = jnp.tile(jnp.array([False, True]), cfg.iterations)
        start = (x0, jnp.zeros((4, 3), x0.dtype), carry, jnp.zeros((), x0.dtype))
        (x, _, new_carry, cost), _ = jax.lax.scan(phase, start, phases)
        return new_carry, x, cost

    medium_axis = None if family is None else 0  # shared model, or one medium per program

    def advance(medium, carry, x0, target):
        # The Gauss-Newton algebra at the physics' precision (full float32 by default).
        with mjx_arm_arm.mjx_precision():
            return _advance(medium, carry, x0, target)

    def _advance(medium, carry, x0, target):
        def step(carry, inputs):
            x0_n, target_n = inputs
            carry, applied, cost = jax.vmap(plan_one, in_axes=(medium_axis, 0, 0, 0))(
                medium, carry, x0_n, target_n
            )
            return carry, (applied, cost)

        inputs = (jnp.swapaxes(x0, 0, 1), jnp.swapaxes(target, 0, 1))
        carry, (applied, cost) = jax.lax.scan(step, carry, inputs)
        return carry, jnp.swapaxes(applied, 0, 1), jnp.swapaxes(cost, 0, 1), carry[2]

    return jax.jit(advance)


class TrackingStopped(RuntimeError):
    """`track` was asked to stop between chunks; its progress is in the resume file.

    Attributes: steps_done, n_steps (source steps planned so far, in all), path (the file).
    """

    def __init__(self, steps_done: int, n_steps: int, path: Path | None):
        self.steps_done, self.n_steps, self.path = steps_done, n_steps, path
        where = f"; {path} resumes it" if path is not None else " (no resume file)"
        super().__init__(f"tracking stopped after {steps_done} of {n_steps} source steps{where}")


def _fingerprint(
    arm_c: Arm, k: int, cfg: MpcConfig, init, target, chunk_steps: int, media=None
) -> str:
    """What a resume file must match: the arm and its medium, k, the settings, the inputs and the
    chunking (two domains share the MJCF's hash, so the domain is named on its own), and the
    per-program media (their family's fields and theta [S, P]) where given."""
    h = hashlib.sha256()
    precision = mjx_arm_arm.MJX_MATMUL_PRECISION
    domain = getattr(arm_c, "domain", None)
    h.update(repr((arm_c.model_hash, domain, k, cfg, chunk_steps, precision)).encode())
    arrays = [init, target]
    if media is not None:
        family, theta = media
        h.update(repr((family.fit, family.arm.domain)).encode())
        arrays.append(theta)
    for a in arrays:
        h.update(repr(a.shape).encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _save_progress(path: Path, key: str, chunk: int, carry, applied: list, cost: list) -> None:
    """Writes the carry's leaves and the plans so far to `path` (atomically)."""
    import jax

    leaves = {f"leaf{i}": np.asarray(x) for i, x in enumerate(jax.tree.leaves(carry))}
    write_atomically(
        path,
        lambda f: np.savez(
            f, key=key, chunk=chunk, applied=np.concatenate(applied, 1),
            cost=np.concatenate(cost, 1), **leaves,
        ),
    )  # fmt: skip


def _load_progress(path: Path, key: str, carry, log):
    """(chunk, carry, applied, cost) saved in `path` for the same `key`, else None."""
    import jax
    import jax.numpy as jnp

    if not path.exists():
        return None
    try:
        with np.load(path) as f:
            if str(f["key"]) != key:
                log(f"{path} was saved for other programs or settings; starting afresh")
                return None
            leaves, treedef = jax.tree.flatten(carry)
            saved = [f[f"leaf{i}"] for i in range(len(leaves))]
            if any(a.shape != b.shape for a, b in zip(saved, leaves, strict=True)):
                raise ValueError("leaf shapes differ")
            restored = jax.tree.unflatten(treedef, [jnp.asarray(a) for a in saved])
            return int(f["chunk"]), restored, [f["applied"]], [f["cost"]]
    except (OSError, ValueError, KeyError) as err:
        log(f"{path} is unreadable ({err}); starting afresh")
        return None


_PLANNERS: dict = {}


def _cached_planner(arm_c: Arm, k: int, cfg: MpcConfig, family=None):
    """`_planner`, built once per arm, k, settings and family in a process: a second call (the
    next shard of a teacher, or other media of the same family) reuses the compiled program
    instead of tracing it again."""
    # Traced with that precision.
    key = (id(arm_c), k, cfg, mjx_arm_arm.MJX_MATMUL_PRECISION, id(family))
    if key not in _PLANNERS:  # the arm and family are kept with it, so their ids are not reused
        _PLANNERS[key] = (arm_c, family, _planner(arm_c, k, cfg, family))
    return _PLANNERS[key][2]


def _rest_carry(arm_c: Arm, n_prog: int, media=None):
    """(MJX data, pressure, healthy) at rest for n_prog programs (float32): `arm_c`'s rest, or
    with media (family, theta [S, P]) each program's medium's (`DomainFamily.rest_state`)."""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    data = mjx.make_data(arm_c.mjx_model)
    if media is None:
        data = data.replace(
            qpos=jnp.asarray(arm_c.rest_qpos, jnp.float32),
            qvel=jnp.asarray(arm_c.rest_qvel, jnp.float32),
        )
        data = jax.tree.map(lambda leaf: jnp.broadcast_to(leaf, (n_prog,) + leaf.shape), data)
    else:
        family, theta = media
        qpos, qvel, _ = jax.vmap(family.rest_state)(jnp.asarray(theta, jnp.float32))
        data = jax.tree.map(lambda leaf: jnp.broadcast_to(leaf, (n_prog,) + leaf.shape), data)
        data = data.replace(qpos=qpos.astype(jnp.float32), qvel=qvel.astype(jnp.float32))
    pressure = jnp.full((n_prog, 3), arm_c.valve.p_min_bar, jnp.float32)
    return data, pressure, jnp.ones(n_prog, bool)


def _check_media(arm_c: Arm, media, n_prog: int):
    """`media` as (family, theta [S, P] float32), or None.

    Raises:
      ValueError: not a (DomainFamily, theta) pair, theta not [n_prog, len(family.fit)] and
        finite, or a family of another arm (MJCF, substeps or valve) than `arm_c`.
    """
    if media is None:
        return None
    try:
        family, theta = media
        fit, base_arm = family.fit, family.arm
    except (TypeError, ValueError, AttributeError):
        raise ValueError(
            "media must be (DomainFamily, theta [S, P]), e.g. (DomainFamily.of(arm_c), theta)"
        ) from None
    theta = np.asarray(theta, np.float64)
    if theta.shape != (n_prog, len(fit)) or not np.isfinite(theta).all():
        raise ValueError(
            f"media theta must be finite log-parameters [{n_prog}, {len(fit)}] (one row per"
            f" program, columns {fit}), got shape {theta.shape}"
        )
    same_arm = (
        base_arm.model_hash == arm_c.model_hash
        and base_arm.n_substeps == arm_c.n_substeps
        and base_arm.valve == arm_c.valve
    )
    if not same_arm:
        raise ValueError("the media's family is of another arm (MJCF, substeps or valve)")
    return family, theta.astype(np.float32)


def track(
    arm_c: Arm,
    target_poses: np.ndarray,
    k: int,
    init_program: np.ndarray,
    cfg: MpcConfig = MpcConfig(),
    progress: bool = False,
    chunk_steps: int = CHUNK_STEPS,
    resume: Path | None = None,
    should_stop: Callable[[], bool] | None = None,
    log=print,
    media=None,
) -> tuple[np.ndarray, dict]:
    """D_c commands that track target poses, planned in MJX (`tracking.mpc.track`'s API).

    Args:
      arm_c: the D_c arm.
      target_poses: [T, 6] or [S, T, 6] target poses (m, unit d3), one per source step.
      k: control periods each command is held.
      init_program: [T, 3] or [S, T, 3] commands (bar) each step's plan starts from.
      cfg: the tracker's settings; `horizon_steps` must be 1.
      progress: show a progress bar over source steps.
      chunk_steps: source steps per jitted call.
      resume: a file for the progress (the simulator states and the plans so far): read when it
        was saved for the same arm, k, settings, programs and chunking, so that a stopped run
        goes on where it stopped; written when `should_stop` stops the run; removed at the end.
        Programs of 60 s at k = 20 outlast a 10-minute call on one GPU.
      should_stop: called after each chunk; True stops the run (`TrackingStopped`).
      log: where notes on the resume file go.
      media: None (every program in `arm_c`'s medium), or (family, theta [S, P]): program s is
        planned in `family.model(theta[s])` from that medium's rest, where family is a
        `mjx_arm.identify_family.DomainFamily` of `arm_c`'s MJCF and theta its log-parameters
        (one row per program; with [T, ...] inputs S = 1). k is shared by all programs.

    Returns:
      (commands [T * k, 3] or [S, T * k, 3] (bar), each held k periods; info: "cost" [T] or
      [S, T] (squared residual of the applied step), "wall_s", "first_chunk_s" (the compile and
      the first chunk, in this call), "healthy" [S] (no program's simulation diverged),
      "resumed_steps" (source steps read from `resume`)).

    Raises:
      ValueError: `mpc.track`'s, a horizon other than 1, chunk_steps < 1, or media that are
        not a family of `arm_c`'s MJCF with theta [S, P] (`_check_media`).
      TrackingStopped: `should_stop` said so, after the progress was written to `resume`.
    """
    import jax.numpy as jnp

    single, targets, init = _batched(target_poses, init_program, k, cfg)
    if cfg.horizon_steps != 1:
        raise ValueError(f"the MJX tracker plans one step at a time, got {cfg.horizon_steps=}")
    if chunk_steps < 1:
        raise ValueError(f"chunk_steps must be >= 1, got {chunk_steps}")
    n_prog, n_steps, _ = targets.shape
    media = _check_media(arm_c, media, n_prog)
    family = None if media is None else media[0]
    init = np.clip(init, arm_c.valve.p_min_bar, arm_c.valve.p_max_bar)
    t0 = time.perf_counter()
    advance = _cached_planner(arm_c, k, cfg, family)
    carry = _rest_carry(arm_c, n_prog, media)
    medium = arm_c.mjx_model if media is None else jnp.asarray(media[1])
    n_chunks = -(-n_steps // chunk_steps)
    pad = n_chunks * chunk_steps - n_steps  # the last chunk is padded with its last step
    init_p = np.concatenate([init, np.repeat(init[:, -1:], pad, 1)], 1).astype(np.float32)
    target_p = np.concatenate([targets, np.repeat(targets[:, -1:], pad, 1)], 1).astype(np.float32)
    applied, cost, first = [], [], 0
    key = None
    if resume is not None:
        key = _fingerprint(arm_c, k, cfg, init_p, target_p, chunk_steps, media)
        saved = _load_progress(resume, key, carry, log)
        if saved is not None:
            first, carry, applied, cost = saved
            log(f"resuming from {resume}: {first * chunk_steps} of {n_steps} source steps done")
    resumed_steps = min(first * chunk_steps, n_steps)
    chunks = range(first, n_chunks)
    if progress:
        from tqdm import tqdm

        chunks = tqdm(chunks, desc="mpc (mjx)", unit=f"x{chunk_steps} steps", initial=first,
                      total=n_chunks)  # fmt: skip
    first_chunk_s = 0.0
    healthy = carry[2]
    announce_compile(
        (id(advance), n_prog, chunk_steps), n_prog, chunk_steps, what="the MJX tracker's chunk"
    )
    for c in chunks:
        part = slice(c * chunk_steps, (c + 1) * chunk_steps)
        carry, applied_c, cost_c, healthy = advance(
            medium, carry, jnp.asarray(init_p[:, part]), jnp.asarray(target_p[:, part])
        )
        applied.append(np.asarray(applied_c, np.float64))
        cost.append(np.asarray(cost_c, np.float64))
        if c == first:
            first_chunk_s = time.perf_counter() - t0
        if c + 1 < n_chunks and should_stop is not None and should_stop():
            if resume is not None:
                _save_progress(resume, key, c + 1, carry, applied, cost)
            raise TrackingStopped(min((c + 1) * chunk_steps, n_steps), n_steps, resume)
    if resume is not None:
        resume.unlink(missing_ok=True)
    applied = np.concatenate(applied, 1)[:, :n_steps]
    cost = np.concatenate(cost, 1)[:, :n_steps]
    commands = np.repeat(applied, k, axis=1)
    info = {
        "cost": cost[0] if single else cost,
        "wall_s": time.perf_counter() - t0,
        "first_chunk_s": first_chunk_s,
        "healthy": np.asarray(healthy),
        "resumed_steps": resumed_steps,
    }
    return (commands[0] if single else commands), info
