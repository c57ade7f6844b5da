"""The forward speed, travel and bias filter: the IMU block integrated exactly (gravity's share at
the pitch, the bias, missing samples, the travel reset per frame), DPC's increment weighted
linearly, DPC's sum kept over a long drive whatever its errors' skew, a constant bias found from
DPC's increments, and its arguments checked."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.filtering import ukf
from jbevo.inertial.kinematics import GRAVITY
from jbevo.models.forward_fusion import BIAS_STD, COLD_SPEED_STD, MISSING_ACCEL_STD, WARM_SPEED_STD, ForwardFusion

pytestmark = pytest.mark.usefixtures("float64")

DT = 0.01


def block(forward, samples=10):
    accel = np.zeros((samples, 3))
    accel[:, 0] = forward
    accel[:, 2] = GRAVITY
    return jnp.asarray(accel)


def bias_share(fusion, samples=10):
    """The bias's share of the speed's variance after a block: its prior over the block and its
    walk after each sample (the walk after sample k reaches the speed through the ``samples - k``
    samples after it)."""
    walk = float(jnp.exp(fusion.log_bias_walk)) ** 2 * DT
    return (samples * DT * BIAS_STD) ** 2 + walk * DT**2 * sum(j**2 for j in range(samples))


def test_a_block_is_integrated_exactly():
    fusion = ForwardFusion.create(accel_std=0.1)
    state = fusion.initial(jnp.float64(12.0), WARM_SPEED_STD, jnp.float64)
    moved = fusion.predict(state, block(np.linspace(-1.0, 2.0, 10)), jnp.float64(0.0), DT)
    speeds = 12.0 + DT * np.cumsum(np.r_[0.0, np.linspace(-1.0, 2.0, 10)])  # before and after each sample
    travel = DT * np.sum(0.5 * (speeds[1:] + speeds[:-1]))
    np.testing.assert_allclose(moved.mean, [speeds[-1], travel, 0.0], rtol=1e-12, atol=1e-15)
    # The speed's variance grows by the accelerometer's noise per sample and the bias's share; the
    # travel's by the speed's over the block.
    expected = WARM_SPEED_STD**2 + 10 * (0.1 * DT) ** 2 + bias_share(fusion)
    assert float(moved.cov[0, 0]) == pytest.approx(expected, rel=1e-9)
    assert float(moved.cov[1, 1]) == pytest.approx((10 * DT * WARM_SPEED_STD) ** 2, rel=0.01)
    # A bias in the state is taken off every sample.
    biased = ukf.GaussianState(state.mean.at[2].set(0.5), state.cov)
    shifted = fusion.predict(biased, block(np.linspace(-1.0, 2.0, 10) + 0.5), jnp.float64(0.0), DT)
    np.testing.assert_allclose(shifted.mean, [speeds[-1], travel, 0.5], rtol=1e-12)


def test_gravity_share_and_missing_samples():
    fusion = ForwardFusion.create()
    state = fusion.initial(jnp.float64(5.0), WARM_SPEED_STD, jnp.float64)
    pitch = np.radians(2.0)  # nose down: a car at constant speed downhill reads f_x = -g sin(pitch)
    level = fusion.predict(state, block(-GRAVITY * np.sin(pitch)), jnp.float64(pitch), DT)
    np.testing.assert_allclose(level.mean, [5.0, 0.5, 0.0], rtol=1e-12, atol=1e-15)
    # A missing sample counts as the block's mean (5/9 here), as that sample measured, but with
    # the missing sample's walk.
    gap = np.array(block(np.r_[np.zeros(5), np.ones(5)]))
    gap[2] = np.nan
    filled = np.array(block(np.r_[np.zeros(5), np.ones(5)]))
    filled[2, 0] = 5.0 / 9.0
    a = fusion.predict(state, jnp.asarray(gap), jnp.float64(0.0), DT)
    b = fusion.predict(state, jnp.asarray(filled), jnp.float64(0.0), DT)
    np.testing.assert_allclose(a.mean, b.mean, rtol=1e-12)
    extra = (MISSING_ACCEL_STD**2 - float(jnp.exp(fusion.log_accel_std)) ** 2) * DT**2
    assert float(a.cov[0, 0] - b.cov[0, 0]) == pytest.approx(extra, rel=1e-5)
    # A block with no sample: gravity's share alone, and the speed grows uncertain.
    dead = fusion.predict(state, jnp.full((10, 3), jnp.nan), jnp.float64(pitch), DT)
    assert float(dead.mean[0]) == pytest.approx(5.0 + 10 * DT * GRAVITY * np.sin(pitch), rel=1e-12)
    expected = WARM_SPEED_STD**2 + 10 * (MISSING_ACCEL_STD * DT) ** 2 + bias_share(fusion)
    assert float(dead.cov[0, 0]) == pytest.approx(expected, rel=1e-9)


def test_the_travel_restarts_every_frame():
    fusion = ForwardFusion.create()
    state = fusion.initial(jnp.float64(10.0), WARM_SPEED_STD, jnp.float64)
    first = fusion.predict(state, block(0.0), jnp.float64(0.0), DT)
    second = fusion.predict(first, block(0.0), jnp.float64(0.0), DT)
    np.testing.assert_allclose(second.mean, [10.0, 1.0, 0.0], rtol=1e-12, atol=1e-15)
    assert float(second.cov[0, 1]) > 0  # the travel follows the speed again
    assert float(second.cov[1, 2]) < 0  # and the bias, against it


def test_dpc_increments_find_a_constant_bias():
    """At a constant 10 m/s an accelerometer reading 0.1 m/s^2 too high (or a pitch off by
    0.6 deg) integrates to 1 m/s of speed error in 10 s; DPC's exact increments (5 % noise) find
    the bias, and the frame's travel stays within a centimetre."""

    def drive(fusion):
        state = fusion.initial(jnp.float64(10.0), WARM_SPEED_STD, jnp.float64, fusion.bias_std)
        frame = jax.jit(lambda s: fusion.update(fusion.predict(s, block(0.1), jnp.float64(0.0), DT), jnp.float64(1.0)))
        for _ in range(300):  # 30 s
            state = frame(state)
        return state

    state = drive(ForwardFusion.create())
    assert float(state.mean[2]) == pytest.approx(0.1, rel=0.1)
    assert abs(float(ForwardFusion.travel(state)) - 1.0) < 0.01
    assert abs(float(state.mean[0]) - 10.0) < 0.1
    # Without the bias state the accelerometer, trusted, carries the speed away.
    unbiased = drive(ForwardFusion.create(bias_walk=1e-9, bias_std=0.0))
    assert float(unbiased.mean[0]) - 10.0 > 0.5 and float(ForwardFusion.travel(unbiased)) - 1.0 > 0.05


