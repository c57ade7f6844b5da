"""The frame's turn from two sensors: DPC's rotation between the BEVs and the gyro's yaw
increment, averaged with inverse-variance weights.

A calibrated gyro turns a frame to a few hundredths of a degree (the KITTI OXTS: 0.026 deg per
frame against the ground truth after calibration, :mod:`jbevo.inertial.calibration`), while DPC's
rotation between two real BEVs scatters by a few tenths (foreshortened texture, off-ground
content) and drifts with any error of the projection's roll. :class:`YawFusion` holds one
learnable number, the log of DPC's yaw standard deviation over the gyro's; the gyro's weight is
``1 / (1 + exp(-2 r))``. Hand-set ``exp(r) = 4`` (weight 0.94): a prior that DPC's turn is a few
times noisier than a calibrated gyro's, not a value fitted on any frames.

Convention: ``rotation`` as :func:`jbevo.vision.registration.register` returns it (a positive
rotation carries the earlier BEV counter-clockwise onto the later one: the vehicle turned right),
so the gyro's yaw increment ``d`` enters as ``-d``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo.geometry.angles import wrap_angle


class YawFusion(eqx.Module):
    """Inverse-variance fusion of DPC's rotation with the gyro's yaw increment.

    Attributes:
        log_std_ratio: log of DPC's yaw standard deviation over the gyro's (per frame).
    """

    log_std_ratio: Float[Array, ""]

    @classmethod
    def create(cls, std_ratio: float = 4.0) -> YawFusion:
        if not std_ratio > 0:
            raise ValueError(f"std_ratio must be positive, got {std_ratio}")
        return cls(jnp.log(jnp.float32(std_ratio)))

    @property
    def gyro_weight(self) -> Float[Array, ""]:
        """The gyro's weight in the fused turn, in (0, 1)."""
        return jax.nn.sigmoid(2.0 * self.log_std_ratio)

    def fuse(self, rotation: Float[Array, ""], gyro_yaw: Float[Array, ""]) -> Float[Array, ""]:
        """The fused registration rotation (radians, ``register``'s sense) from DPC's ``rotation``
        and the gyro's yaw increment ``gyro_yaw`` over the same frame (NaN: DPC's alone)."""
        w = self.gyro_weight.astype(rotation.dtype)
        gap = wrap_angle(-gyro_yaw - rotation)
        return wrap_angle(rotation + jnp.where(jnp.isfinite(gap), w * jnp.nan_to_num(gap), 0.0))


__all__ = ["YawFusion"]
