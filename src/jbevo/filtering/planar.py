"""The planar pose filter model: state ``(x, y, yaw)`` in a z-up world frame, control a body-frame
increment ``(dx, dy, dyaw)`` (odometry), measurement a pose fix ``(x, y, yaw)``.

Yaw is wrapped to [-pi, pi) in every difference, sum and mean (:mod:`jbevo.filtering.unscented`).
BEVO+ localizes with it; it fits any planar dead reckoning fused with absolute fixes.

Example::

    >>> import jax.numpy as jnp
    >>> from jbevo.filtering import ukf
    >>> state = ukf.GaussianState(jnp.zeros(3), 0.1 * jnp.eye(3))
    >>> moved = ukf.predict(planar_pose_model(), state, jnp.array([1.0, 0.0, 0.1]), 0.01 * jnp.eye(3))
    >>> [round(float(v), 3) for v in moved.mean]
    [1.0, 0.0, 0.1]
"""

from __future__ import annotations

import functools

from jbevo.filtering.ukf import StateSpaceModel
from jbevo.filtering.unscented import circular_mean_fn, wrapped_add_fn, wrapped_residual_fn
from jbevo.geometry.se2 import se2_compose

#: Index of yaw in the planar state and in the pose-fix measurement.
YAW = 2


#: Chi-square bound with 3 degrees of freedom at 99.9 %.
CHI2_3DOF_999 = 16.27


def _pose_fix(pose):
    return pose


@functools.cache
def planar_pose_model() -> StateSpaceModel:
    """The (x, y, yaw) UKF model: odometry increments as motion, pose fixes as measurements.

    Cached: every call returns the same (hashable) model, so jitted code that takes it as a
    static argument compiles once.
    """
    residual = wrapped_residual_fn([YAW])
    mean = circular_mean_fn([YAW])
    return StateSpaceModel(
        motion=se2_compose,
        measurement=_pose_fix,
        state_residual=residual,
        state_add=wrapped_add_fn([YAW]),
        state_mean=mean,
        measurement_residual=residual,
        measurement_mean=mean,
    )


__all__ = ["CHI2_3DOF_999", "YAW", "planar_pose_model"]
