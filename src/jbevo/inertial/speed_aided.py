"""The speed-aided pitch/roll filter that BEVO runs.

The accelerometer's forward axis reads f_x = dv/dt - g sin(pitch): during a speed change the
tilt is wrong by dv/dt / g (2 m/s^2: 11.5 deg). The speed-aided filter therefore does not
measure pitch with it; it integrates it: the state carries the forward speed v, propagated by
dv/dt = f_x + g sin(pitch), and the odometry's speed measures v. A pitch error d then shows as a
speed drifting at g d, which the speed measurement corrects: pitch is observable from the
vehicle's own odometry, at standstill (zero speed) within a few frames. Roll is still measured by
the lateral tilt atan2(f_y, f_z) after removing the centripetal w_z v (a car does not slip
sideways), which a longitudinal acceleration does not disturb.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo.filtering import ukf
from jbevo.filtering.noise import DiagonalCovariance
from jbevo.inertial.attitude_filter import FilterNoise
from jbevo.inertial.kinematics import GRAVITY, euler_rates, fill_missing, valid_mean


SPEED_AIDED_STATE = ("pitch", "roll", "bias_x", "bias_y", "bias_z", "speed")


def _speed_aided_motion(state: Float[Array, " 6"], control, dt: float) -> Float[Array, " 6"]:
    """Integrate a frame's gyro and accelerometer samples (NaN-free, ``(S, 3)`` each)."""
    gyro, accel = control
    bias = state[2:5]

    def step(s, sample):
        omega, f = sample
        pitch_dot, roll_dot = euler_rates(s[0], s[1], omega - bias)
        speed_dot = f[0] + GRAVITY * jnp.sin(s[0])
        return s + dt * jnp.stack([pitch_dot, roll_dot, speed_dot]), None

    s, _ = jax.lax.scan(step, jnp.stack([state[0], state[1], state[5]]), (gyro, accel))
    return jnp.concatenate([s[:2], bias, s[2:]])


def _speed_aided_measurement(state: Float[Array, " 6"], mean_gyro: Float[Array, " 3"]) -> Float[Array, " 2"]:
    """``(lateral tilt, speed)``: the roll the accelerometer's y and z axes show after the
    centripetal term, and the forward speed."""
    pitch, roll, speed = state[0], state[1], state[5]
    w = mean_gyro - state[2:5]
    f_y = GRAVITY * jnp.cos(pitch) * jnp.sin(roll) + w[2] * speed
    f_z = GRAVITY * jnp.cos(pitch) * jnp.cos(roll) - w[1] * speed
    return jnp.stack([jnp.arctan2(f_y, f_z), speed])


@functools.cache
def speed_aided_model(dt: float) -> ukf.StateSpaceModel:
    """The speed-aided UKF model (state :data:`SPEED_AIDED_STATE`; control ``(gyro, accel)``
    blocks; measurement ``(lateral tilt, speed)`` given the frame's mean gyro)."""
    return ukf.StateSpaceModel(
        motion=functools.partial(_speed_aided_motion, dt=dt), measurement=_speed_aided_measurement
    )


class SpeedAidedAttitude(FilterNoise):
    """Learnable noise of the speed-aided pitch/roll filter: ``motion_noise`` per frame for
    (pitch, roll, 3 gyro biases, speed), ``measurement_noise`` for (lateral tilt, speed)."""

    @classmethod
    def create(
        cls,
        dt: float = 0.01,
        motion_std=(2e-4, 2e-4, 2e-5, 2e-5, 2e-5, 0.05),
        measurement_std=(0.02, 3.0),
    ) -> SpeedAidedAttitude:
        """Hand-set: ~0.01 deg of gyro error and 5 cm/s of accelerometer error per frame; ~1 deg
        of false lateral tilt. The odometry speed's 3 m/s is not its noise (a few cm per frame,
        ~0.5 m/s) but a slow coupling: a sweep over 0.3-30 m/s on the five built-in drives (BEVO
        per-frame error 17, 16, 10, 11, 12, 13 cm at 0.3, 1, 3, 5, 10, 30) put it at 3; a
        tighter value lets the speed jerk the pitch, and every pitch jump moves the BEV."""
        return cls(
            DiagonalCovariance.from_std(jnp.asarray(motion_std)),
            DiagonalCovariance.from_std(jnp.asarray(measurement_std)),
            dt,
        )

    def predict(self, state: ukf.GaussianState, gyro: Float[Array, "S 3"], accel: Float[Array, "S 3"]) -> ukf.GaussianState:
        """Propagate through a frame's IMU block (missing samples filled with the block's mean)."""
        model = speed_aided_model(self.dt)
        return ukf.predict(model, state, (fill_missing(gyro), fill_missing(accel)), self.motion_noise())

    def update(
        self, predicted: ukf.GaussianState, gyro: Float[Array, "S 3"], accel: Float[Array, "S 3"], speed: Array,
        robust: bool = True,
    ) -> ukf.GaussianState:
        """Condition on the lateral tilt of the block's mean specific force (none if the block
        has no valid sample) and the odometry's forward ``speed`` (NaN: none). With ``robust``
        the measurement noise grows with the squared innovation (Cauchy-like), so gross odometry
        failures and unmodelled accelerations lose their weight instead of pulling the state."""
        mean_gyro, _, _ = valid_mean(gyro)
        mean_accel, _, count = valid_mean(accel)
        tilt = jnp.where(count[0] > 0, jnp.arctan2(mean_accel[1], mean_accel[2]), jnp.nan)
        z = jnp.stack([tilt, jnp.asarray(speed, tilt.dtype)])
        r = self.measurement_noise()
        if robust:
            expected = _speed_aided_measurement(predicted.mean, mean_gyro)
            innovation = jnp.where(jnp.isfinite(z), z - expected, 0.0)
            r = r + jnp.diag(innovation**2)
        state, _ = ukf.update(speed_aided_model(self.dt), predicted, z, r, measurement_input=mean_gyro)
        return state


__all__ = ["SPEED_AIDED_STATE", "SpeedAidedAttitude", "speed_aided_model"]
