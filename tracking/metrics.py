"""Tracking-error metrics of the paper (X_err, phi_err), summaries, and the tracking loss.

The one copy of each: the evaluation scores with them (numpy, float64), the CCGAN-GP's k choice
and forward-model reports take them inside JAX (`ccgan.train`, `ccgan.forward`), and the oracle
and the fine-tune minimise `tracking_loss` through the MJX rollout. `position_error_cm`,
`orientation_error_rad` and `tracking_loss` therefore take numpy or JAX arrays: with JAX arrays
(or tracers, under jit and grad) they compute in jax.numpy at the inputs' precision, else in
numpy at float64.

Poses are [..., 6]: the tip position (m), then the d3 director (unit for the simulator's poses).
"""

from __future__ import annotations

import sys

import numpy as np

M_TO_CM = 100.0


def _numpy_of(*arrays):
    """(array module, arrays in it): jax.numpy when any input is a JAX array or tracer (JAX is
    then already imported), else numpy with the inputs as float64 arrays."""
    jax = sys.modules.get("jax")
    if jax is not None and any(isinstance(a, jax.Array) for a in arrays):
        import jax.numpy as jnp

        return jnp, [jnp.asarray(a) for a in arrays]
    return np, [np.asarray(a, dtype=np.float64) for a in arrays]


def position_error_cm(poses_pred, poses_target):
    """X_err = ||X_pred - X_target||_2 per sample, in cm.

    Args:
      poses_pred: [..., 6] or [..., 3] predicted poses (tip position in m first).
      poses_target: same shape, target poses.

    Returns:
      [...] position errors (cm).
    """
    xp, (pred, target) = _numpy_of(poses_pred, poses_target)
    return M_TO_CM * xp.linalg.norm(pred[..., :3] - target[..., :3], axis=-1)


def orientation_error_rad(poses_pred, poses_target):
    """phi_err = arccos(clip(cosine similarity of the d3 directors, -1, 1)) per sample, in rad.

    Args:
      poses_pred: [..., 6] predicted poses (d3 in the last three columns; need not be unit).
      poses_target: [..., 6] target poses.

    Returns:
      [...] angles between the directors (rad), in [0, pi].
    """
    xp, (pred, target) = _numpy_of(poses_pred, poses_target)
    a, b = pred[..., 3:6], target[..., 3:6]
    denom = xp.linalg.norm(a, axis=-1) * xp.linalg.norm(b, axis=-1)
    cos = xp.sum(a * b, axis=-1) / xp.maximum(denom, 1e-12)
    return xp.arccos(xp.clip(cos, -1.0, 1.0))


def tracking_loss(poses_m, target_m, orientation_weight_cm_per_rad: float):
    """Per-program tracking loss [...]: mean over time of X_err_cm^2 + w^2 * 2 (1 - cos phi).

    The objective of the oracle (`tracking.oracle`) and of the retired simulator fine-tune
    (`ccgan.finetune`, at commit 22875a2); `tracking.mpc.residuals` is its least-squares form.

    Args:
      poses_m, target_m: [..., T, 6] poses (tip position in m, then the unit d3 director).
      orientation_weight_cm_per_rad: w, the cm of position error one rad of orientation error
        is worth (2 (1 - cos phi) ~ phi^2 for small phi).

    Returns:
      [...] losses (cm^2).
    """
    xp, (poses, target) = _numpy_of(poses_m, target_m)
    x_cm2 = xp.sum((M_TO_CM * (poses[..., :3] - target[..., :3])) ** 2, axis=-1)
    phi2 = 2.0 * (1.0 - xp.sum(poses[..., 3:] * target[..., 3:], axis=-1))
    return xp.mean(x_cm2 + orientation_weight_cm_per_rad**2 * phi2, axis=-1)


def mean_std(values: np.ndarray) -> tuple[float, float]:
    """(mean, population std) of all values, as floats; (nan, nan) when empty."""
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(v.std())


def format_mean_std(values: np.ndarray, digits: int = 2) -> str:
    """'mean ± std' of all values, e.g. '1.23 ± 0.45'."""
    mean, std = mean_std(values)
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def tracking_errors(poses_pred: np.ndarray, poses_target: np.ndarray) -> dict[str, float]:
    """Summary of a tracked trajectory.

    Args:
      poses_pred, poses_target: [..., T, 6] poses (m, unit d3).

    Returns:
      {"x_err_cm_mean", "x_err_cm_std", "phi_err_rad_mean", "phi_err_rad_std"} over all samples.
    """
    x_mean, x_std = mean_std(position_error_cm(poses_pred, poses_target))
    phi_mean, phi_std = mean_std(orientation_error_rad(poses_pred, poses_target))
    return {
        "x_err_cm_mean": x_mean,
        "x_err_cm_std": x_std,
        "phi_err_rad_mean": phi_mean,
        "phi_err_rad_std": phi_std,
    }


def repetition_spread_cm(poses_reps: np.ndarray) -> dict[str, float]:
    """Spread of repeated trajectories (periodicity test).

    Args:
      poses_reps: [R, T, 6] the same program run R times from rest.

    Returns:
      {"spread_cm_mean": mean over t of the RMS distance of the R tips from their mean (cm),
       "spread_cm_max": largest distance of any repetition's tip from the mean (cm)}.
    """
    pos = np.asarray(poses_reps, dtype=np.float64)[..., :3]
    dev = M_TO_CM * np.linalg.norm(pos - pos.mean(axis=0, keepdims=True), axis=-1)  # [R, T]
    return {
        "spread_cm_mean": float(np.sqrt((dev**2).mean(axis=0)).mean()),
        "spread_cm_max": float(dev.max()),
    }


def tip_excursion_cm(poses_target: np.ndarray, rest_pose: np.ndarray) -> float:
    """How far a target path takes the tip: the RMS distance (cm) of its tip from the rest tip.

    The scale an X_err is read against: the same error is small on a path that sweeps
    centimetres and large on one that hardly leaves rest.

    Args:
      poses_target: [T, 6] target poses (tip position m, then d3).
      rest_pose: [6] the tip pose at rest.
    """
    offset = np.asarray(poses_target)[..., :3] - np.asarray(rest_pose)[:3]
    return float(np.sqrt(np.mean(np.sum(offset**2, axis=-1)))) * M_TO_CM
