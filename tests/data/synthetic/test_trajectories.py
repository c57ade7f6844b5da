"""Trajectories and the IMU they drive: procedural drives are car-like, KITTI drives keep the real
planar motion without the road grade, and the noiseless IMU integrates back to the trajectory."""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from jbevo.data.kitti_frames import CAMERA_HEIGHT
from jbevo.data.pose_files import read_kitti
from jbevo.data.synthetic.imu import NOISELESS, simulate_imu
from jbevo.data.synthetic.trajectories import (
    kitti_drive,
    procedural_drive,
    speed_targets,
)
from jbevo.geometry.euler import euler_zyx
from jbevo.inertial.kinematics import GRAVITY


def test_procedural_drive_is_deterministic_and_car_like():
    times, poses = procedural_drive(3, 601)
    times2, poses2 = procedural_drive(3, 601)
    np.testing.assert_array_equal(poses, poses2)
    assert not np.allclose(poses, procedural_drive(4, 601)[1])
    np.testing.assert_allclose(np.diff(times), 0.1)
    step = np.linalg.norm(np.diff(poses[:, :2, 3], axis=0), axis=1)
    assert step.max() < 1.5 and step.sum() > 100  # under 15 m/s, moving
    euler = euler_zyx(poses[:, :3, :3])
    assert 0.3 < np.degrees(euler[:, 1]).std() < 2.5 and 0.3 < np.degrees(euler[:, 2]).std() < 2.5
    assert np.abs(poses[:, 2, 3] - CAMERA_HEIGHT).max() < 0.06
    # no side slip: the velocity points along the heading
    heading = np.arctan2(np.diff(poses[:, 1, 3]), np.diff(poses[:, 0, 3]))
    moving = step > 0.2
    slip = np.angle(np.exp(1j * (heading - euler[:-1, 0] - 0.5 * np.diff(np.unwrap(euler[:, 0])))))
    assert np.abs(slip[moving]).max() < np.radians(3)


def test_every_speed_target_is_written_and_a_long_stop_lasts_its_length():
    """A stop (2-5 s) drawn after a shorter hold (4-12 s) used to leave samples unwritten (memory
    garbage: drives that differed between two identical calls). Replaying the draws shows each
    stop whole at zero and every sample finite, on the seeds whose stops outlast their holds."""
    dt, n = 0.01, 60_000
    seen_long_stop = 0
    for seed in range(40):
        target = speed_targets(np.random.default_rng(seed), n, dt, (4.0, 14.0), 0.5)
        assert np.all(np.isfinite(target)) and np.all((target == 0) | ((target >= 4) & (target <= 14)))
        rng, i = np.random.default_rng(seed), 0
        while i < n:
            hold = int(rng.uniform(4.0, 12.0) / dt)
            stop = rng.random() < 0.5 and i > 0
            length = int(rng.uniform(2.0, 5.0) / dt) if stop else hold
            if not stop:
                rng.uniform(4.0, 14.0)
            elif length > hold:
                seen_long_stop += 1
                assert np.all(target[i : i + length] == 0.0)
            i += length
    assert seen_long_stop > 0


def _quat_rate(q, w):
    """d/dt of the quaternion (x, y, z, w) of R_world_body for body rate ``w``."""
    x, y, z, s = q
    return 0.5 * np.array(
        [
            s * w[0] + y * w[2] - z * w[1],
            s * w[1] + z * w[0] - x * w[2],
            s * w[2] + x * w[1] - y * w[0],
            -x * w[0] - y * w[1] - z * w[2],
        ]
    )


def _integrate(imu, dt):
    """Strapdown integration of the IMU samples: RK4 on the attitude quaternion (rates between
    samples from a cubic spline through them), then the world acceleration integrated with
    Simpson-like trapezoids."""
    gyro = CubicSpline(imu.times, imu.gyro)
    q = Rotation.from_euler("ZYX", imu.euler[0]).as_quat()
    rotations = [q]
    for t in imu.times[:-1]:
        k1 = _quat_rate(q, gyro(t))
        k2 = _quat_rate(q + 0.5 * dt * k1, gyro(t + 0.5 * dt))
        k3 = _quat_rate(q + 0.5 * dt * k2, gyro(t + 0.5 * dt))
        k4 = _quat_rate(q + dt * k3, gyro(t + dt))
        q = q + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        q = q / np.linalg.norm(q)
        rotations.append(q)
    rotations = Rotation.from_quat(np.array(rotations))
    a = rotations.apply(imu.accel) - np.array([0.0, 0.0, GRAVITY])
    v = imu.velocity[0] + np.concatenate([[np.zeros(3)], np.cumsum(0.5 * (a[1:] + a[:-1]) * dt, axis=0)])
    p = imu.position[0] + np.concatenate([[np.zeros(3)], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt, axis=0)])
    return p, rotations


def test_noiseless_imu_integrates_back_to_the_trajectory_over_60_s():
    times, poses = procedural_drive(1, 601)
    imu = simulate_imu(times, poses, noise=NOISELESS, smoothing=None)
    positions, rotations = _integrate(imu, 0.01)
    assert np.linalg.norm(positions - imu.position, axis=1).max() < 0.5
    truth = Rotation.from_euler("ZYX", imu.euler)
    angle = (rotations.inv() * truth).magnitude().max()
    assert np.degrees(angle) < 0.05


def test_kitti_drive_keeps_planar_motion_and_removes_the_grade(reference_data):
    kitti = read_kitti(reference_data / "kitti_odom" / "gt_poses" / "07.txt").poses
    times, poses = kitti_drive(kitti)
    assert len(poses) == len(kitti) and times[1] == pytest.approx(0.1)
    # planar path: KITTI x (right) and z (forward) are the body-world y (negated) and x
    np.testing.assert_allclose(poses[:, 0, 3], kitti[:, 2, 3], atol=1e-9)
    np.testing.assert_allclose(poses[:, 1, 3], -kitti[:, 0, 3], atol=1e-9)
    euler = euler_zyx(poses[:, :3, :3])
    assert np.abs(np.degrees(euler[:, 1:])).max() < 4.0 and np.abs(np.mean(euler[:, 1:], axis=0)).max() < np.radians(0.2)
    assert np.abs(poses[:, 2, 3] - CAMERA_HEIGHT).max() < 0.3
    with pytest.raises(ValueError, match="kitti_poses"):
        kitti_drive(kitti[:1])
