"""The yaw fusion (jbevo.models.yaw_fusion): inverse-variance weights, the gyro's sense against
register's, wrapping across +-pi, DPC alone where the gyro has nothing, and its gradient."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.models.yaw_fusion import YawFusion


def test_weights_are_inverse_variance():
    fusion = YawFusion.create(std_ratio=4.0)
    assert float(fusion.gyro_weight) == pytest.approx(16 / 17, rel=1e-6)
    # DPC's rotation r = -(the turn): a gyro turn of +0.01 rad agrees with r = -0.01.
    assert float(fusion.fuse(jnp.float32(-0.01), jnp.float32(0.01))) == pytest.approx(-0.01, abs=1e-8)
    fused = float(YawFusion.create(1.0).fuse(jnp.float32(0.0), jnp.float32(0.02)))
    assert fused == pytest.approx(-0.01, abs=1e-7)  # equal variances: the midpoint
    with pytest.raises(ValueError, match="positive"):
        YawFusion.create(0.0)


def test_wraps_and_falls_back_to_dpc():
    fusion = YawFusion.create(1.0)
    # DPC at +179 deg, the gyro's turn at +179 deg (rotation -179): the midpoint is 180, not 0.
    fused = float(fusion.fuse(jnp.float32(np.radians(179.0)), jnp.float32(np.radians(179.0))))
    assert abs(abs(np.degrees(fused)) - 180.0) < 1e-3
    assert float(fusion.fuse(jnp.float32(0.3), jnp.float32(jnp.nan))) == pytest.approx(0.3)


def test_gradient_matches_the_closed_form(float64):
    fusion = YawFusion(jnp.float64(0.3))
    grad = jax.grad(lambda f: f.fuse(jnp.float64(0.01), jnp.float64(-0.03)))(fusion).log_std_ratio
    w = 1 / (1 + np.exp(-0.6))
    # fused = r + w (g - r) with g = 0.03, r = 0.01; dw/dlog = 2 w (1 - w).
    assert float(grad) == pytest.approx(0.02 * 2 * w * (1 - w), rel=1e-9)
