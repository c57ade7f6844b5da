"""The road's tilt as a state: the grade under the car, against gravity, along its heading.

The attitude filter (:mod:`jbevo.inertial.speed_aided`) estimates the body's pitch against
gravity: its speed state integrates ``f_x + g sin(pitch)``, which holds only for the pitch
against gravity. The BEV, however, needs the camera's pitch against the road, and a street's
grade changes under the car by tenths of a degree within tens of metres (on the real KITTI runs
a constant camera-to-road pitch fitted on one half of a run misses the other half by that much:
``benchmarks/real_kitti.py``). Correcting the gravity pitch with the bands' slope, which sees the
road, makes the filter fight its own speed coupling.

:class:`RoadTilt` keeps the two apart: a scalar Gaussian state ``d``, the road's tilt along the
heading (radians, positive where the road falls away ahead, as a nose-down pitch), which the BEV's
projection adds to the filter's pitch, and which only the bands' slope measures
(:meth:`jbevo.vision.bands.BandGeometry.slope_measurement`: the slope is linear in the projection's
pitch error with coefficient ``2 D / h``). Between frames it walks: its variance grows by
``q^2 |D|`` over the ``D`` metres travelled (the grade changes with distance, not with time). The
hand-set walk, ``q`` = 0.0025 rad per square-root metre, is a degree over about 50 m; learnable.

The bands engage only from a travel per frame (:attr:`jbevo.vision.bands.BandGeometry.min_travel`);
below it the tilt used to stay where the last engaged frame left it, and a stale tilt scales
DPC's forward motion by ``1 - 2 x e / h`` (``e`` the projection's pitch error, ``x`` the BEV's
centre distance: 35 % per degree on the real-street grid). The odometry's speed, which the
attitude filter takes as a measurement of its speed state, therefore measures the tilt too:
:meth:`RoadTilt.update_with_speed` conditions both beliefs on it at once, with the coefficient
``v 2 x / h`` on the tilt, so a speed that disagrees with the accelerometer's integration moves the
tilt where the tilt is uncertain and the speed where the speed is. An underestimated travel then
no longer holds the bands below their gate (on the street world's KITTI 08 it did, for 300
frames).

**Level road** (``level``, static). The BEV is projected on the road's plane whatever the filter
says: its pitch is the tilt state alone and its roll zero (both on top of the road view's camera
offsets), so the state is the camera's pitch against the road beyond the road view's, not the
grade, and changes only with the car's load and suspension. The filter's attitude against gravity
still serves the IMU (the speed state, the gyro's turn). The grade then never enters the BEV, and
the tilt's walk can be small (:data:`jbevo.models.presets.LEVEL_ROAD_WALK`), but the suspension's
pitch and roll against the road, which the filter's attitude carries, are lost to it. Where it
holds and where it does not: ``benchmarks/street_oracle.py``, ``benchmarks/real_kitti.py``.

Example::

    >>> import jax.numpy as jnp
    >>> tilt = RoadTilt.create()
    >>> state = tilt.predict(tilt.initial(jnp.float32), jnp.float32(10.0))
    >>> round(float(state.cov[0, 0]) ** 0.5, 4)
    0.0118
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from jbevo.filtering import ukf
from jbevo.inertial.speed_aided import AttitudeState, SpeedAidedAttitude
from jbevo.vision.bands import SlopeMeasurement


class RoadTilt(eqx.Module):
    """The road tilt's random walk (learnable) and its prior (static).

    Attributes:
        log_walk_std: log of ``q``, radians per square-root metre travelled.
        initial_std: the prior's standard deviation (radians; static, hand-set 0.5 deg).
        level: static; the BEV's pitch is the tilt alone and its roll zero (module docstring).
        speed_coupling: static; the odometry's speed measures the tilt too
            (:meth:`update_with_speed`). Off (an ablation), only the bands' slope does.
    """

    log_walk_std: Float[Array, ""]
    initial_std: float = eqx.field(static=True, default=0.0087)
    level: bool = eqx.field(static=True, default=False)
    speed_coupling: bool = eqx.field(static=True, default=True)

    @classmethod
    def create(
        cls, walk_std: float = 0.0025, initial_std: float = 0.0087, level: bool = False, speed_coupling: bool = True
    ) -> RoadTilt:
        if not (walk_std > 0 and initial_std > 0):
            raise ValueError(f"walk_std and initial_std must be positive, got {walk_std}, {initial_std}")
        return cls(jnp.log(jnp.float32(walk_std)), float(initial_std), bool(level), bool(speed_coupling))

    def initial(self, dtype) -> ukf.GaussianState:
        """A level road, ``initial_std`` uncertain."""
        return ukf.GaussianState(jnp.zeros(1, dtype), jnp.full((1, 1), self.initial_std**2, dtype))

    def predict(self, state: ukf.GaussianState, travel: Float[Array, ""]) -> ukf.GaussianState:
        """The walk over ``travel`` metres."""
        grow = (jnp.exp(2.0 * self.log_walk_std) * jnp.abs(travel)).astype(state.cov.dtype)
        return ukf.GaussianState(state.mean, state.cov + grow)

    @staticmethod
    def update(state: ukf.GaussianState, slope: SlopeMeasurement, use: Bool[Array, ""] | bool = True) -> ukf.GaussianState:
        """Condition on the bands' slope (its ``pitch`` coefficient, value and variance), the
        only measurement of the road's tilt; unchanged where ``use`` is False."""
        dtype = state.mean.dtype
        h = jnp.reshape(slope.pitch, (1,)).astype(dtype)
        return ukf.linear_update(state, h, slope.value.astype(dtype), slope.variance.astype(dtype), use)

    @staticmethod
    def update_with_speed(
        attitude: SpeedAidedAttitude,
        belief: AttitudeState,
        state: ukf.GaussianState,
        speed: Float[Array, ""],
        sensitivity: Float[Array, ""] | float,
    ) -> tuple[AttitudeState, ukf.GaussianState]:
        """Condition the attitude ``belief`` and the tilt ``state`` together on the odometry's
        forward ``speed`` (m/s; NaN: no update), measured from BEVs projected with the tilt:
        ``speed = v (1 + sensitivity (d - d_hat))`` to first order, ``sensitivity`` the relative
        change of the BEV's forward motion per radian of the projection's pitch (``2 x / h``;
        zero: :meth:`SpeedAidedAttitude.update_speed` alone). The innovation and its (robust)
        variance are :meth:`SpeedAidedAttitude.speed_measurement`'s. One Kalman update of the two
        beliefs stacked, which then stay separate (the cross-covariance the update creates is
        dropped)."""
        innovation, variance, ok = attitude.speed_measurement(belief, speed)
        dtype = belief.mean.dtype
        n = belief.mean.shape[-1]
        mean = jnp.concatenate([belief.mean, state.mean.astype(dtype)])
        cov = jnp.zeros((n + 1, n + 1), dtype).at[:n, :n].set(belief.cov).at[n:, n:].set(state.cov.astype(dtype))
        coefficient = (belief.speed * jnp.asarray(sensitivity, dtype))[None]
        h = jnp.concatenate([AttitudeState.row(speed=1.0, dtype=dtype), coefficient])
        joint = ukf.linear_update(ukf.GaussianState(mean, cov), h, innovation, variance, ok)
        tilt = ukf.GaussianState(joint.mean[n:].astype(state.mean.dtype), joint.cov[n:, n:].astype(state.cov.dtype))
        return AttitudeState(joint.mean[:n], joint.cov[:n, :n]), tilt


__all__ = ["RoadTilt"]
