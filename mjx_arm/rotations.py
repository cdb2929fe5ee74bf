"""Rotation helpers in JAX: cross-product matrices, the SO(3) exponential and logarithm.

The reference rod (`mjx_arm.cosserat`) keeps each element's directors as a rotation matrix and
measures curvature as the logarithm of neighbouring frames' relative rotation, so these must be
exact at any angle below pi and safe (finite gradients) at zero.
"""

from __future__ import annotations

import jax.numpy as jnp


def hat(v: jnp.ndarray) -> jnp.ndarray:
    """[..., 3] -> [..., 3, 3] cross-product matrices."""
    zero = jnp.zeros_like(v[..., 0])
    return jnp.stack(
        [
            jnp.stack([zero, -v[..., 2], v[..., 1]], -1),
            jnp.stack([v[..., 2], zero, -v[..., 0]], -1),
            jnp.stack([-v[..., 1], v[..., 0], zero], -1),
        ],
        -2,
    )


def exp_so3(theta: jnp.ndarray) -> jnp.ndarray:
    """Rotation vectors [..., 3] -> rotation matrices exp(hat(theta)) [..., 3, 3] (Rodrigues)."""
    angle = jnp.linalg.norm(theta, axis=-1)
    small = angle < 1e-8
    safe = jnp.where(small, 1.0, angle)
    a = jnp.where(small, 1.0 - angle**2 / 6.0, jnp.sin(safe) / safe)
    b = jnp.where(small, 0.5 - angle**2 / 24.0, 2.0 * (jnp.sin(0.5 * safe) / safe) ** 2)
    k = hat(theta)
    eye = jnp.eye(3, dtype=theta.dtype)
    return eye + a[..., None, None] * k + b[..., None, None] * (k @ k)


def log_so3(rot: jnp.ndarray) -> jnp.ndarray:
    """Rotation matrices [..., 3, 3] (angle < pi) -> rotation vectors [..., 3]."""
    skew = 0.5 * jnp.stack(
        [
            rot[..., 2, 1] - rot[..., 1, 2],
            rot[..., 0, 2] - rot[..., 2, 0],
            rot[..., 1, 0] - rot[..., 0, 1],
        ],
        -1,
    )
    sin_angle = jnp.linalg.norm(skew, axis=-1)
    cos_angle = 0.5 * (jnp.trace(rot, axis1=-2, axis2=-1) - 1.0)
    angle = jnp.arctan2(sin_angle, cos_angle)
    small = sin_angle < 1e-12
    factor = jnp.where(small, 1.0, angle / jnp.where(small, 1.0, sin_angle))
    return factor[..., None] * skew


def orthonormalise(q: jnp.ndarray) -> jnp.ndarray:
    """One Newton-Schulz step toward the nearest rotation; removes rounding drift."""
    return 1.5 * q - 0.5 * q @ jnp.swapaxes(q, -1, -2) @ q
