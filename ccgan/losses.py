"""Loss terms of the CCGAN-GP, as small pure functions (B = batch, T = time, D = features).

The tracking metrics (X_err, phi_err) and the simulator tracking loss are not here but in
`tracking.metrics`, one copy for every layer.
"""

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
