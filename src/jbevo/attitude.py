"""The pitch/roll DUKF: gyro integration as motion, accelerometer tilt as measurement.

State ``(pitch, roll)`` (radians, ZYX Euler, positive pitch nose down), optionally with a gyro
bias ``(bx, by, bz)`` (rad/s, random walk). One filter step per camera frame:

* **Motion**: integrate the gyro samples between the two frames with the exact ZYX Euler-rate
  kinematics, ``pitch' = cos(roll) wy - sin(roll) wz`` and
  ``roll' = wx + tan(pitch) (sin(roll) wy + cos(roll) wz)`` (forward Euler per IMU sample). The
  seed's ``[w_pitch, w_roll] * dt`` ignores the coupling through roll and the yaw rate; in a turn
  at 2 deg of roll it mistakes 3.5 % of the yaw rate for pitch rate.
* **Measurement**: the tilt of the mean specific force over the frame's samples,
  ``pitch = -atan2(ax, sqrt(ay^2 + az^2))``, ``roll = atan2(ay, az)``. The accelerometer also feels
  the car's own acceleration (braking, centripetal force: often 1-3 m/s^2, several degrees of false
  tilt); the *motion-compensated* measurement first removes the body acceleration predicted from
  the odometry's body-frame velocity and the gyro, ``dv/dt + w x v`` (:func:`body_acceleration`).
  The gyro's bias enters that term as ``b x v`` (0.3 deg/s of yaw-rate bias at 10 m/s is
  0.05 m/s^2 of false lateral force); with the bias state the measurement model predicts it, so
  the filter can tell it from tilt.

Q (per frame) and R are learnable :class:`jbevo.ukf.DiagonalCovariance` s. Missing IMU samples
(NaN) are skipped: a frame's motion integrates its valid gyro samples with the mean of those
filling the gaps, its measurement averages the valid accelerometer samples, and a frame with none
makes no update (the UKF skips NaN measurements exactly).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo import ukf


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


def accel_tilt(accel: Float[Array, "... 3"]) -> Float[Array, "... 2"]:
    """``(pitch, roll)`` of a specific-force vector (gravity only: exact)."""
    ax, ay, az = accel[..., 0], accel[..., 1], accel[..., 2]
    return jnp.stack([-jnp.arctan2(ax, jnp.sqrt(ay**2 + az**2)), jnp.arctan2(ay, az)], -1)


def _valid_mean(samples: Float[Array, "... S 3"]) -> tuple[Array, Array, Array]:
    """Mean over the sample axis of the rows without NaN, the row mask and the count (the mean is
    zero where no row is valid); NaN-free in value and gradient."""
    ok = jnp.all(jnp.isfinite(samples), axis=-1, keepdims=True)
    clean = jnp.where(ok, samples, 0.0)
    count = jnp.sum(ok, axis=-2)
    return jnp.sum(clean, axis=-2) / jnp.maximum(count, 1), ok, count


def _fill_missing(samples: Float[Array, "S 3"]) -> Float[Array, "S 3"]:
    """Replace NaN rows by the mean of the valid rows (zero if none), NaN-free in value and grad."""
    mean, ok, _ = _valid_mean(samples)
    return jnp.where(ok, jnp.where(ok, samples, 0.0), mean)


def integrate_gyro(state: Float[Array, " n"], gyro: Float[Array, "S 3"], dt: float) -> Float[Array, " n"]:
    """Propagate ``(pitch, roll[, bias])`` over the (NaN-free) gyro samples of one frame."""
    bias = state[2:5] if state.shape[0] == 5 else jnp.zeros(3, state.dtype)

    def step(pr, omega):
        pitch_dot, roll_dot = euler_rates(pr[0], pr[1], omega - bias)
        return pr + dt * jnp.stack([pitch_dot, roll_dot]), None

    pr, _ = jax.lax.scan(step, state[:2], gyro)
    return jnp.concatenate([pr, state[2:]])


GRAVITY = 9.80665


def _measure(state):
    return state[:2]


def _measure_compensated(state, velocity):
    """Tilt the compensated specific force should show: gravity in the body frame minus the part
    of ``w x v`` that the gyro bias put into the compensation, ``b x v``."""
    pitch, roll = state[0], state[1]
    g = GRAVITY * jnp.stack([-jnp.sin(pitch), jnp.cos(pitch) * jnp.sin(roll), jnp.cos(pitch) * jnp.cos(roll)])
    return accel_tilt(g - jnp.cross(state[2:5], velocity))


@functools.cache
def attitude_model(dt: float, bias_in_compensation: bool = False) -> ukf.StateSpaceModel:
    """The UKF model; cached so that jitted code sees the same (hashable) model. With
    ``bias_in_compensation`` the measurement takes the frame's body velocity and accounts for
    the gyro bias inside the compensation's ``w x v`` (state with bias only)."""
    measurement = _measure_compensated if bias_in_compensation else _measure
    return ukf.StateSpaceModel(motion=functools.partial(integrate_gyro, dt=dt), measurement=measurement)


