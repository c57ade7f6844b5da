"""SE(2): planar poses ``(x, y, yaw)`` in a z-up world frame and body-frame increments
``(dx, dy, dyaw)`` (x forward, y left; yaw wrapped to [-pi, pi)).

Example::

    >>> import jax.numpy as jnp
    >>> pose = se2_compose(jnp.array([0.0, 0.0, jnp.pi / 2]), jnp.array([1.0, 0.0, 0.0]))
    >>> [round(float(v), 6) + 0.0 for v in pose]
    [0.0, 1.0, 1.570796]
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.sincos import sincos


def se2_compose(pose: Float[Array, "... 3"], increment: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Apply a body-frame increment (dx, dy, dyaw) to a world pose (x, y, yaw).

    ``(dx, dy)`` is expressed in the body frame of ``pose`` (x forward, y left); the result's
    yaw is wrapped to [-pi, pi).
    """
    x, y, yaw = pose[..., 0], pose[..., 1], pose[..., 2]
    dx, dy, dyaw = increment[..., 0], increment[..., 1], increment[..., 2]
    s, c = sincos(yaw)
    return jnp.stack([x + c * dx - s * dy, y + s * dx + c * dy, wrap_angle(yaw + dyaw)], axis=-1)


def se2_between(pose_a: Float[Array, "... 3"], pose_b: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """The body-frame increment that carries ``pose_a`` to ``pose_b`` (inverse of :func:`se2_compose`)."""
    ddx, ddy = pose_b[..., 0] - pose_a[..., 0], pose_b[..., 1] - pose_a[..., 1]
    s, c = sincos(pose_a[..., 2])
    return jnp.stack([c * ddx + s * ddy, -s * ddx + c * ddy, wrap_angle(pose_b[..., 2] - pose_a[..., 2])], axis=-1)


__all__ = ["se2_between", "se2_compose"]
