"""Tracking-error metrics of the paper (Eqs. for X_err and phi_err) and summary helpers."""

from __future__ import annotations

import numpy as np

M_TO_CM = 100.0


def position_error_cm(poses_pred: np.ndarray, poses_target: np.ndarray) -> np.ndarray:
    """X_err = ||X_pred - X_target||_2 per sample, in cm.

    Args:
      poses_pred: [..., 6] or [..., 3] predicted poses (tip position in m first).
      poses_target: same shape, target poses.

    Returns:
      [...] position errors (cm).
    """
    pred = np.asarray(poses_pred, dtype=np.float64)[..., :3]
    target = np.asarray(poses_target, dtype=np.float64)[..., :3]
    return M_TO_CM * np.linalg.norm(pred - target, axis=-1)


def orientation_error_rad(poses_pred: np.ndarray, poses_target: np.ndarray) -> np.ndarray:
    """phi_err = arccos(clip(cosine similarity of the d3 directors, -1, 1)) per sample, in rad.

    Args:
      poses_pred: [..., 6] predicted poses (d3 in the last three columns; need not be unit).
      poses_target: [..., 6] target poses.

    Returns:
      [...] angles between the directors (rad), in [0, pi].
    """
    a = np.asarray(poses_pred, dtype=np.float64)[..., 3:6]
    b = np.asarray(poses_target, dtype=np.float64)[..., 3:6]
    denom = np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)
    cos = np.sum(a * b, axis=-1) / np.maximum(denom, 1e-12)
    return np.arccos(np.clip(cos, -1.0, 1.0))


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
