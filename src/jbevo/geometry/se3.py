"""SE(3) helpers for trajectories of ``(N, 4, 4)`` homogeneous poses ``T_world_frame`` (JAX), and
the lift of planar ``(x, y, yaw)`` rows to them (z = 0)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float


def general_inverse(pose: Float[Array, "... 4 4"]) -> Float[Array, "... 4 4"]:
    """``inv`` of any 4x4 (what the devkit uses: estimates need not be exactly orthonormal)."""
    return jnp.linalg.inv(pose)


def rotation_angle(pose: Float[Array, "... 4 4"]) -> Float[Array, "..."]:
    """The devkit's rotation error: ``acos(clip((trace(R) - 1) / 2, -1, 1))`` in radians."""
    d = 0.5 * (pose[..., 0, 0] + pose[..., 1, 1] + pose[..., 2, 2] - 1.0)
    return jnp.arccos(jnp.clip(d, -1.0, 1.0))


def translation_norm(pose: Float[Array, "... 4 4"]) -> Float[Array, "..."]:
    """The length of each pose's translation."""
    return jnp.linalg.norm(pose[..., :3, 3], axis=-1)


def relative_to_first(poses: Float[Array, "N 4 4"], first: int | Array) -> Float[Array, "N 4 4"]:
    """``inv(P[first]) P``: the trajectory expressed in the frame of its pose ``first``."""
    return general_inverse(poses[first]) @ poses


def planar_to_se3(xy_yaw: Float[Array, "N 3"]) -> Float[Array, "N 4 4"]:
    """Lift ``(x, y, yaw)`` rows (world z up) to 4x4 poses with ``z = 0``."""
    x, y, yaw = xy_yaw[..., 0], xy_yaw[..., 1], xy_yaw[..., 2]
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    zero, one = jnp.zeros_like(x), jnp.ones_like(x)
    rows = [
        [c, -s, zero, x],
        [s, c, zero, y],
        [zero, zero, one, zero],
        [zero, zero, zero, one],
    ]
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def se3_to_planar(poses: Float[Array, "N 4 4"]) -> Float[Array, "N 3"]:
    """``(x, y, yaw)`` of poses in a z-up world (yaw of the x axis about z)."""
    return jnp.stack([poses[..., 0, 3], poses[..., 1, 3], jnp.arctan2(poses[..., 1, 0], poses[..., 0, 0])], -1)


__all__ = ["general_inverse", "planar_to_se3", "relative_to_first", "rotation_angle", "se3_to_planar", "translation_norm"]
