"""BEVO+ localization: the planar pose filter (state x, y, yaw).

Motion: the body-frame odometry increment ``(dx, dy, dyaw)`` composed onto the pose
(:func:`jbevo.geometry.se2_compose`). Measurement: a pose fix ``(x, y, yaw)`` in the world frame
(from map matching), yaw wrapped. The map crop and DPC map matching that produce the fixes build
on this model.
"""

from __future__ import annotations

import functools

from jbevo.geometry import se2_compose
from jbevo.ukf import StateSpaceModel
from jbevo.unscented import circular_mean_fn, wrapped_add_fn, wrapped_residual_fn

#: Index of yaw in the planar state and in the pose-fix measurement.
YAW = 2


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

