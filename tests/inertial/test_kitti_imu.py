"""The real KITTI IMU made ready for a filter (reference data): the day's calibration from its
training drives, applied and resampled, the truth levelled; and the synthetic world rendered at
the attitude that IMU sees."""

import functools

import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.sequences import kitti_sequence, small_camera
from jbevo.data.synthetic.world import World
from jbevo.geometry.euler import euler_zyx
from jbevo.inertial import kitti_imu
from jbevo.inertial.kinematics import accel_tilt


@pytest.fixture
def folders(reference_data):
    return reference_data / "kitti_odom" / "gt_poses", reference_data / "kitti_odom" / "imu"


@functools.cache
def _drive(poses, imu):
    return kitti_imu.calibrated_drive(poses, imu, "10")  # the day's calibration is cached too


@pytest.fixture
def drive(folders):
    return _drive(*folders)


def test_recording_days():
    assert kitti_imu.recording_day("01") == "2011_10_03" and kitti_imu.recording_day("10") == "2011_09_30"
    with pytest.raises(ValueError, match="no public IMU"):
        kitti_imu.recording_day("03")


def test_calibrated_drive_is_levelled_and_in_the_body_frame(drive):
    assert drive.gyro.shape == (1201, 10, 3) and drive.gravity.tilt_deg == pytest.approx(2.9, abs=0.15)
    # After levelling, the accelerometer's pitch agrees with the truth's on average over the drive
    # (braking and accelerating average out; roll keeps the mean centripetal force of the turns).
    truth = euler_zyx(drive.body_poses[:, :3, :3])[:, 1:3]
    tilt = np.asarray(accel_tilt(jnp.asarray(np.nanmean(drive.accel, axis=1))))
    assert np.degrees(abs(np.nanmean(tilt[:, 0] - truth[:, 0]))) < 0.3
    # The gyro integrated over a frame matches the truth's rotation to a few hundredths of a degree.
    r = drive.body_poses[:, :3, :3]
    inc = np.einsum("nji,njk->nik", r[:-1], r[1:])
    yaw_truth = np.arctan2(inc[:, 1, 0], inc[:, 0, 0])
    yaw_gyro = np.nansum(drive.gyro[1:, :, 2], axis=1) * kitti_imu.FRAME_STEP_S / 10
    assert np.degrees(np.sqrt(np.mean((yaw_truth - yaw_gyro)[5:-5] ** 2))) < 0.05


def test_kitti_sequence_with_the_real_imu(folders, drive):
    from jbevo.data.pose_files import read_kitti

    poses = read_kitti(folders[0] / "10.txt").poses
    world = World.create("town02", size=256)
    seq = kitti_sequence(poses, 100, 6, camera=small_camera(0.1), world=world, real_imu=drive)
    np.testing.assert_allclose(seq.gyro, drive.gyro[101:107], rtol=1e-6)
    np.testing.assert_allclose(seq.pitch_roll, euler_zyx(drive.body_poses[101:107, :3, :3])[:, 1:3], atol=1e-6)
    assert seq.imu_dt == pytest.approx(kitti_imu.FRAME_STEP_S / 10, rel=1e-5)
    assert float(np.std(np.asarray(seq.images, float))) > 1.0
    with pytest.raises(ValueError, match="real IMU drive has"):
        kitti_sequence(poses[:-1], 0, 3, camera=small_camera(0.1), world=world, real_imu=drive)
