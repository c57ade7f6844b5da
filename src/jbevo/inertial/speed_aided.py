"""The speed-aided pitch/roll filter that BEVO runs.

The accelerometer's forward axis reads ``f_x = dv/dt - g sin(pitch)``: during a speed change its
tilt is wrong by ``dv/dt / g`` (2 m/s^2: 11.5 deg). The speed-aided filter therefore does not
measure pitch with it; it integrates it: the state carries the forward speed ``v``, propagated by
``dv/dt = f_x + g sin(pitch)``, and the odometry's speed measures ``v``. A pitch error ``d`` then
shows as a speed drifting at ``g d``, which the speed measurement corrects: pitch is observable
from the vehicle's own odometry, at standstill (zero speed) within a few frames. Roll is measured
by the lateral tilt ``atan2(f_y, f_z)`` after removing the centripetal ``w_z v`` (a car does not
slip sideways), which a longitudinal acceleration does not disturb.

The belief is an :class:`AttitudeState`: a Gaussian over ``(pitch, roll, gyro bias x, y, z,
forward speed)`` (rad, rad/s, m/s; ZYX Euler, positive pitch nose down) with named views; no
index into it exists outside this module. Per frame: :meth:`SpeedAidedAttitude.predict` through
the IMU block, then any of the named measurement updates: :meth:`~SpeedAidedAttitude.update_speed`,
:meth:`~SpeedAidedAttitude.update_lateral_tilt`, :meth:`~SpeedAidedAttitude.update_pitch` and
:meth:`~SpeedAidedAttitude.update_linear` (a scalar measurement linear in the named state, as the
BEV bands give).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from jbevo.filtering import smoother, ukf
from jbevo.filtering.noise import DiagonalCovariance
from jbevo.inertial.attitude_filter import FilterNoise
from jbevo.inertial.kinematics import GRAVITY, euler_rates, fill_missing, forward_acceleration, valid_mean

#: The state's entries, in order.
SPEED_AIDED_STATE = ("pitch", "roll", "gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "speed")
_PITCH, _ROLL, _BIAS, _SPEED = 0, 1, slice(2, 5), 5


class AttitudeState(NamedTuple):
    """The speed-aided filter's Gaussian belief (:data:`SPEED_AIDED_STATE`), with named views
    (which also read a stack of beliefs with leading axes, as a ``lax.scan`` returns them)."""

    mean: Float[Array, "*batch 6"]
    cov: Float[Array, "*batch 6 6"]

    @classmethod
    def initial(
        cls,
        pitch_roll: Float[Array, " 2"],
        speed: Float[Array, ""],
        pitch_roll_std: float,
        gyro_bias_std: float,
        speed_std: float,
    ) -> AttitudeState:
        """A belief at ``pitch_roll`` and ``speed`` with zero gyro bias and independent standard
        deviations."""
        dtype = pitch_roll.dtype
        mean = jnp.concatenate([pitch_roll, jnp.zeros(3, dtype), jnp.asarray(speed, dtype)[None]])
        std = jnp.asarray([pitch_roll_std] * 2 + [gyro_bias_std] * 3 + [speed_std], dtype)
        return cls(mean, jnp.diag(std**2))

    @property
    def pitch(self) -> Float[Array, "*batch"]:
        return self.mean[..., _PITCH]

    @property
    def roll(self) -> Float[Array, "*batch"]:
        return self.mean[..., _ROLL]

    @property
    def pitch_roll(self) -> Float[Array, "*batch 2"]:
        return self.mean[..., _PITCH : _ROLL + 1]

    @property
    def gyro_bias(self) -> Float[Array, "*batch 3"]:
        """The gyro's bias ``(x, y, z)`` (rad/s); ``y`` is the pitch rate's."""
        return self.mean[..., _BIAS]

    @property
    def pitch_rate_bias(self) -> Float[Array, "*batch"]:
        return self.mean[..., _BIAS][..., 1]

    @property
    def speed(self) -> Float[Array, "*batch"]:
        return self.mean[..., _SPEED]

    def gaussian(self) -> ukf.GaussianState:
        return ukf.GaussianState(self.mean, self.cov)

    def astype(self, dtype) -> AttitudeState:
        return AttitudeState(self.mean.astype(dtype), self.cov.astype(dtype))

    @staticmethod
    def row(
        pitch: Float[ArrayLike, ""] = 0.0,
        pitch_rate_bias: Float[ArrayLike, ""] = 0.0,
        speed: Float[ArrayLike, ""] = 0.0,
        dtype=None,
    ) -> Float[Array, " 6"]:
        """The row ``h`` of a scalar measurement ``z = h . state`` given by its coefficients on the
        named entries."""
        dtype = dtype or jnp.result_type(pitch, pitch_rate_bias, speed, float)
        zero = jnp.zeros((), dtype)
        return jnp.stack(
            [jnp.asarray(pitch, dtype), zero, zero, jnp.asarray(pitch_rate_bias, dtype), zero, jnp.asarray(speed, dtype)]
        )


def _motion(state: Float[Array, " 6"], control, dt: float) -> Float[Array, " 6"]:
    """Integrate a frame's gyro and accelerometer samples (NaN-free, ``(S, 3)`` each)."""
    gyro, accel = control
    bias = state[_BIAS]

    def step(s, sample):
        omega, f = sample
        pitch_dot, roll_dot = euler_rates(s[0], s[1], omega - bias)
        speed_dot = forward_acceleration(f[0], s[0])
        return s + dt * jnp.stack([pitch_dot, roll_dot, speed_dot]), None

    s, _ = jax.lax.scan(step, jnp.stack([state[_PITCH], state[_ROLL], state[_SPEED]]), (gyro, accel))
    return jnp.concatenate([s[:2], bias, s[2:]])


