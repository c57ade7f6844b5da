"""The forward motion per frame from the accelerometer and DPC together.

On the real KITTI runs BEVO's per-frame motion error is almost all along the heading (06: 8.3 of
8.4 cm RMS, 07: 6.8 of 7.0 cm with the street preset; across the heading 1.2 and 1.7 cm): lane
markings and kerbs run along the motion and fix the lateral shift, little in a street's ground
texture fixes the forward one. The accelerometer measures exactly that axis's change of speed.

:class:`ForwardFusion` is a linear Kalman filter over ``(speed, travel, bias)``: the forward speed
(m/s), the distance travelled since the previous frame (m) and the bias of the forward
acceleration (m/s^2). Within a frame each IMU sample moves the speed by ``(a - bias) dt`` with
``a = f_x + g sin(pitch)`` (the specific force's forward axis and gravity's share at the body's
pitch, positive nose down, as :mod:`jbevo.inertial.speed_aided` models it) and the travel by
``speed dt + (a - bias) dt^2 / 2``; the speed walks by ``accel_std`` m/s^2 per sample
(accelerometer noise and vibration). The bias is what the accelerometer's own bias and the
attitude filter's pitch error (0.1 deg of pitch is 0.017 m/s^2 of gravity's share) add to the
forward acceleration; both change slowly, so it walks by ``bias_walk`` m/s^2 per square root of
a second. Without it a pitch error integrates into the speed, which DPC's increments, trusted
little against an accelerometer taken as unbiased, pull back only partly (on the street world's
long drives the fused distance then falls short by a tenth to a fifth).

DPC's forward increment measures the travel with a standard deviation of ``displacement_std``
metres, linearly: the weight of an increment depends on neither its value nor its innovation, so
over long spans the fused travel keeps DPC's own sum (the filter passes DPC's slow errors, a
scale that a stale road tilt or pitch leaves, unchanged; it removes the per-frame scatter). A
weight that grows as the increment shrinks (a noise relative to it) or falls with the innovation
(a robust update) pulls the fused distance toward DPC's low increments whenever their errors are
skewed or grow with the speed: on the street world's KITTI 00 drive, the preset's distance ratio
0.954 became 0.929 with a 5 % relative, robust update, and is 0.951 with this one; on its 09 and
10 the pooled devkit t_err rose from 3.70 to 5.12 % with that update and is 3.86 % with this one
(``benchmarks/forward_fusion.py``). A gross increment then moves the travel by the gain's share
of its error rather than none; a gate that dropped gross increments would drop every one of them
once the speed had drifted past it. The posterior travel is the frame's forward motion. At the
start of each frame the travel is reset to zero.

The attitude filter keeps its own speed state and DPC's raw increment (its pitch coupling is
unchanged); this filter only replaces the forward component of the output increment. Hand-set:
``accel_std`` 0.05 m/s^2, ``displacement_std`` 5 cm (5 % of a metre per frame), ``bias_walk``
:data:`BIAS_WALK` from :data:`BIAS_STD` at the start; all three learnable.

Example::

    >>> import jax.numpy as jnp
    >>> fusion = ForwardFusion.create()
    >>> state = fusion.initial(jnp.float32(10.0), 0.1, jnp.float32)
    >>> accel = jnp.zeros((10, 3), jnp.float32).at[:, 0].set(1.0)  # 10 samples at 1 m/s^2
    >>> state = fusion.predict(state, accel, jnp.float32(0.0), 0.01)
    >>> [round(float(v), 3) for v in state.mean]  # from 10 m/s, no bias yet
    [10.1, 1.005, 0.0]
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from jbevo.filtering import ukf
from jbevo.inertial.kinematics import fill_missing, forward_acceleration

#: The measurement row of the travel (a tuple: no JAX array at import, which would start the
#: backend before a multi-process job can join).
_TRAVEL = (0.0, 1.0, 0.0)

#: The speed's walk (m/s^2) over a missing IMU sample, which is filled with the block's mean (or
#: zero when the whole block is missing): about a car's range of acceleration.
MISSING_ACCEL_STD = 3.0

#: The speed's prior standard deviation (m/s) started from the truth's speed (a warm start) and
#: from none (a cold start: the car may already be moving; the accelerometer cannot tell).
WARM_SPEED_STD, COLD_SPEED_STD = 0.1, 5.0

#: The forward acceleration's bias's prior standard deviation (m/s^2), warm or cold: about
#: gravity's share of a 0.6 deg pitch error.
BIAS_STD = 0.1

#: The bias's hand-set random walk (m/s^2 per square root of a second): chosen among 0.005, 0.02
#: and 0.05 on the street world's KITTI 00 and 08 drives (``benchmarks/forward_fusion.py``'s
#: ``bias_walk_sweep``, none of them a drive or run scored with it): the lowest devkit error on
#: both (the per-frame motion error falls toward the smallest walk).
BIAS_WALK = 0.05


class ForwardFusion(eqx.Module):
    """The forward speed, travel and bias filter's noise (learnable) and the bias's prior (static).

    Attributes:
        log_accel_std: log of the speed's walk per IMU sample, m/s^2.
        log_displacement_std: log of DPC's forward increment's standard deviation, metres.
        log_bias_walk: log of the bias's random walk, m/s^2 per square root of a second.
        bias_std: the bias's prior standard deviation, m/s^2 (:data:`BIAS_STD`; 0 with a
            negligible walk: a filter without the bias state).
    """

    log_accel_std: Float[Array, ""]
    log_displacement_std: Float[Array, ""]
    log_bias_walk: Float[Array, ""]
    bias_std: float = eqx.field(static=True, default=BIAS_STD)

    @classmethod
    def create(
        cls,
        accel_std: float = 0.05,
        displacement_std: float = 0.05,
        bias_walk: float = BIAS_WALK,
        bias_std: float = BIAS_STD,
    ) -> ForwardFusion:
        if not (accel_std > 0 and displacement_std > 0 and bias_walk > 0 and bias_std >= 0):
            raise ValueError(
                f"accel_std, displacement_std and bias_walk must be positive and bias_std not negative, got "
                f"{accel_std}, {displacement_std}, {bias_walk}, {bias_std}"
            )
        log = lambda v: jnp.log(jnp.float32(v))
        return cls(log(accel_std), log(displacement_std), log(bias_walk), float(bias_std))

    @staticmethod
    def initial(speed: Float[Array, ""], speed_std: float, dtype, bias_std: float = BIAS_STD) -> ukf.GaussianState:
        """Speed ``speed``, ``speed_std`` uncertain; no travel yet; no bias, ``bias_std``
        uncertain."""
        mean = jnp.stack([jnp.asarray(speed, dtype), jnp.zeros((), dtype), jnp.zeros((), dtype)])
        return ukf.GaussianState(mean, jnp.diag(jnp.asarray([speed_std**2, 0.0, bias_std**2], dtype)))

    def predict(
        self, state: ukf.GaussianState, accel: Float[Array, "S 3"], pitch: Float[Array, ""], dt: float
    ) -> ukf.GaussianState:
        """A frame's IMU block: the travel reset to zero, then each sample's forward specific force
        (``accel[:, 0]``) integrated at the body's ``pitch``. A missing sample (a NaN row) is
        filled with the block's mean, as the attitude filter does, and walks the speed by
        :data:`MISSING_ACCEL_STD` instead of ``accel_std``."""
        dtype = state.mean.dtype
        missing = jnp.any(jnp.isnan(accel), axis=-1)
        std = jnp.where(missing, MISSING_ACCEL_STD, jnp.exp(self.log_accel_std))
        qs = (std.astype(dtype) * dt) ** 2
        qb = (jnp.exp(self.log_bias_walk).astype(dtype) ** 2) * dt
        accel = forward_acceleration(fill_missing(accel)[:, 0], pitch).astype(dtype)
        f = jnp.array([[1.0, 0.0, -dt], [dt, 1.0, -0.5 * dt**2], [0.0, 0.0, 1.0]], dtype)
        zero = jnp.zeros((), dtype)

        def sample(carry, inputs):
            mean, cov = carry
            a, q = inputs
            mean = f @ mean + jnp.stack([a * dt, 0.5 * a * dt**2, zero])  # exact for a constant ``a``
            cov = f @ cov @ f.T + jnp.diag(jnp.stack([q, zero, qb]))
            return (mean, cov), None

        # The travel restarts at zero: its row and column go, the speed and bias keep theirs.
        keep = jnp.asarray([1.0, 0.0, 1.0], dtype)
        start = (state.mean * keep, state.cov * keep[:, None] * keep[None, :])
        (mean, cov), _ = jax.lax.scan(sample, start, (accel, qs))
        return ukf.GaussianState(mean, cov)

    def update(
        self, state: ukf.GaussianState, displacement: Float[Array, ""], use: Bool[Array, ""] | bool = True
    ) -> ukf.GaussianState:
        """Condition the travel on DPC's forward ``displacement`` (metres; unchanged where ``use``
        is False or it is not finite)."""
        dtype = state.mean.dtype
        z = jnp.asarray(displacement, dtype)
        ok = jnp.isfinite(z) & use
        z = jnp.where(ok, z, 0.0)
        innovation = z - state.mean[1]
        variance = jnp.exp(2.0 * self.log_displacement_std).astype(dtype)
        return ukf.linear_update(state, jnp.asarray(_TRAVEL, dtype), innovation, variance, ok)

    @staticmethod
    def travel(state: ukf.GaussianState) -> Float[Array, ""]:
        """The frame's forward motion (metres)."""
        return state.mean[1]


__all__ = ["BIAS_STD", "BIAS_WALK", "COLD_SPEED_STD", "MISSING_ACCEL_STD", "WARM_SPEED_STD", "ForwardFusion"]