def body_acceleration(
    velocity: Float[Array, "T 2"], gyro: Float[Array, "T 3"], frame_dt: float
) -> Float[Array, "T 3"]:
    """Predicted body-frame acceleration ``dv/dt + w x v`` of a vehicle whose body-frame velocity
    is planar, ``v = (vx, vy, 0)`` (what the odometry gives), with ``w`` the frame's mean gyro.

    For a car without side slip (``vy = 0``) this is ``(dvx/dt, vx wz, -vx wy)``.
    """
    v = jnp.concatenate([velocity, jnp.zeros_like(velocity[:, :1])], axis=-1)
    return jnp.gradient(v, frame_dt, axis=0) + jnp.cross(gyro, v)


def tilt_measurements(accel: Float[Array, "T S 3"], compensation: Float[Array, "T 3"] | None = None) -> Array:
    """Per-frame tilt of the mean valid specific force (NaN for a frame without samples)."""
    mean, _, count = _valid_mean(accel)
    if compensation is not None:
        mean = mean - compensation
    tilt = accel_tilt(mean)
    return jnp.where(count > 0, tilt, jnp.nan)


class _FilterNoise(eqx.Module):
    """The learnable part of a pitch/roll filter: per-frame motion noise (Q) and measurement
    noise (R), and the IMU sample interval ``dt``."""

    motion_noise: ukf.DiagonalCovariance
    measurement_noise: ukf.DiagonalCovariance
    dt: float = eqx.field(static=True)


class AttitudeFilter(_FilterNoise):
    """Learnable pitch/roll filter. ``motion_noise`` is per frame: 2 values (pitch, roll), or 5
    with the gyro bias state; ``measurement_noise`` 2 values (pitch, roll of the tilt)."""

    @classmethod
    def create(
        cls,
        dt: float = 0.01,
        motion_std=(2e-4, 2e-4),
        measurement_std=(0.02, 0.02),
        gyro_bias: bool = False,
        bias_walk_std: float = 2e-5,
    ) -> AttitudeFilter:
        """Defaults are hand-set: ~0.01 deg of gyro error per frame, ~1 deg of false tilt."""
        q = list(motion_std) + ([bias_walk_std] * 3 if gyro_bias else [])
        return cls(ukf.DiagonalCovariance.from_std(jnp.asarray(q)), ukf.DiagonalCovariance.from_std(jnp.asarray(measurement_std)), dt)

    @property
    def gyro_bias(self) -> bool:
        return self.motion_noise.log_std.shape[0] == 5

    def __call__(
        self,
        gyro: Float[Array, "T S 3"],
        accel: Float[Array, "T S 3"],
        initial: Float[Array, " 2"] | None = None,
        velocity: Float[Array, "T 2"] | None = None,
        initial_std: float = 0.03,
        initial_bias_std: float = 0.005,
    ) -> Float[Array, "T 2"]:
        """Filtered ``(pitch, roll)`` after each frame's samples. ``initial`` defaults to the tilt
        of the first frame's accelerometer samples. With ``velocity`` (the odometry's planar
        body-frame velocity per frame, m/s) the measurement is motion-compensated; with a bias
        state the measurement model also removes the bias's share of the compensation."""
        if gyro.ndim != 3 or gyro.shape[-1] != 3 or accel.shape != gyro.shape:
            raise ValueError(f"gyro and accel must both have shape (T, S, 3), got {gyro.shape} and {accel.shape}")
        if velocity is not None and velocity.shape != (gyro.shape[0], 2):
            raise ValueError(f"velocity must have shape ({gyro.shape[0]}, 2), got {velocity.shape}")
        gyro = jax.vmap(_fill_missing)(gyro)
        v3 = None
        compensation = None
        if velocity is not None:
            v3 = jnp.concatenate([velocity, jnp.zeros_like(velocity[:, :1])], axis=-1)
            compensation = body_acceleration(velocity, jnp.mean(gyro, axis=1), self.dt * gyro.shape[1])
        z = tilt_measurements(accel, compensation)
        if initial is None:
            initial = jnp.nan_to_num(z[0])
        n = 5 if self.gyro_bias else 2
        mean = jnp.concatenate([initial, jnp.zeros(n - 2, initial.dtype)])
        std = jnp.asarray([initial_std] * 2 + [initial_bias_std] * (n - 2), initial.dtype)
        prior = ukf.GaussianState(mean, jnp.diag(std**2))
        bias_in_compensation = self.gyro_bias and velocity is not None
        model = attitude_model(self.dt, bias_in_compensation)
        result = ukf.filter(
            model, prior, gyro, z, self.motion_noise(), self.measurement_noise(),
            measurement_inputs=v3 if bias_in_compensation else None,
        )
        return result.filtered_mean[:, :2]


