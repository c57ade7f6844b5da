"""The pitch/roll DUKF: kinematics and tilt against the simulator's conventions, filtering on a
simulated drive (with and without motion compensation), missing samples, gradients, bad input."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.imu import ADIS16448, planar_body_velocity, simulate_imu
from jbevo.geometry.euler import body_rates, rotation_zyx
from jbevo.inertial.attitude_filter import AttitudeFilter
from jbevo.inertial.kinematics import (
    GRAVITY,
    accel_tilt,
    euler_rates,
    forward_acceleration,
    tilt_measurements,
)


def test_euler_rates_invert_the_simulators_body_rates(float64):
    rng = np.random.default_rng(0)
    e = np.stack([rng.uniform(-3, 3, 20), rng.uniform(-0.5, 0.5, 20), rng.uniform(-0.5, 0.5, 20)], -1)
    e_dot = rng.normal(size=(20, 3))
    omega = body_rates(e, e_dot)
    pitch_dot, roll_dot = euler_rates(jnp.asarray(e[:, 1]), jnp.asarray(e[:, 2]), jnp.asarray(omega))
    np.testing.assert_allclose(pitch_dot, e_dot[:, 1], atol=1e-12)
    np.testing.assert_allclose(roll_dot, e_dot[:, 2], atol=1e-12)


def test_tilt_of_gravity_is_exact(float64):
    rng = np.random.default_rng(1)
    e = np.stack([rng.uniform(-3, 3, 20), rng.uniform(-1, 1, 20), rng.uniform(-1, 1, 20)], -1)
    f = np.einsum("nji,j->ni", rotation_zyx(e), [0.0, 0.0, GRAVITY])
    np.testing.assert_allclose(accel_tilt(jnp.asarray(f)), e[:, 1:], atol=1e-12)


def test_forward_acceleration_is_the_body_x_share_of_the_acceleration(float64):
    # Specific force f = R^T (a + g z); f_x + g sin(pitch) must leave the body-x part of a only.
    rng = np.random.default_rng(2)
    e = np.stack([rng.uniform(-3, 3, 20), rng.uniform(-0.5, 0.5, 20), rng.uniform(-0.5, 0.5, 20)], -1)
    a = rng.normal(size=(20, 3))
    r = rotation_zyx(e)
    f = np.einsum("nji,nj->ni", r, a + [0.0, 0.0, GRAVITY])
    expected = np.einsum("nji,nj->ni", r, a)[:, 0]
    np.testing.assert_allclose(forward_acceleration(jnp.asarray(f[:, 0]), jnp.asarray(e[:, 1])), expected, atol=1e-12)


def wobbly_drive(seconds: float = 60.0, seed: int = 0):
    """A car-like drive: speed changes, turns, suspension pitch/roll of ~1-2 deg (z-up world)."""
    t = np.arange(0.0, seconds + 1e-9, 0.1)
    speed = 8 + 3 * np.sin(0.15 * t)
    yaw = np.cumsum(0.25 * np.sin(0.1 * t + seed) * 0.1)
    pitch = np.radians(1.5) * np.sin(0.9 * t) + np.radians(0.5) * np.sin(2.3 * t)
    roll = np.radians(2.0) * np.sin(0.7 * t + 1.0)
    x = np.cumsum(speed * np.cos(yaw) * 0.1)
    y = np.cumsum(speed * np.sin(yaw) * 0.1)
    poses = np.tile(np.eye(4), (len(t), 1, 1))
    poses[:, :3, :3] = rotation_zyx(np.stack([yaw, pitch, roll], -1))
    poses[:, 0, 3], poses[:, 1, 3] = x, y
    d = simulate_imu(t, poses, noise=ADIS16448, seed=seed)
    n = len(t) - 1
    vb = planar_body_velocity(d)[: n * 10]
    gyro = d.gyro[: n * 10].reshape(n, 10, 3)
    accel = d.accel[: n * 10].reshape(n, 10, 3)
    velocity = jnp.asarray(vb.reshape(n, 10, 2).mean(1))
    return jnp.asarray(gyro), jnp.asarray(accel), velocity, d.frame_euler[1:, 1:], jnp.asarray(d.frame_euler[0, 1:])


@pytest.fixture(scope="module")
def drive():
    return wobbly_drive()


def rmse_deg(est, truth):
    return float(np.degrees(np.sqrt(np.mean((np.asarray(est) - truth) ** 2))))


def test_filter_beats_accelerometer_tilt_and_compensation_helps(drive):
    gyro, accel, velocity, truth, initial = drive
    run = eqx.filter_jit(lambda f, c: f(gyro, accel, initial, c))
    accel_only = rmse_deg(tilt_measurements(accel), truth)
    plain = rmse_deg(run(AttitudeFilter.create(), None), truth)
    compensated = rmse_deg(run(AttitudeFilter.create(gyro_bias=True), velocity), truth)
    assert plain < accel_only / 2
    assert compensated < plain / 3 and compensated < 0.3, (accel_only, plain, compensated)


def test_missing_samples_are_skipped(drive):
    gyro, accel, velocity, truth, initial = drive
    f = AttitudeFilter.create()
    clean = f(gyro, accel, initial)
    rng = np.random.default_rng(2)
    holes = jnp.asarray(rng.random(gyro.shape[:2]) < 0.1)[..., None]
    holed_gyro = jnp.where(holes, jnp.nan, gyro)
    holed_accel = jnp.where(holes, jnp.nan, accel).at[5].set(jnp.nan)  # frame 5: no accel at all
    est = f(holed_gyro, holed_accel, initial)
    assert np.all(np.isfinite(est))
    assert rmse_deg(est, np.asarray(clean)) < 0.1
    assert np.isnan(np.asarray(tilt_measurements(holed_accel))[5]).all()


def test_gradients_match_finite_differences(float64, drive):
    gyro, accel, velocity, truth, initial = drive
    gyro, accel, velocity, truth = gyro[:100], accel[:100], velocity[:100], jnp.asarray(truth[:100])

    def loss(log_std):
        f = AttitudeFilter.create(gyro_bias=True)
        f = eqx.tree_at(lambda f: f.measurement_noise.log_std, f, log_std)
        return jnp.mean((f(gyro, accel, initial, velocity) - truth) ** 2)

    x = jnp.log(jnp.array([0.02, 0.03]))
    g = jax.grad(loss)(x)
    assert np.all(np.isfinite(g)) and np.all(g != 0)
    eps = 1e-5
    for i in range(2):
        e = jnp.zeros(2).at[i].set(eps)
        fd = (loss(x + e) - loss(x - e)) / (2 * eps)
        assert float(g[i]) == pytest.approx(float(fd), rel=1e-4)


def test_bad_input_is_named(as_users_run):
    f = AttitudeFilter.create()
    with pytest.raises(ValueError, match=r"\(T, S, 3\)"):
        f(jnp.zeros((5, 10, 3)), jnp.zeros((5, 10, 2)))
    with pytest.raises(ValueError, match="velocity must have shape"):
        f(jnp.zeros((5, 10, 3)), jnp.zeros((5, 10, 3)) + jnp.array([0, 0, 9.8]), velocity=jnp.zeros((5, 3)))


def test_speed_aided_filter_holds_pitch_through_accelerations():
    """Fed the true speed, the speed-aided filter keeps pitch and roll within a few tenths of a
    degree on a procedural drive that starts at rest and accelerates at up to 2 m/s^2, where the
    accelerometer's own tilt is off by degrees."""
    from jbevo.data.synthetic.imu import ADIS16448, simulate_imu
    from jbevo.data.synthetic.trajectories import procedural_drive
    from jbevo.inertial.speed_aided import AttitudeState, SpeedAidedAttitude

    times, poses = procedural_drive(4, 301)
    imu = simulate_imu(times, poses, noise=ADIS16448, seed=1, smoothing=None)
    t, s = 300, 10
    gyro = jnp.asarray(imu.gyro.reshape(t, s, 3), jnp.float32)
    accel = jnp.asarray(imu.accel.reshape(t, s, 3), jnp.float32)
    speed = np.linalg.norm(np.diff(poses[:, :2, 3], axis=0), axis=1) / 0.1  # per frame, like odometry
    truth = imu.frame_euler[1:, 1:]
    f = SpeedAidedAttitude.create(0.01)
    first = np.asarray(accel[0]).mean(0)
    tilt0 = jnp.asarray([-np.arctan2(first[0], np.hypot(first[1], first[2])), np.arctan2(first[1], first[2])], jnp.float32)
    state = AttitudeState.initial(tilt0, jnp.float32(0.0), 0.03, 0.005, 0.1)

    @jax.jit
    def run(state):
        def step(st, x):
            g, a, v = x
            st = f.update_lateral_tilt(f.update_speed(f.predict(st, g, a), v), g, a).astype(jnp.float32)
            return st, st

        return jax.lax.scan(step, state, (gyro, accel, jnp.asarray(speed, jnp.float32)))[1]

    beliefs = run(state)
    estimate = np.asarray(beliefs.pitch_roll)
    err = np.degrees(np.sqrt(np.mean((estimate[20:] - truth[20:]) ** 2, axis=0)))
    tilt = np.asarray(accel).mean(1)
    tilt_pitch = -np.arctan2(tilt[:, 0], np.hypot(tilt[:, 1], tilt[:, 2]))
    tilt_err = np.degrees(np.sqrt(np.mean((tilt_pitch - truth[:, 0]) ** 2)))
    assert tilt_err > 2.0
    print("speed-aided pitch, roll RMSE (deg):", err, "tilt-only pitch RMSE:", tilt_err)
    assert err[0] < 0.3 and err[1] < 0.3, err
    # Offline, the RTS smoother over the same beliefs uses the frames after each one too.
    smoothed = np.asarray(jax.jit(lambda b, g, a: f.smooth(b, g, a))(beliefs, gyro, accel).pitch_roll)
    smoothed_err = np.degrees(np.sqrt(np.mean((smoothed[20:] - truth[20:]) ** 2, axis=0)))
    print("smoothed pitch, roll RMSE (deg):", smoothed_err)
    assert np.all(smoothed_err < 0.8 * err), (smoothed_err, err)
    with pytest.raises(ValueError, match="must share T"):
        f.smooth(beliefs, gyro[1:], accel[1:])


