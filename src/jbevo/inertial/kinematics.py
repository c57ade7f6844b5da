"""IMU kinematics for pitch and roll: exact ZYX Euler rates from body rates, the tilt of a
specific-force vector, the yaw a gyro block turns, the body acceleration of a planar vehicle,
and the handling of missing samples (NaN rows).

Units: rad, rad/s, m/s^2 (specific force: at rest and level ``(0, 0, +g)``); body x forward,
y left, z up; positive pitch nose down.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

GRAVITY = 9.80665


def euler_rates(pitch: Array, roll: Array, omega: Float[Array, "... 3"]) -> tuple[Array, Array]:
    """``(d pitch / dt, d roll / dt)`` from body rates ``omega = (wx, wy, wz)`` (ZYX Euler)."""
    wx, wy, wz = omega[..., 0], omega[..., 1], omega[..., 2]
    sr, cr = jnp.sin(roll), jnp.cos(roll)
    pitch_dot = cr * wy - sr * wz
    roll_dot = wx + jnp.tan(pitch) * (sr * wy + cr * wz)
    return pitch_dot, roll_dot


def gyro_yaw_increment(gyro: Float[Array, "S 3"], pitch: Array, roll: Array, dt: float) -> Float[Array, ""]:
    """The yaw turned over one block of gyro samples (rad; NaN rows skipped), with the ZYX yaw
    rate ``(sin(roll) wy + cos(roll) wz) / cos(pitch)`` at a constant ``pitch`` and ``roll``."""
    ok = jnp.all(jnp.isfinite(gyro), axis=-1)
    g = jnp.where(ok[:, None], gyro, 0.0)
    rate = (jnp.sin(roll) * g[:, 1] + jnp.cos(roll) * g[:, 2]) / jnp.cos(pitch)
    return dt * jnp.sum(rate)


def forward_acceleration(forward_force: Array, pitch: Array) -> Array:
    """The rate of change of the forward speed, ``f_x + g sin(pitch)`` (m/s^2): the specific
    force's forward axis plus gravity's share along it at ``pitch`` (positive nose down; at rest
    on a slope the two cancel)."""
    return forward_force + GRAVITY * jnp.sin(pitch)


def accel_tilt(accel: Float[Array, "... 3"]) -> Float[Array, "... 2"]:
    """``(pitch, roll)`` of a specific-force vector (gravity only: exact)."""
    ax, ay, az = accel[..., 0], accel[..., 1], accel[..., 2]
    return jnp.stack([-jnp.arctan2(ax, jnp.sqrt(ay**2 + az**2)), jnp.arctan2(ay, az)], -1)


def valid_mean(samples: Float[Array, "... S 3"]) -> tuple[Array, Array, Array]:
    """Mean over the sample axis of the rows without NaN, the row mask and the count (the mean is
    zero where no row is valid); NaN-free in value and gradient."""
    ok = jnp.all(jnp.isfinite(samples), axis=-1, keepdims=True)
    clean = jnp.where(ok, samples, 0.0)
    count = jnp.sum(ok, axis=-2)
    return jnp.sum(clean, axis=-2) / jnp.maximum(count, 1), ok, count


def fill_missing(samples: Float[Array, "S 3"]) -> Float[Array, "S 3"]:
    """Replace NaN rows by the mean of the valid rows (zero if none), NaN-free in value and grad."""
    mean, ok, _ = valid_mean(samples)
    return jnp.where(ok, jnp.where(ok, samples, 0.0), mean)


def body_acceleration(velocity: Float[Array, "T 2"], gyro: Float[Array, "T 3"], frame_dt: float) -> Float[Array, "T 3"]:
    """Predicted body-frame acceleration ``dv/dt + w x v`` of a vehicle whose body-frame velocity
    is planar, ``v = (vx, vy, 0)`` (what the odometry gives), with ``w`` the frame's mean gyro.

    For a car without side slip (``vy = 0``) this is ``(dvx/dt, vx wz, -vx wy)``.
    """
    v = jnp.concatenate([velocity, jnp.zeros_like(velocity[:, :1])], axis=-1)
    # The time derivative by central differences (one-sided at the ends).
    dv = jnp.concatenate([v[1:2] - v[:1], 0.5 * (v[2:] - v[:-2]), v[-1:] - v[-2:-1]]) / frame_dt
    return dv + jnp.cross(gyro, v)


def tilt_measurements(accel: Float[Array, "T S 3"], compensation: Float[Array, "T 3"] | None = None) -> Array:
    """Per-frame tilt of the mean valid specific force (NaN for a frame without samples)."""
    mean, _, count = valid_mean(accel)
    if compensation is not None:
        mean = mean - compensation
    tilt = accel_tilt(mean)
    return jnp.where(count > 0, tilt, jnp.nan)


__all__ = [
    "GRAVITY",
    "accel_tilt",
    "body_acceleration",
    "euler_rates",
    "fill_missing",
    "forward_acceleration",
    "gyro_yaw_increment",
    "tilt_measurements",
    "valid_mean",
]
