"""Angles: radians, wrapped to [-pi, pi)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


def wrap_angle(angle: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
    """Wrap angles to [-pi, pi). Differentiable (derivative 1 almost everywhere).

    Written with ``floor`` and multiplies rather than ``mod``: XLA treats ``remainder`` as an
    expensive op that it will not duplicate into several fused consumers, which splits filter
    steps into many small kernels.
    """
    angle = jnp.asarray(angle)
    two_pi = 2 * jnp.pi
    return angle - two_pi * jnp.floor((angle + jnp.pi) * (1 / two_pi))


__all__ = ["wrap_angle"]
