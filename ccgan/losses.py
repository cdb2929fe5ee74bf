"""Loss terms of the CCGAN-GP, as small pure functions (B = batch, T = time, D = features)."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp


def critic_loss(real_scores, fake_scores):
    """Wasserstein critic loss: E[C(fake)] - E[C(real)] (the critic minimises it).

    Args:
      real_scores: [B] critic scores of real samples.
      fake_scores: [B] critic scores of generated samples.

    Returns:
      scalar.
    """
    return jnp.mean(fake_scores) - jnp.mean(real_scores)


def generator_adversarial_loss(fake_scores):
    """Generator adversarial loss: -E[C(G(x))].

    Args:
      fake_scores: [B] critic scores of generated samples.

    Returns:
      scalar.
    """
    return -jnp.mean(fake_scores)


def gradient_penalty(critic_fn: Callable, real, fake, key):
    """WGAN-GP penalty E[(||grad_x C(x_hat)||_2 - 1)^2] on random interpolates.

    x_hat = eps * real + (1 - eps) * fake with one eps ~ U[0, 1] per sample. The gradient of the sum
    of scores equals the per-sample gradients because the critic treats samples independently.

    Args:
      critic_fn: x [B, T, D] -> scores [B].
      real: [B, T, D] real samples.
      fake: [B, T, D] generated samples (same shape).
      key: PRNG key for eps.

    Returns:
      scalar.
    """
    eps = jax.random.uniform(key, (real.shape[0],) + (1,) * (real.ndim - 1), real.dtype)
    x_hat = eps * real + (1.0 - eps) * fake
    grads = jax.grad(lambda x: jnp.sum(critic_fn(x)))(x_hat)
    norms = jnp.sqrt(jnp.sum(grads**2, axis=tuple(range(1, grads.ndim))) + 1e-12)
    return jnp.mean((norms - 1.0) ** 2)


def l1_loss(prediction, target):
    """Mean absolute error over every element: [B, T, D] x [B, T, D] -> scalar."""
    return jnp.mean(jnp.abs(prediction - target))


def cycle_loss(reconstructed, original):
    """Cycle-consistency (L1): mean |G_s(G_c(x)) - x| for one direction.

    Args:
      reconstructed: [B, T, 9] G_back(G_fwd(x)).
      original: [B, T, 9] x.

    Returns:
      scalar.
    """
    return l1_loss(reconstructed, original)


def identity_loss(mapped, original):
    """Identity (L1): mean |G_s(x_s) - x_s| for one generator fed its own domain.

    Args:
      mapped: [B, T, 9] G(x) with x already in G's output domain.
      original: [B, T, 9] x.

    Returns:
      scalar.
    """
    return l1_loss(mapped, original)


def feedback_loss(predicted_pose, target_pose):
    """Feedback MSE between F_c(G_c(pressure_s)) and the D_s target pose.

    Args:
      predicted_pose: [B, T, 6] poses F_c predicts for G_c's commands (normalised).
      target_pose: [B, T, 6] D_s poses the commands must reproduce (normalised).

    Returns:
      scalar.
    """
    return jnp.mean((predicted_pose - target_pose) ** 2)


def tracking_loss(poses_m, target_m, orientation_weight_cm_per_rad: float):
    """Per-program tracking loss [...]: mean over time of X_err_cm^2 + w^2 * 2 (1 - cos phi).

    Args:
      poses_m, target_m: [..., T, 6] poses (tip position in m, then the unit d3 director).
      orientation_weight_cm_per_rad: w, the cm of position error one rad of orientation error
        is worth (2 (1 - cos phi) ~ phi^2 for small phi).
    """
    x_cm2 = jnp.sum((100.0 * (poses_m[..., :3] - target_m[..., :3])) ** 2, axis=-1)
    phi2 = 2.0 * (1.0 - jnp.sum(poses_m[..., 3:] * target_m[..., 3:], axis=-1))
    return jnp.mean(x_cm2 + orientation_weight_cm_per_rad**2 * phi2, axis=-1)


def position_error_cm(pred_pose_m, target_pose_m):
    """Tip position error ||X_pred - X_target||_2 in cm: [..., 6] x [..., 6] (m) -> [...]."""
    return 100.0 * jnp.linalg.norm(pred_pose_m[..., :3] - target_pose_m[..., :3], axis=-1)


def orientation_error_rad(pred_pose, target_pose):
    """arccos of the cosine similarity of the d3 directors: [..., 6] x [..., 6] -> [...] (rad)."""
    a, b = pred_pose[..., 3:], target_pose[..., 3:]
    cos = jnp.sum(a * b, -1) / (jnp.linalg.norm(a, axis=-1) * jnp.linalg.norm(b, axis=-1) + 1e-12)
    return jnp.arccos(jnp.clip(cos, -1.0, 1.0))
