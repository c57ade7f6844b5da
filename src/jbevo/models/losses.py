"""The training losses of BEVO (per-frame motion) and BEVO+ (filtered pose), robust (Huber) in
the planar error ``|d(x, y)|^2 + (yaw_weight * d yaw)^2``."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo.data.sequence import Sequence
from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.se2 import se2_between
from jbevo.models.bevo import BevoOutput
from jbevo.models.bevo_plus import LocalizationOutput


def planar_huber(err: Float[Array, "N 3"], yaw_weight: float, huber: float) -> Float[Array, " N"]:
    """Huber loss of planar errors ``(dx, dy, dyaw)``: with ``e = dx^2 + dy^2 + (yaw_weight *
    wrap(dyaw))^2`` (metres), ``e / 2`` below ``huber^2`` and ``huber (sqrt(e) - huber / 2)``
    above."""
    sq_err = err[:, 0] ** 2 + err[:, 1] ** 2 + (yaw_weight * wrap_angle(err[:, 2])) ** 2
    norm = jnp.sqrt(sq_err + 1e-12)
    return jnp.where(norm <= huber, 0.5 * sq_err, huber * (norm - 0.5 * huber))


def relative_motion(seq: Sequence) -> Float[Array, "T 3"]:
    """Ground-truth increments ``(dx, dy, dyaw)`` from frame t-1 to t (zero for frame 0)."""
    planar = seq.planar
    inc = se2_between(planar[:-1], planar[1:])
    return jnp.concatenate([jnp.zeros_like(inc[:1]), inc])


def motion_loss(
    output: BevoOutput, seq: Sequence, yaw_weight: float = 10.0, huber: float = 0.3, trajectory_weight: float = 0.0
) -> Float[Array, ""]:
    """Mean Huber loss of the per-frame motion error ``e = |d(x, y)|^2 + (yaw_weight * d yaw)^2``
    (metres; ``yaw_weight`` in metres per radian: at 10, a 0.1 deg yaw error weighs as 1.7 cm):
    ``e / 2`` below ``huber^2`` and linear in ``sqrt(e)`` above, so that a few gross registration
    failures do not drown the gradient of the many good frames. Plus ``trajectory_weight`` times
    the mean squared position error of the accumulated poses."""
    loss = jnp.mean(planar_huber(output.increments[1:] - relative_motion(seq)[1:], yaw_weight, huber))
    if trajectory_weight:
        loss = loss + trajectory_weight * jnp.mean(jnp.sum((output.poses[:, :2] - seq.planar[:, :2]) ** 2, -1))
    return loss


def localization_loss(
    output: LocalizationOutput, seq: Sequence, yaw_weight: float = 10.0, huber: float = 1.0
) -> Float[Array, ""]:
    """Mean Huber loss of the filtered pose error ``e = |d(x, y)|^2 + (yaw_weight * d yaw)^2``
    (metres; ``yaw_weight`` metres per radian), quadratic below ``huber`` metres and linear
    above, over all frames: the robot's location (and heading) as supervision."""
    return jnp.mean(planar_huber(output.poses - seq.planar, yaw_weight, huber))


__all__ = ["localization_loss", "motion_loss", "planar_huber", "relative_motion"]
