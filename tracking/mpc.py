"""Receding-horizon tracking in the D_c simulator: D_c commands chosen step by step in MuJoCo C.

A model-based reference beside the learned translators. At every source step n it holds the
simulator's state, plans the next `horizon_steps` held commands by damped Gauss-Newton on the
tracking residuals of those steps (finite-difference Jacobians, one batched `mujoco.rollout`
call per iteration, box limits by clipping and a short line search), applies the first command
for k control periods, and moves on. The residual is [100 (x_c - x_s), w (d3_c - d3_s)] per
step, so its squared norm is X_err_cm^2 + w^2 |d3_c - d3_s|^2 ~ the oracle's tracking loss
(`tracking.metrics.tracking_loss`, with phi_err^2 ~ |d3_c - d3_s|^2 for unit vectors).

Unlike a translator it needs the D_c simulator (or the real arm's model) at translation time;
unlike the oracle it never sees more than `horizon_steps` of the future and needs no gradients.
It gives the oracle a start (`tracking.oracle`, as `eval.pipeline` runs it) and the fine-tune a
teacher (`ccgan.distill`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import time
from pathlib import Path

import numpy as np
from mujoco import rollout as mj_rollout

from mjx_arm.arm import POSE_DIM, Arm, SimState
from mjx_arm.atomic import write_atomically
from mjx_arm.machine import usable_cores


@dataclasses.dataclass(frozen=True)
class MpcConfig:
    """Settings of the receding-horizon tracker."""

    horizon_steps: int = 1
    """Source steps planned at once (each held k control periods); only the first is applied."""
    iterations: int = 2
    """Gauss-Newton iterations per source step (the plan is warm-started from the last one)."""
    fd_step_bar: float = 1e-3
    """Finite-difference step of the Jacobian (bar)."""
    damping: float = 1e-3
    """Levenberg-Marquardt damping, relative to the mean diagonal of J^T J."""
    orientation_weight_cm_per_rad: float = 10.0
    """w: cm of position error one radian of orientation error costs (the oracle's default)."""


def residuals(poses: np.ndarray, target: np.ndarray, w: float) -> np.ndarray:
    """[..., 6] residuals of poses against targets (m, unit d3): 100 dx (cm) and w dd3."""
    return np.concatenate(
        [100.0 * (poses[..., :3] - target[..., :3]), w * (poses[..., 3:] - target[..., 3:])], -1
    )


def _batched(
    target_poses: np.ndarray, init_program: np.ndarray, k: int, cfg: MpcConfig
) -> tuple[bool, np.ndarray, np.ndarray]:
    """Checks the tracker's inputs and gives them a program axis.

    Returns:
      (single: whether one program [T, ...] was given, targets [S, T, 6] (m, unit d3), init
      [S, T, 3] (bar, not yet clipped to the valve range)).

    Raises:
      ValueError: shapes that do not match, non-finite values, or k, horizon_steps or
        iterations below 1.
    """
    single = np.ndim(target_poses) == 2
    targets = np.asarray(target_poses, np.float64)[None] if single else np.asarray(target_poses)
    init = np.asarray(init_program, np.float64)[None] if single else np.asarray(init_program)
    if targets.shape[:2] != init.shape[:2] or targets.shape[-1] != POSE_DIM:
        raise ValueError(f"targets {targets.shape} and init program {init.shape} do not match")
    if not (np.isfinite(targets).all() and np.isfinite(init).all()):
        raise ValueError("targets and init program must be finite")
    if k < 1 or cfg.horizon_steps < 1 or cfg.iterations < 1:
        raise ValueError("k, horizon_steps and iterations must be positive")
    return single, targets, init


def _block_poses(
    arm_c: Arm, pool: mj_rollout.Rollout, start: SimState, held: np.ndarray, k: int
) -> np.ndarray:
    """Poses [S, C, L, 6] (m, unit d3) at the end of each held block of candidate plans
    [S, C, L, 3] (bar, each command held k periods), every candidate of program s from the
    state `start` of program s ([S] states)."""
    n_prog, n_cand = held.shape[:2]
    rep = SimState(np.repeat(start.physics, n_cand, 0), np.repeat(start.pressure_bar, n_cand, 0))
    flat = np.repeat(held.reshape(n_prog * n_cand, -1, 3), k, axis=1)
    poses, _, _ = arm_c.rollout_c_from(rep, flat, pool)
    return poses[:, k - 1 :: k].reshape(n_prog, n_cand, -1, POSE_DIM)


#: Fractions of the Gauss-Newton step tried by the line search (0 keeps the current plan).
LINE_STEPS = np.array([1.0, 0.5, 0.25, 0.0])


def _gauss_newton(
    arm_c: Arm,
    pool: mj_rollout.Rollout,
    state: SimState,
    plan: np.ndarray,
    target: np.ndarray,
    k: int,
    cfg: MpcConfig,
) -> np.ndarray:
    """One damped Gauss-Newton iteration on the plans [S, H, 3] (bar) from `state`.

    The Jacobian of the residuals is taken by finite differences (one candidate per command,
    all in one rollout call); commands at a valve limit that the cost pushes beyond it stay
    there, and the step is the best of `LINE_STEPS` after clipping to the valve range.

    Args:
      target: [S, 1, H, 6] target poses (m, unit d3) of the planned steps.

    Returns:
      [S, H, 3] the new plans (bar).
    """
    lo, hi = arm_c.valve.p_min_bar, arm_c.valve.p_max_bar
    n_prog, horizon, _ = plan.shape
    n_var = horizon * 3
    x = plan.reshape(n_prog, n_var)
    # Forward differences, backward where the upper limit is near.
    step = np.where(x + cfg.fd_step_bar > hi, -cfg.fd_step_bar, cfg.fd_step_bar)
    cand = np.repeat(x[:, None], n_var + 1, 1)
    cand[:, 1:] += step[:, None, :] * np.eye(n_var)[None]
    poses = _block_poses(arm_c, pool, state, cand.reshape(n_prog, n_var + 1, horizon, 3), k)
    r = residuals(poses, target, cfg.orientation_weight_cm_per_rad)
    r = r.reshape(n_prog, n_var + 1, -1)
    jac = (r[:, 1:] - r[:, :1]) / step[:, :, None]  # [S, n_var, n_res]
    # Commands at a limit that the cost pushes beyond it stay there (active set).
    slope = (jac @ r[:, 0, :, None])[..., 0]
    pinned = ((x <= lo + 1e-9) & (slope > 0)) | ((x >= hi - 1e-9) & (slope < 0))
    jac = np.where(pinned[..., None], 0.0, jac)
    hess = jac @ jac.transpose(0, 2, 1)
    grad = jac @ r[:, 0, :, None]
    scale = np.trace(hess, axis1=1, axis2=2)[:, None, None] / n_var
    eye = np.eye(n_var)[None]
    delta = -np.linalg.solve(hess + (cfg.damping * scale + 1e-12) * eye, grad)[..., 0]
    delta = np.where(pinned, 0.0, delta)
    trial = np.clip(x[:, None] + LINE_STEPS[None, :, None] * delta[:, None], lo, hi)
    poses = _block_poses(arm_c, pool, state, trial.reshape(n_prog, len(LINE_STEPS), horizon, 3), k)
    r = residuals(poses, target, cfg.orientation_weight_cm_per_rad)
    best = np.argmin((r**2).sum((-1, -2)), axis=1)
    return trial[np.arange(n_prog), best].reshape(n_prog, horizon, 3)


def track(
    arm_c: Arm,
    target_poses: np.ndarray,
    k: int,
    init_program: np.ndarray,
    cfg: MpcConfig = MpcConfig(),
    progress: bool = False,
    result_path: str | os.PathLike | None = None,
) -> tuple[np.ndarray, dict]:
    """D_c commands that track target poses, one source step at a time.

    Args:
      arm_c: the D_c arm.
      target_poses: [T, 6] or [S, T, 6] target poses (m, unit d3), one per source step.
      k: control periods each command is held (the pose after the k-th is scored).
      init_program: [T, 3] or [S, T, 3] commands (bar) each newly planned step starts from,
        e.g. the source program itself (the stretch program's commands).
      cfg: the tracker's settings.
      progress: show a progress bar over source steps.
      result_path: optional .npz file. A result of the same tracking (arm, targets, start, k,
        settings) found there is returned without tracking again; otherwise the result is
        written there, so that a run stopped later (at a deadline) and started again does not
        redo minutes of tracking.

    Returns:
      (commands [T * k, 3] or [S, T * k, 3] (bar), each held k periods; info: "cost" [T] or
      [S, T] (squared residual of the applied step), "wall_s", "reused" (read from
      result_path)).
    """
    single, targets, init = _batched(target_poses, init_program, k, cfg)
    n_prog, n_steps, _ = targets.shape
    init = np.clip(init, arm_c.valve.p_min_bar, arm_c.valve.p_max_bar)
    t0 = time.perf_counter()
    path = None if result_path is None else Path(result_path)
    fingerprint = _fingerprint(arm_c, targets, init, k, cfg)
    stored = _stored_result(path, fingerprint)
    if stored is not None:
        commands, cost = stored
        info = {"cost": cost[0] if single else cost, "wall_s": 0.0, "reused": True}
        return (commands[0] if single else commands), info
    state = arm_c.rest_state(n_prog)
    applied = np.zeros((n_prog, n_steps, 3))
    cost = np.zeros((n_prog, n_steps))
    plan = init[:, : cfg.horizon_steps].copy()
    steps = range(n_steps)
    if progress:
        from tqdm import tqdm

        steps = tqdm(steps, desc="mpc", unit="step")
    with mj_rollout.Rollout(nthread=usable_cores()) as pool:
        for n in steps:
            horizon = plan.shape[1]
            target = targets[:, None, n : n + horizon]
            for _ in range(cfg.iterations):
                plan = _gauss_newton(arm_c, pool, state, plan, target, k, cfg)
            first = np.repeat(plan[:, :1], k, axis=1)
            poses, _, state = arm_c.rollout_c_from(state, first, pool)
            applied[:, n] = plan[:, 0]
            r = residuals(poses[:, -1], targets[:, n], cfg.orientation_weight_cm_per_rad)
            cost[:, n] = (r**2).sum(-1)
            # Shift the plan; a newly planned step starts from the init program's command.
            plan = plan[:, 1:]
            if n + horizon < n_steps:
                plan = np.concatenate([plan, init[:, n + horizon, None]], 1)
    commands = np.repeat(applied, k, axis=1)
    if path is not None:
        arrays = {"fingerprint": np.asarray(fingerprint), "commands": commands, "cost": cost}
        write_atomically(path, lambda f: np.savez(f, **arrays))
    wall_s = time.perf_counter() - t0
    info = {"cost": cost[0] if single else cost, "wall_s": wall_s, "reused": False}
    return (commands[0] if single else commands), info


#: Decimals (of m and bar) the tracker's cache fingerprint rounds its targets and start to.
FINGERPRINT_DECIMALS = 9


def _fingerprint(arm_c: Arm, targets, init, k: int, cfg: MpcConfig) -> str:
    """What the tracker's commands depend on: the arm and its medium (two domains share the
    MJCF's hash, so the domain is named on its own), the targets, the start, k, the settings."""
    digest = hashlib.sha256()
    for array in (targets, init):
        # Rounded to FINGERPRINT_DECIMALS: the same float64 targets computed on another machine
        # (the rod's D_s path on a GPU and on a CPU differ by ~1e-15 m) name the same tracking.
        rounded = np.round(np.asarray(array, np.float64), FINGERPRINT_DECIMALS) + 0.0
        digest.update(np.ascontiguousarray(rounded).tobytes())
    domain = getattr(arm_c, "domain", None)
    digest.update(repr((arm_c.model_hash, domain, k, dataclasses.asdict(cfg))).encode())
    return digest.hexdigest()[:16]


def _stored_result(path: Path | None, fingerprint: str):
    """(commands [S, T * k, 3], cost [S, T]) stored at path by the same tracking, else None (no
    file, another tracking's, or one that does not read)."""
    if path is None or not path.is_file():
        return None
    try:
        with np.load(path) as f:
            if str(f["fingerprint"]) != fingerprint:
                return None
            return f["commands"], f["cost"]
    except (OSError, ValueError, KeyError):
        return None