def test_a_missing_gyro_block_widens_the_attitude_by_the_assumed_rate():
    from jbevo.inertial.speed_aided import AttitudeState, SpeedAidedAttitude

    rate = np.radians(1.5)
    plain, widening = SpeedAidedAttitude.create(0.01), SpeedAidedAttitude.create(0.01, gap_rate_std=rate)
    state = AttitudeState.initial(jnp.asarray([0.01, -0.02], jnp.float32), jnp.float32(5.0), 0.003, 0.005, 0.1)
    level = jnp.tile(jnp.asarray([0.1, 0.0, 9.80665], jnp.float32), (10, 1))
    gyro = jnp.tile(jnp.asarray([0.01, -0.02, 0.1], jnp.float32), (10, 1))
    missing = jnp.full((10, 3), jnp.nan, jnp.float32)
    # A whole block missing: the attitude is held, and only pitch and roll widen, by the frame's worth.
    a, b = plain.predict(state, missing, missing), widening.predict(state, missing, missing)
    np.testing.assert_array_equal(np.asarray(a.mean), np.asarray(b.mean))
    np.testing.assert_allclose(np.asarray(b.pitch_roll), np.asarray(state.pitch_roll), atol=1e-7)
    grow = np.array(b.cov - a.cov)
    np.testing.assert_allclose(np.diag(grow)[:2], (10 * 0.01 * rate) ** 2, rtol=1e-3)
    grow[0, 0] = grow[1, 1] = 0.0
    np.testing.assert_allclose(grow, 0.0, atol=1e-12)
    # Not widened when told not to (BEVO's frame 0), and measured blocks, whole or padded with
    # missing rows, are predicted as without it.
    np.testing.assert_array_equal(np.asarray(widening.predict(state, missing, missing, widen=False).cov), np.asarray(a.cov))
    padded = gyro.at[5:].set(jnp.nan)
    for g in (gyro, padded):
        a, b = plain.predict(state, g, level), widening.predict(state, g, level)
        np.testing.assert_array_equal(np.asarray(a.cov), np.asarray(b.cov))
        np.testing.assert_array_equal(np.asarray(a.mean), np.asarray(b.mean))
    with pytest.raises(ValueError, match="gap_rate_std must be non-negative"):
        SpeedAidedAttitude.create(0.01, gap_rate_std=-1.0)


