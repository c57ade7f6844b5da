"""A planar odometry and pose-fix simulator (ground truth, noisy increments, noisy fixes).

It drives the localization filter in tests, benchmarks and the demo without images: a vehicle
follows a smooth random drive, the odometry reports each body-frame increment with Gaussian
noise, and a pose fix (x, y, yaw) arrives every step with Gaussian noise, missing with a given
probability (NaN rows).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.se2 import se2_compose


class PlanarSequence(NamedTuple):
    """A planar drive: ``T`` steps of increments and fixes, ``T + 1`` true poses."""

    poses: Float[Array, "T+1 3"]  #: true (x, y, yaw); poses[0] is the start
    increments: Float[Array, "T 3"]  #: noisy body-frame odometry (dx, dy, dyaw) from t to t+1
    fixes: Float[Array, "T 3"]  #: noisy pose fixes of poses[1:], NaN rows where missing


def simulate_planar_sequence(
    key: PRNGKeyArray,
    steps: int,
    *,
    speed: float = 1.0,
    yaw_rate_std: float = 0.05,
    odometry_std=(0.02, 0.01, 0.005),
    fix_std=(0.5, 0.5, 0.05),
    fix_dropout: float = 0.0,
    dtype=None,
) -> PlanarSequence:
    """Simulate ``steps`` steps of a smooth drive (metres and radians per step).

    The yaw rate is a slowly varying random walk (std ``yaw_rate_std`` rad/step, mean-reverting),
    the forward speed varies by +-30 % around ``speed`` m/step, and there is a small lateral
    slip. Deterministic for a given ``key``.
    """
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    if not 0.0 <= fix_dropout <= 1.0:
        raise ValueError(f"fix_dropout must be in [0, 1], got {fix_dropout}")
    dtype = dtype or jnp.result_type(float)
    k_rate, k_speed, k_slip, k_odo, k_fix, k_drop = jax.random.split(key, 6)

    def ou(key, std, decay):
        noise = jax.random.normal(key, (steps,), dtype) * std * jnp.sqrt(1 - decay**2)
        return jax.lax.scan(lambda s, w: (decay * s + w, decay * s + w), jnp.zeros((), dtype), noise)[1]

    yaw_rate = ou(k_rate, yaw_rate_std, 0.98)
    forward = speed * (1.0 + 0.3 * jnp.tanh(ou(k_speed, 1.0, 0.995)))
    slip = 0.02 * speed * ou(k_slip, 1.0, 0.9)
    true_inc = jnp.stack([forward, slip, yaw_rate], axis=-1)

    start = jnp.zeros(3, dtype)
    _, poses = jax.lax.scan(lambda p, d: (se2_compose(p, d), se2_compose(p, d)), start, true_inc)
    poses = jnp.concatenate([start[None], poses], axis=0)

    odo_noise = jax.random.normal(k_odo, (steps, 3), dtype) * jnp.asarray(odometry_std, dtype)
    increments = true_inc + odo_noise
    fixes = poses[1:] + jax.random.normal(k_fix, (steps, 3), dtype) * jnp.asarray(fix_std, dtype)
    fixes = fixes.at[:, 2].set(wrap_angle(fixes[:, 2]))
    dropped = jax.random.uniform(k_drop, (steps,)) < fix_dropout
    fixes = jnp.where(dropped[:, None], jnp.nan, fixes)
    return PlanarSequence(poses, increments, fixes)


__all__ = ["PlanarSequence", "simulate_planar_sequence"]