def test_dpc_pulls_the_travel_linearly():
    fusion = ForwardFusion.create(accel_std=0.5, displacement_std=0.05)
    state = fusion.initial(jnp.float64(10.0), 1.0, jnp.float64)
    predicted = fusion.predict(state, block(0.0), jnp.float64(0.0), DT)  # travel 1 m, 0.1 m uncertain
    pull = lambda z: float((ForwardFusion.travel(fusion.update(predicted, jnp.float64(z))) - 1.0) / (z - 1.0))
    # The gain of a 5 cm measurement against a 10 cm prediction, whatever the increment: above or
    # below the prediction, near or gross.
    prior = float(predicted.cov[1, 1])
    for z in (1.02, 0.98, 1.5, 0.5):
        assert pull(z) == pytest.approx(prior / (prior + 0.05**2), rel=1e-6)  # float32 parameters
    # The speed moves with the travel (they are correlated through the block).
    assert float(ForwardFusion.travel(fusion.update(predicted, jnp.float64(1.02)))) > 1.0
    assert float(fusion.update(predicted, jnp.float64(1.02)).mean[0]) > 10.0
    for skipped in (fusion.update(predicted, jnp.float64(np.nan)), fusion.update(predicted, jnp.float64(1.2), use=False)):
        np.testing.assert_array_equal(skipped.mean, predicted.mean)


def test_the_fused_distance_keeps_dpcs_over_a_long_drive():
    """At a steady 10 m/s, DPC's increments 4 % short with skewed scatter (most a little low, a few
    far high: 8 cm RMS): over 2000 frames the fused travel sums to DPC's within 0.1 % and scatters
    less about its own mean than DPC does."""
    rng = np.random.default_rng(3)
    skewed = rng.exponential(0.08, 2000) - 0.08
    increments = 0.96 + skewed
    fusion = ForwardFusion.create()
    frame = jax.jit(lambda s, z: fusion.update(fusion.predict(s, block(0.0), jnp.float64(0.0), DT), z))
    state, fused = fusion.initial(jnp.float64(10.0), WARM_SPEED_STD, jnp.float64, fusion.bias_std), []
    for z in increments:
        state = frame(state, jnp.float64(z))
        fused.append(float(ForwardFusion.travel(state)))
    fused = np.asarray(fused[200:])  # after the warm start's 1 m/frame has given way to DPC's
    assert fused.mean() == pytest.approx(increments[200:].mean(), rel=1e-3)
    assert fused.std() < 0.5 * increments[200:].std()


def test_cold_start_is_vague_and_arguments_are_checked():
    assert COLD_SPEED_STD > 10 * WARM_SPEED_STD
    with pytest.raises(ValueError, match="positive"):
        ForwardFusion.create(accel_std=0.0)
    with pytest.raises(ValueError, match="positive"):
        ForwardFusion.create(displacement_std=-0.1)
    with pytest.raises(ValueError, match="bias_walk"):
        ForwardFusion.create(bias_walk=0.0)
