"""IMU simulator: analytic motion gives the analytic gyro and specific force; noise statistics
follow the preset; KITTI poses become z-up body poses."""

import numpy as np
import pytest

from jbevo.data.kitti_frames import body_poses_from_kitti
from jbevo.data.synthetic.imu import NOISELESS, ImuNoise, simulate_imu
from jbevo.geometry.euler import euler_zyx, rotation_zyx
from jbevo.inertial.kinematics import GRAVITY


def circle_drive(n: int = 601, dt: float = 0.1, speed: float = 10.0, yaw_rate: float = 0.2, pitch: float = 0.03):
    """Constant speed and yaw rate, constant pitch (nose down), on a z-up world."""
    t = dt * np.arange(n)
    yaw = yaw_rate * t
    radius = speed / yaw_rate
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = rotation_zyx(np.stack([yaw, np.full(n, pitch), np.zeros(n)], -1))
    poses[:, 0, 3] = radius * np.sin(yaw)
    poses[:, 1, 3] = radius * (1 - np.cos(yaw))
    return t, poses


def test_circle_gives_the_analytic_gyro_and_specific_force():
    speed, yaw_rate, pitch = 10.0, 0.2, 0.03
    t, poses = circle_drive(speed=speed, yaw_rate=yaw_rate, pitch=pitch)
    d = simulate_imu(t, poses, noise=NOISELESS, smoothing=None)
    inner = slice(200, -200)  # away from the spline's end conditions
    # Body rates of a constant yaw rate seen from a pitched body: R_y(pitch)^T (0, 0, wz).
    gyro = np.array([-np.sin(pitch) * yaw_rate, 0.0, np.cos(pitch) * yaw_rate])
    np.testing.assert_allclose(d.gyro[inner], np.broadcast_to(gyro, d.gyro[inner].shape), atol=1e-5)
    world = np.array([0.0, speed * yaw_rate, GRAVITY])  # centripetal (left) plus gravity
    expected = rotation_zyx(np.array([0.0, pitch, 0.0])).T @ world
    # The world acceleration turns with the heading; in the body frame it is constant.
    np.testing.assert_allclose(d.accel[inner], np.broadcast_to(expected, d.accel[inner].shape), atol=2e-3)
    np.testing.assert_allclose(d.frame_euler[:, 1], pitch, atol=1e-12)


def test_euler_round_trip_and_kitti_frames():
    rng = np.random.default_rng(0)
    e = np.stack([rng.uniform(-3, 3, 50), rng.uniform(-1.2, 1.2, 50), rng.uniform(-3, 3, 50)], -1)
    np.testing.assert_allclose(euler_zyx(rotation_zyx(e)), e, atol=1e-12)
    # KITTI camera 0 moving forward along its z with identity rotation: body moves along +x, level.
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, 2, 3] = [0.0, 1.0, 2.0]
    body = body_poses_from_kitti(poses)
    np.testing.assert_allclose(body[:, :3, 3], [[0, 0, 0], [1, 0, 0], [2, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(body[0, :3, :3], np.eye(3), atol=1e-12)


def test_noise_follows_the_preset_and_the_seed():
    t = 0.1 * np.arange(3001)
    poses = np.tile(np.eye(4), (len(t), 1, 1))
    noise = ImuNoise(1e-3, 0.0, 2e-2, 0.0)
    a = simulate_imu(t, poses, noise=noise, seed=1)
    b = simulate_imu(t, poses, noise=noise, seed=1)
    np.testing.assert_array_equal(a.gyro, b.gyro)
    assert np.std(a.gyro) == pytest.approx(1e-3 * 10.0, rel=0.03)  # density * sqrt(100 Hz)
    assert np.std(a.accel - [0, 0, GRAVITY]) == pytest.approx(2e-2 * 10.0, rel=0.03)
    with pytest.raises(ValueError, match="body_poses must have shape"):
        simulate_imu(t, poses[:-1])
    with pytest.raises(ValueError, match="smoothing spline needs at least 5 poses, got 4"):
        simulate_imu(t[:4], poses[:4])
    assert simulate_imu(t[:4], poses[:4], smoothing=None).gyro.shape[0] > 0  # interpolating: no minimum


def test_the_biases_are_returned_as_added():
    """``gyro_bias`` and ``accel_bias`` are exactly what the samples carry besides white noise,
    and the random walk grows as the preset says (std = random_walk * sqrt(t))."""
    t, poses = circle_drive(n=301)
    clean = simulate_imu(t, poses, noise=NOISELESS, smoothing=None)
    walk = ImuNoise(0.0, 1e-3, 0.0, 3e-3, gyro_turn_on_bias=0.01, accel_turn_on_bias=0.05)
    d = simulate_imu(t, poses, noise=walk, seed=3, smoothing=None)
    np.testing.assert_allclose(d.gyro - d.gyro_bias, clean.gyro, atol=1e-12)
    np.testing.assert_allclose(d.accel - d.accel_bias, clean.accel, atol=1e-12)
    runs = [simulate_imu(t, poses, noise=ImuNoise(0.0, 0.0, 0.0, 3e-3), seed=s, smoothing=None) for s in range(40)]
    spread = np.std([r.accel_bias[-1] for r in runs])
    assert spread == pytest.approx(3e-3 * np.sqrt(t[-1]), rel=0.25)


def test_kitti_oxts_preset_matches_its_record():
    """The preset is the RMS over axes of what benchmarks/attitude_real.py measured (2 digits)."""
    import json
    from pathlib import Path

    from jbevo.data.synthetic.imu import KITTI_OXTS

    noise = json.loads((Path(__file__).parents[3] / "benchmarks" / "results" / "attitude_real.json").read_text())["imu_noise"]

    def rms(values):
        return float(np.sqrt(np.mean(np.square(values))))

    expected = {
        "gyro_noise_density": rms(noise["gyro_noise_density_rad_s_sqrt_hz"]),
        "gyro_random_walk": rms(noise["gyro_random_walk_bound_rad_s2_sqrt_hz"]),
        "accel_noise_density": rms(noise["accel_noise_density_m_s2_sqrt_hz"]),
        "accel_random_walk": noise["adis16448"]["accel_random_walk_m_s3_sqrt_hz"],
        "gyro_turn_on_bias": rms(noise["gyro_bias_spread_rad_s"]),
        "accel_turn_on_bias": rms(noise["accel_bias_spread_m_s2"][:2]),
    }
    for name, value in expected.items():
        assert getattr(KITTI_OXTS, name) == pytest.approx(value, rel=0.05), name
