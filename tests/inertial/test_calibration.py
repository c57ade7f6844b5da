"""IMU calibration: a known mounting, time offset, gyro scale, biases and world tilt put into a
noiseless simulated drive are recovered; on the real KITTI IMU (reference data) the estimates
agree across drives and with KITTI's published calibration chain."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jbevo.data.imu_stream import ImuStream
from jbevo.data.synthetic.imu import NOISELESS, simulate_imu
from jbevo.data.synthetic.trajectories import procedural_drive
from jbevo.inertial import calibration as cal

MOUNTING_DEG = np.array([0.4, -0.7, 1.2])
OFFSET_S = -0.058
GYRO_SCALE = 1.006
GYRO_BIAS = np.radians([0.01, -0.02, 0.015])
ACCEL_BIAS = np.array([0.05, -0.03, 0.0])
TILT = Rotation.from_rotvec(np.radians([1.5, -2.0, 0.0])).as_matrix()  # level world -> truth world


def _drive(seed: int, frames: int = 900) -> cal.CalibrationDrive:
    t, body = procedural_drive(seed, frames)
    imu = simulate_imu(t, body, rate_hz=100.0, noise=NOISELESS, smoothing=None)
    r_ib = Rotation.from_rotvec(np.radians(MOUNTING_DEG)).as_matrix().T
    stream = ImuStream(
        imu.times - OFFSET_S,  # stamped earlier than taken: stamp + offset = time
        imu.gyro @ r_ib.T / GYRO_SCALE + GYRO_BIAS,
        imu.accel @ r_ib.T + ACCEL_BIAS,
    )
    truth = np.array(body)
    truth[:, :3, :3] = TILT @ truth[:, :3, :3]
    truth[:, :3, 3] = truth[:, :3, 3] @ TILT.T
    return cal.CalibrationDrive(t, truth, stream)


@pytest.fixture(scope="module")
def drives():
    return [_drive(1), _drive(2)]


@pytest.fixture(scope="module")
def calibration(drives):
    return cal.calibrate(drives, groups=4)


def test_recovers_a_known_mounting_offset_scale_and_biases(calibration):
    np.testing.assert_allclose(calibration.rotation_deg, MOUNTING_DEG, atol=0.01)
    assert calibration.time_offset_s == pytest.approx(OFFSET_S, abs=1e-3)
    assert calibration.gyro_scale == pytest.approx(GYRO_SCALE, abs=1e-3)
    np.testing.assert_allclose(calibration.gyro_bias, GYRO_BIAS, atol=np.radians(0.002))
    np.testing.assert_allclose(calibration.accel_bias, ACCEL_BIAS, atol=0.005)
    assert calibration.std is not None and np.all(calibration.std.rotation_deg < 0.05)


def test_recovers_the_world_tilt_and_levels_the_truth(drives, calibration):
    gravity = cal.gravity_up(drives[0], calibration)
    true_up = TILT @ np.array([0.0, 0.0, 1.0])
    angle = np.degrees(np.arccos(np.clip(gravity.up @ true_up, -1, 1)))
    assert angle < 0.01
    assert gravity.tilt_deg == pytest.approx(np.degrees(np.arccos(true_up[2])), abs=0.01)
    level = cal.level_poses(drives[0].body_poses, gravity.up)
    t, body = procedural_drive(1, 900)
    err = Rotation.from_matrix(np.einsum("nji,njk->nik", level[:, :3, :3], body[:, :3, :3])).magnitude()
    # The level world keeps the heading up to the tilt's own small yaw (the smallest rotation).
    assert np.degrees(err).max() < 0.05


def test_applied_calibration_gives_the_body_rates(drives, calibration):
    d = drives[0]
    body = cal.apply(d.imu, calibration)
    t, poses = procedural_drive(1, 900)
    truth = simulate_imu(t, poses, rate_hz=100.0, noise=NOISELESS, smoothing=None)
    inside = slice(10, -10)
    np.testing.assert_allclose(body.times[inside], truth.times[inside], atol=1e-3)
    np.testing.assert_allclose(body.gyro[inside], truth.gyro[inside], rtol=2e-3, atol=np.radians(0.005))


def test_rejects_bad_drives(drives):
    d = drives[0]
    with pytest.raises(ValueError, match="at least one drive"):
        cal.calibrate([])
    with pytest.raises(ValueError, match="body_poses must have shape"):
        cal.calibrate([d._replace(body_poses=d.body_poses[:-1])])
    with pytest.raises(ValueError, match="NaN"):
        poses = d.body_poses.copy()
        poses[3, 0, 0] = np.nan
        cal.calibrate([d._replace(body_poses=poses)])
    with pytest.raises(ValueError, match="increase"):
        cal.calibrate([d._replace(imu=d.imu._replace(times=d.imu.times[::-1].copy()))])


def test_real_kitti_imu_calibrates_consistently(reference_data):
    from jbevo.data import pose_files
    from jbevo.data.kitti import imu_to_rectified_camera, read_kitti_imu
    from jbevo.data.kitti_frames import body_from_camera_rotation, body_poses_from_kitti

    estimates, tilts = [], []
    for name in ("09", "10"):
        body = body_poses_from_kitti(pose_files.read_kitti(reference_data / "kitti_odom" / "gt_poses" / f"{name}.txt").poses)
        t = 0.10365 * np.arange(len(body))
        drive = cal.CalibrationDrive(t, body, read_kitti_imu(reference_data / "kitti_odom" / "imu" / f"{name}.mat", t))
        c = cal.calibrate([drive], groups=0)
        estimates.append(c)
        tilts.append(cal.gravity_up(drive, c, groups=2).tilt_deg)
    a, b = estimates
    # The mounting's tilt (x, y) agrees across drives; its heading is weakly observed.
    np.testing.assert_allclose(a.rotation_deg[:2], b.rotation_deg[:2], atol=0.1)
    for c in estimates:
        assert -0.07 < c.time_offset_s < -0.045  # the IMU rows run ~60 ms ahead of the frames
        assert c.gyro_residual_deg < 0.05
    # KITTI's world (camera 0 at frame 0) against gravity: 2.0 and 2.9 deg on 09 and 10.
    np.testing.assert_allclose(tilts, [2.0, 2.9], atol=0.15)
    published = body_from_camera_rotation(
        imu_to_rectified_camera(reference_data / "realdata" / "kitti_raw_2011_09_26_drive_0001_oxts" / "calib")[:3, :3]
    )
    difference = Rotation.from_matrix(a.rotation_body_imu @ published.T).magnitude()
    assert np.degrees(difference) < 1.5