def test_a_widened_attitude_recovers_faster_after_an_imu_gap():
    """A car at 5 m/s on a level road rolls by 0.5 deg while its IMU is missing for 12 frames; the
    accelerometer then shows the new roll. Widened through the gap, the filter's roll is nearer
    the truth in the frames after it than that of a filter that holds its belief as certain as
    before."""
    from jbevo.inertial.speed_aided import AttitudeState, SpeedAidedAttitude

    before, after = 0.0, np.radians(0.5)
    frames, gap = 40, slice(10, 22)
    roll = np.where(np.arange(frames) < gap.start, before, after)
    gravity = np.stack([np.zeros(frames), 9.80665 * np.sin(roll), 9.80665 * np.cos(roll)], -1)
    accel = jnp.asarray(np.repeat(gravity[:, None], 10, 1), jnp.float32).at[gap].set(jnp.nan)
    gyro = jnp.zeros((frames, 10, 3), jnp.float32).at[gap].set(jnp.nan)
    state = AttitudeState.initial(jnp.zeros(2, jnp.float32), jnp.float32(5.0), 0.003, 0.005, 0.1)

    def run(f):
        def step(st, x):
            g, a = x
            st = f.update_lateral_tilt(f.update_speed(f.predict(st, g, a), jnp.float32(5.0)), g, a).astype(jnp.float32)
            return st, st.roll

        return np.degrees(np.asarray(jax.jit(lambda s: jax.lax.scan(step, s, (gyro, accel))[1])(state)))

    held, widened = (run(SpeedAidedAttitude.create(0.01, gap_rate_std=r)) for r in (0.0, np.radians(1.5)))
    # Through the gap both hold the roll of before it.
    np.testing.assert_allclose(held[gap], 0.0, atol=1e-4)
    np.testing.assert_allclose(widened[gap], 0.0, atol=1e-4)
    later = slice(gap.stop, gap.stop + 5)
    held_err, widened_err = (np.sqrt(np.mean((r[later] - 0.5) ** 2)) for r in (held, widened))
    assert widened_err < 0.85 * held_err, (widened_err, held_err)