# ----------------------------------------------------------------------------- speed-aided filter
#
# The accelerometer's forward axis reads f_x = dv/dt - g sin(pitch): during a speed change the
# tilt is wrong by dv/dt / g (2 m/s^2: 11.5 deg). The speed-aided filter therefore does not
# measure pitch with it; it integrates it: the state carries the forward speed v, propagated by
# dv/dt = f_x + g sin(pitch), and the odometry's speed measures v. A pitch error d then shows as a
# speed drifting at g d, which the speed measurement corrects: pitch is observable from the
# vehicle's own odometry, at standstill (zero speed) within a few frames. Roll is still measured by
# the lateral tilt atan2(f_y, f_z) after removing the centripetal w_z v (a car does not slip
# sideways), which a longitudinal acceleration does not disturb.

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


class SpeedAidedAttitude(_FilterNoise):
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
            ukf.DiagonalCovariance.from_std(jnp.asarray(motion_std)),
            ukf.DiagonalCovariance.from_std(jnp.asarray(measurement_std)),
            dt,
        )

    def predict(self, state: ukf.GaussianState, gyro: Float[Array, "S 3"], accel: Float[Array, "S 3"]) -> ukf.GaussianState:
        """Propagate through a frame's IMU block (missing samples filled with the block's mean)."""
        model = speed_aided_model(self.dt)
        return ukf.predict(model, state, (_fill_missing(gyro), _fill_missing(accel)), self.motion_noise())

    def update(
        self, predicted: ukf.GaussianState, gyro: Float[Array, "S 3"], accel: Float[Array, "S 3"], speed: Array,
        robust: bool = True,
    ) -> ukf.GaussianState:
        """Condition on the lateral tilt of the block's mean specific force (none if the block
        has no valid sample) and the odometry's forward ``speed`` (NaN: none). With ``robust``
        the measurement noise grows with the squared innovation (Cauchy-like), so gross odometry
        failures and unmodelled accelerations lose their weight instead of pulling the state."""
        mean_gyro, _, _ = _valid_mean(gyro)
        mean_accel, _, count = _valid_mean(accel)
        tilt = jnp.where(count[0] > 0, jnp.arctan2(mean_accel[1], mean_accel[2]), jnp.nan)
        z = jnp.stack([tilt, jnp.asarray(speed, tilt.dtype)])
        r = self.measurement_noise()
        if robust:
            expected = _speed_aided_measurement(predicted.mean, mean_gyro)
            innovation = jnp.where(jnp.isfinite(z), z - expected, 0.0)
            r = r + jnp.diag(innovation**2)
        state, _ = ukf.update(speed_aided_model(self.dt), predicted, z, r, measurement_input=mean_gyro)
        return state