def _lateral_tilt(state: Float[Array, " 6"], mean_gyro: Float[Array, " 3"]) -> Float[Array, " 1"]:
    """The roll the accelerometer's y and z axes show after the centripetal term."""
    pitch, roll, speed = state[_PITCH], state[_ROLL], state[_SPEED]
    w = mean_gyro - state[_BIAS]
    f_y = GRAVITY * jnp.cos(pitch) * jnp.sin(roll) + w[2] * speed
    f_z = GRAVITY * jnp.cos(pitch) * jnp.cos(roll) - w[1] * speed
    return jnp.arctan2(f_y, f_z)[None]


@functools.cache
def speed_aided_model(dt: float) -> ukf.StateSpaceModel:
    """The speed-aided UKF model (state :data:`SPEED_AIDED_STATE`; control ``(gyro, accel)``
    blocks; measurement the lateral tilt given the frame's mean gyro)."""
    return ukf.StateSpaceModel(motion=functools.partial(_motion, dt=dt), measurement=_lateral_tilt)


class SpeedAidedAttitude(FilterNoise):
    """Learnable noise of the speed-aided pitch/roll filter: ``motion_noise`` per frame for
    (pitch, roll, 3 gyro biases, speed), ``measurement_noise`` for (lateral tilt, speed).

    ``gap_rate_std`` (static, rad/s; 0: off): through a frame whose gyro block is missing
    altogether (all rows NaN, e.g. an IMU dropout marked as such:
    :func:`jbevo.data.kitti.without_dropouts`) the prediction holds the attitude, and the pitch
    and roll variances grow by ``(S dt gap_rate_std)^2`` (``S`` samples of ``dt``): the rates the
    gyro did not see are taken as unknown, about ``gap_rate_std`` in size, constant through a
    frame and independent from frame to frame. Off, a missing stretch leaves the belief as
    certain as a measured one, and the measurements after it barely move it. Blocks with some
    valid rows (padding) are predicted as before; ``widen=False`` (BEVO's frame 0) skips it. The
    smoother (:meth:`smooth`) does not add it.

    Example::

        >>> import jax.numpy as jnp
        >>> f = SpeedAidedAttitude.create()
        >>> s = AttitudeState.initial(jnp.zeros(2), jnp.float32(5.0), 0.03, 0.005, 0.1)
        >>> s = f.predict(s, jnp.zeros((10, 3)), jnp.tile(jnp.array([0.0, 0.0, 9.80665]), (10, 1)))
        >>> s = f.update_speed(s, jnp.float32(5.0))
        >>> round(float(s.speed), 3)
        5.0
    """

    gap_rate_std: float = eqx.field(static=True, default=0.0)

    @classmethod
    def create(
        cls,
        dt: float = 0.01,
        motion_std=(2e-4, 2e-4, 2e-5, 2e-5, 2e-5, 0.05),
        measurement_std=(0.02, 3.0),
        gap_rate_std: float = 0.0,
    ) -> SpeedAidedAttitude:
        """Hand-set: ~0.01 deg of gyro error and 5 cm/s of accelerometer error per frame; ~1 deg
        of false lateral tilt. The odometry speed's 3 m/s is not its noise (a few cm per frame,
        ~0.5 m/s) but a slow coupling: a tighter value lets the speed jerk the pitch, and every
        pitch jump moves the BEV."""
        if not gap_rate_std >= 0:
            raise ValueError(f"gap_rate_std must be non-negative, got {gap_rate_std}")
        return cls(
            DiagonalCovariance.from_std(jnp.asarray(motion_std)),
            DiagonalCovariance.from_std(jnp.asarray(measurement_std)),
            dt,
            float(gap_rate_std),
        )

    def predict(
        self, state: AttitudeState, gyro: Float[Array, "S 3"], accel: Float[Array, "S 3"], widen: Bool[Array, ""] | bool = True
    ) -> AttitudeState:
        """Propagate through a frame's IMU block (missing samples filled with the block's mean;
        with ``gap_rate_std`` and ``widen``, the pitch and roll variances grow through a missing
        block)."""
        model = speed_aided_model(self.dt)
        moved = AttitudeState(
            *ukf.predict(model, state.gaussian(), (fill_missing(gyro), fill_missing(accel)), self.motion_noise())
        )
        if self.gap_rate_std == 0:
            return moved
        _, _, count = valid_mean(gyro)
        grow = jnp.where((count[0] == 0) & widen, (gyro.shape[-2] * self.dt * self.gap_rate_std) ** 2, 0.0)
        grow = grow.astype(moved.cov.dtype)
        tilt = jnp.zeros(moved.mean.shape[-1], moved.cov.dtype).at[_PITCH].set(1.0).at[_ROLL].set(1.0)
        return AttitudeState(moved.mean, moved.cov + jnp.diag(grow * tilt))

    def smooth(self, beliefs: AttitudeState, gyro: Float[Array, "T S 3"], accel: Float[Array, "T S 3"]) -> AttitudeState:
        """Offline: the unscented RTS smoother over this filter's per-frame ``beliefs`` (a stacked
        :class:`AttitudeState`, the belief after frame ``t``'s :meth:`predict` through
        ``gyro[t]``, ``accel[t]`` and its updates), with the same motion and noise. Each frame's
        estimate then uses the frames after it too."""
        if beliefs.mean.ndim != 2 or gyro.shape[:1] != beliefs.mean.shape[:1] or accel.shape != gyro.shape:
            raise ValueError(
                f"beliefs (T, 6), gyro and accel (T, S, 3) must share T; got {beliefs.mean.shape}, {gyro.shape}, {accel.shape}"
            )
        controls = (jax.vmap(fill_missing)(gyro), jax.vmap(fill_missing)(accel))
        q = self.motion_noise().astype(beliefs.mean.dtype)
        out = smoother.smooth_beliefs(speed_aided_model(self.dt), beliefs.mean, beliefs.cov, controls, q)
        return AttitudeState(out.smoothed_mean, out.smoothed_cov)

    def _std(self) -> Float[Array, " 2"]:
        return jnp.exp(self.measurement_noise.log_std)

    def speed_measurement(
        self, state: AttitudeState, speed: Float[Array, ""], robust: bool = True
    ) -> tuple[Float[Array, ""], Float[Array, ""], Bool[Array, ""]]:
        """The odometry's forward ``speed`` (m/s) against the belief: its innovation (zero where
        ``speed`` is NaN), variance and whether it is usable. With ``robust`` the variance grows
        with the squared innovation (Cauchy-like), so gross odometry failures lose their weight
        instead of pulling the state."""
        innovation = jnp.asarray(speed, state.mean.dtype) - state.speed
        ok = jnp.isfinite(innovation)
        innovation = jnp.where(ok, innovation, 0.0)
        variance = self._std()[1] ** 2 + (innovation**2 if robust else 0.0)
        return innovation, variance, ok

    def update_speed(self, state: AttitudeState, speed: Float[Array, ""], robust: bool = True) -> AttitudeState:
        """Condition on the odometry's forward ``speed`` (m/s; NaN: no update; ``robust`` as in
        :meth:`speed_measurement`)."""
        innovation, variance, ok = self.speed_measurement(state, speed, robust)
        return self.update_linear(state, AttitudeState.row(speed=1.0, dtype=state.mean.dtype), innovation, variance, ok)

    def update_lateral_tilt(
        self, state: AttitudeState, gyro: Float[Array, "S 3"], accel: Float[Array, "S 3"], robust: bool = True
    ) -> AttitudeState:
        """Condition on the lateral tilt of the block's mean specific force (no update if the
        block has no valid sample); ``robust`` as in :meth:`update_speed` (unmodelled lateral
        accelerations)."""
        mean_gyro, _, _ = valid_mean(gyro)
        mean_accel, _, count = valid_mean(accel)
        tilt = jnp.where(count[0] > 0, jnp.arctan2(mean_accel[1], mean_accel[2]), jnp.nan)[None].astype(state.mean.dtype)
        variance = self._std()[0] ** 2
        if robust:
            innovation = jnp.where(jnp.isfinite(tilt), tilt - _lateral_tilt(state.mean, mean_gyro), 0.0)
            variance = variance + innovation[0] ** 2
        posterior, _ = ukf.update(
            speed_aided_model(self.dt), state.gaussian(), tilt, jnp.reshape(variance, (1, 1)), measurement_input=mean_gyro
        )
        return AttitudeState(*posterior)

    def update_pitch(
        self, state: AttitudeState, pitch: Float[Array, ""], std: Float[Array, ""], use: Bool[Array, ""] | bool = True
    ) -> AttitudeState:
        """Condition on a direct measurement of the pitch (e.g. from a map) with standard
        deviation ``std``; unchanged where ``use`` is False."""
        h = AttitudeState.row(pitch=1.0, dtype=state.mean.dtype)
        return self.update_linear(state, h, pitch - state.pitch, std**2, use)

    @staticmethod
    def update_linear(
        state: AttitudeState,
        h: Float[Array, " 6"],
        innovation: Float[Array, ""],
        variance: Float[Array, ""],
        use: Bool[Array, ""] | bool = True,
    ) -> AttitudeState:
        """A scalar measurement linear in the state (``h`` from :meth:`AttitudeState.row`) given its
        ``innovation`` and ``variance`` (:func:`jbevo.filtering.ukf.linear_update`)."""
        return AttitudeState(*ukf.linear_update(state.gaussian(), h, innovation, variance, use))


__all__ = ["SPEED_AIDED_STATE", "AttitudeState", "SpeedAidedAttitude", "speed_aided_model"]
