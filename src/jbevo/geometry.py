"""Geometry helpers: angle wrapping (more SO(3)/SE(2)/SE(3) helpers land with the models).

Units are radians; wrapped angles lie in [-pi, pi).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float


def wrap_angle(angle: Float[Array, "..."]) -> Float[Array, "..."]:
    """Wrap angles to [-pi, pi). Differentiable (derivative 1 almost everywhere).

    Written with ``floor`` and multiplies rather than ``mod``: XLA treats ``remainder`` as an
    expensive op that it will not duplicate into several fused consumers, which splits filter
    steps into many small kernels.
    """
    angle = jnp.asarray(angle)
    two_pi = 2 * jnp.pi
    return angle - two_pi * jnp.floor((angle + jnp.pi) * (1 / two_pi))


def se2_compose(pose: Float[Array, "... 3"], increment: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Apply a body-frame increment (dx, dy, dyaw) to a world pose (x, y, yaw).

    ``(dx, dy)`` is expressed in the body frame of ``pose`` (x forward, y left); the result's
    yaw is wrapped to [-pi, pi).
    """
    x, y, yaw = pose[..., 0], pose[..., 1], pose[..., 2]
    dx, dy, dyaw = increment[..., 0], increment[..., 1], increment[..., 2]
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    return jnp.stack([x + c * dx - s * dy, y + s * dx + c * dy, wrap_angle(yaw + dyaw)], axis=-1)


def se2_between(pose_a: Float[Array, "... 3"], pose_b: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """The body-frame increment that carries ``pose_a`` to ``pose_b`` (inverse of :func:`se2_compose`)."""
    ddx, ddy = pose_b[..., 0] - pose_a[..., 0], pose_b[..., 1] - pose_a[..., 1]
    c, s = jnp.cos(pose_a[..., 2]), jnp.sin(pose_a[..., 2])
    return jnp.stack([c * ddx + s * ddy, -s * ddx + c * ddy, wrap_angle(pose_b[..., 2] - pose_a[..., 2])], axis=-1)
