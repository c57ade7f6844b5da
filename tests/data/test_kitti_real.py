"""The KITTI readers on the real data (skipped without JBEVO_REFERENCE_DATA): the odometry IMU
files, a real camera run read with its IMU, and the real raw OXTS drive (its timestamps,
0-2 samples per frame, padding after the real samples)."""

import cv2
import numpy as np
import pytest
import scipy.io

from jbevo.data import kitti
from jbevo.data.imu_stream import group_blocks

RAW = "realdata/kitti_raw_2011_09_26_drive_0001_oxts"


def test_odometry_imu_file_gives_ten_rows_per_frame_block(reference_data):
    path = reference_data / "kitti_odom" / "imu" / "10.mat"
    rows = scipy.io.loadmat(path)["imu_data_interp"]
    t = 0.1 * np.arange(1201)
    stream = kitti.read_kitti_imu(path, t)
    assert stream.times.shape == (12001,) and stream.times[10] == pytest.approx(0.1)
    times, gyro, accel = group_blocks(stream, t)
    assert gyro.shape == (1201, 10, 3)
    assert np.all(np.isnan(gyro[0])) and np.all(np.isfinite(gyro[1:]))
    np.testing.assert_array_equal(gyro[5], rows[40:50, 3:6])  # block t: rows 10 (t - 1) .. 10 t - 1
    np.testing.assert_array_equal(accel[5], rows[40:50, 0:3])
    with pytest.raises(ValueError, match="need at least"):
        kitti.read_kitti_imu(path, 0.1 * np.arange(1300))


def test_real_camera_run_reads_with_its_imu(reference_data, tmp_path):
    run = reference_data / "realdata" / "kitti_odometry_06_first51"
    folder = tmp_path / "sequences" / "06"
    folder.mkdir(parents=True)
    (folder / "image_0").symlink_to(run / "image_0")
    (folder / "times.txt").symlink_to(run / "times.txt")
    (folder / "calib.txt").symlink_to(run / "calib.txt")
    (tmp_path / "poses").mkdir()
    (tmp_path / "poses" / "06.txt").symlink_to(run / "poses.txt")
    seq = kitti.read_odometry(tmp_path, "06", imu=reference_data / "kitti_odom" / "imu")
    assert kitti.has_imu(seq)
    assert seq.gyro.shape == (51, 10, 3) and seq.images.shape[0] == 51
    rows = scipy.io.loadmat(reference_data / "kitti_odom" / "imu" / "06.mat")["imu_data_interp"]
    np.testing.assert_allclose(seq.gyro[50], rows[490:500, 3:6], rtol=1e-6)
    assert seq.imu_dt == pytest.approx(0.01039, abs=1e-4)
    assert not kitti.has_imu(kitti.read_odometry(tmp_path, "06"))


def _raw_drive(reference_data, tmp_path):
    real = reference_data / RAW
    drive = tmp_path / "2011_09_26_drive_0001_sync"
    (drive / "image_00" / "data").mkdir(parents=True)
    (drive / "oxts").symlink_to(real / "oxts")
    (drive / "calib").symlink_to(real / "calib")
    (drive / "image_00" / "timestamps.txt").symlink_to(real / "image_00" / "timestamps.txt")
    for i in range(108):  # the drive's images are not public here: blank frames stand in
        cv2.imwrite(str(drive / "image_00" / "data" / f"{i:010d}.png"), np.zeros((8, 16), np.uint8))
    return drive


def test_real_raw_drive_keeps_its_samples_and_times(reference_data, tmp_path):
    drive = _raw_drive(reference_data, tmp_path)
    seq = kitti.read_raw(drive)
    t = np.asarray(seq.frame_times, float)
    assert t[0] == 0.0 and t[-1] == pytest.approx(11.04, abs=0.01)  # 108 frames, ~9.7 Hz
    oxts_times, oxts = kitti.read_oxts(drive)
    frames = kitti._timestamps(drive / "image_00" / "timestamps.txt")
    np.testing.assert_allclose(t, frames - frames[0], atol=2e-6)
    ok = np.all(np.isfinite(np.asarray(seq.gyro)), -1)
    counts = ok.sum(1)
    assert counts.sum() == 108 - int(np.sum(oxts_times >= frames[-1])) and set(counts) <= {0, 1, 2}
    assert counts.max() == 2 and counts.min() == 0  # synced stamps jitter by +-5 ms around the frames
    # Padding after the real samples: in every block the valid rows come first.
    assert np.all(np.sort(~ok, axis=1) == ~ok)
    # The INS's own pitch and roll are kept (against gravity), not made relative to frame 0.
    nearest = np.abs(oxts_times[None, :] - frames[:, None]).argmin(1)
    np.testing.assert_allclose(np.asarray(seq.pitch_roll), oxts[nearest][:, [4, 3]], atol=1e-5)
    assert float(seq.planar[0, 2]) == pytest.approx(0.0, abs=1e-6)
    resampled = kitti.read_raw(drive, samples_per_frame=1)
    assert bool(np.all(np.isfinite(np.asarray(resampled.gyro[1:-1]))))


def test_published_calibration_chain_is_a_small_rotation(reference_data):
    t = kitti.imu_to_rectified_camera(reference_data / RAW / "calib")
    from jbevo.data.kitti_frames import body_from_camera_rotation

    r = body_from_camera_rotation(t[:3, :3])
    angle = np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)))
    assert 0.3 < angle < 1.5


def test_a_run_folder_reads_with_the_whole_sequences_times(reference_data, tmp_path):
    run = reference_data / "realdata" / "kitti_odometry_07_first160"
    seq = kitti.read_run(run, imu=reference_data / "kitti_odom" / "imu" / "07.mat")
    assert seq.images.shape == (160, 370, 1226) and seq.gyro.shape == (160, 10, 3)
    times = np.loadtxt(run / "times.txt")
    assert len(times) == 1101  # the whole sequence's: the run keeps its first 160
    np.testing.assert_allclose(np.asarray(seq.frame_times, float), times[:160], atol=1e-6)
    assert float(seq.camera.intrinsics[0, 0]) == pytest.approx(707.0912, abs=1e-3)
    np.testing.assert_allclose(np.asarray(seq.planar[0]), 0.0, atol=1e-6)
    (tmp_path / "image_0").symlink_to(run / "image_0")
    for name in ("times.txt", "calib.txt"):
        (tmp_path / name).symlink_to(run / name)
    (tmp_path / "poses.txt").write_text("".join((run / "poses.txt").read_text().splitlines(keepends=True)[:100]))
    with pytest.raises(ValueError, match="100 poses for 160 images"):
        kitti.read_run(tmp_path)
    with pytest.raises(FileNotFoundError, match="missing run folder"):
        kitti.read_run(tmp_path / "absent")


def test_a_calibrated_run_has_the_levelled_truth_and_the_calibrated_imu(reference_data):
    from jbevo.inertial import calibration as cal
    from jbevo.inertial import kitti_imu

    poses, imu = reference_data / "kitti_odom" / "gt_poses", reference_data / "kitti_odom" / "imu"
    raw = kitti.read_run(reference_data / "realdata" / "kitti_odometry_06_first51", imu=imu / "06.mat")
    calibration = cal.calibrate([kitti_imu.calibration_drive(poses, imu, n) for n in ("04", "05", "08")])
    drive = kitti_imu.calibrated_drive(poses, imu, "06", calibration=calibration)
    seq = kitti_imu.calibrated_sequence(raw, drive)
    # KITTI's truth starts level (the first camera pose); against gravity the car is ~1.1 deg
    # nose down and ~2.3 deg rolled at frame 0.
    np.testing.assert_allclose(np.asarray(raw.pitch_roll[0]), 0.0, atol=1e-6)
    assert np.degrees(float(seq.pitch_roll[0, 0])) == pytest.approx(1.1, abs=0.2)
    assert np.degrees(float(seq.pitch_roll[0, 1])) == pytest.approx(2.3, abs=0.3)
    np.testing.assert_allclose(np.asarray(seq.gyro), drive.gyro[:51], rtol=1e-6)
    np.testing.assert_allclose(
        np.linalg.norm(np.diff(np.asarray(seq.planar[:, :2]), axis=0), axis=1),
        np.linalg.norm(np.diff(np.asarray(raw.planar[:, :2]), axis=0), axis=1),
        atol=1e-3,
    )
    with pytest.raises(ValueError, match="not the same drive"):
        kitti_imu.calibrated_sequence(raw, kitti_imu.calibrated_drive(poses, imu, "07", calibration=calibration))


def test_the_published_imu_of_06_starts_with_a_dropout(reference_data):
    # Sequence 06's published IMU is a straight line over frames 1-11; 07's has none over the
    # run's 160 frames. Both sides stay more than an order of magnitude from the tolerance.
    imu = reference_data / "kitti_odom" / "imu"
    t = 0.1 * np.arange(160)
    six, seven = (kitti.read_kitti_imu(imu / f"{name}.mat", t) for name in ("06", "07"))
    flagged = kitti.interpolated_frames(six)
    np.testing.assert_array_equal(np.flatnonzero(flagged), np.arange(1, 12))
    assert not kitti.interpolated_frames(seven).any()
    curvature = kitti.frame_curvature(six)
    assert curvature[flagged[1:-1]].max() < kitti.INTERPOLATION_TOLERANCE / 10
    assert min(curvature[~flagged[1:-1]].min(), kitti.frame_curvature(seven).min()) > 10 * kitti.INTERPOLATION_TOLERANCE


def test_the_rows_of_06s_dropout_are_marked_missing(reference_data):
    # Flagged frames 1-11: the line runs from frame 0's sample to frame 12's. Read as published,
    # block 1 keeps frame 0's sample and blocks 2-12 go whole (block 0 is NaN in the layout).
    imu = reference_data / "kitti_odom" / "imu" / "06.mat"
    raw = kitti.read_run(reference_data / "realdata" / "kitti_odometry_06_first51", imu=imu)
    spans = kitti.dropout_spans(kitti.read_kitti_imu(imu, np.asarray(raw.frame_times)))
    np.testing.assert_allclose(spans, [[raw.frame_times[0], raw.frame_times[12]]])
    marked = np.isnan(np.asarray(kitti.without_dropouts(raw, spans).gyro))
    np.testing.assert_array_equal(np.flatnonzero(marked.all((1, 2))), np.r_[0, 2:13])
    assert marked[1].any(-1).sum() == 9


def test_the_readers_mark_the_dropouts_when_asked(reference_data):
    # read_run(imu_dropouts="missing") is without_dropouts over the published IMU's spans; the
    # calibrated drive marks the same rows as without_dropouts at the calibration's time offset.
    from jbevo.inertial import calibration as cal
    from jbevo.inertial import kitti_imu

    poses, imu = reference_data / "kitti_odom" / "gt_poses", reference_data / "kitti_odom" / "imu"
    run = reference_data / "realdata" / "kitti_odometry_06_first51"
    raw = kitti.read_run(run, imu=imu / "06.mat")
    spans = kitti.dropout_spans(kitti.read_kitti_imu(imu / "06.mat", np.asarray(raw.frame_times)))
    missing = kitti.read_run(run, imu=imu / "06.mat", imu_dropouts="missing")
    expected = kitti.without_dropouts(raw, spans)
    np.testing.assert_array_equal(np.asarray(missing.gyro), np.asarray(expected.gyro))
    np.testing.assert_array_equal(np.asarray(missing.accel), np.asarray(expected.accel))
    calibration = cal.calibrate([kitti_imu.calibration_drive(poses, imu, n) for n in ("04", "05", "08")])
    drive = kitti_imu.calibrated_drive(poses, imu, "06", calibration=calibration)
    marked_drive = kitti_imu.calibrated_drive(poses, imu, "06", calibration=calibration, imu_dropouts="missing")
    published = kitti.read_kitti_imu(imu / "06.mat", drive.frame_times)
    marked = kitti.without_dropouts(
        kitti_imu.calibrated_sequence(raw, drive), kitti.dropout_spans(published), calibration.time_offset_s
    )
    np.testing.assert_array_equal(np.asarray(kitti_imu.calibrated_sequence(raw, marked_drive).gyro), np.asarray(marked.gyro))
    assert np.isnan(marked_drive.gyro[2:12]).all() and np.isfinite(marked_drive.gyro[14:100]).all()
    with pytest.raises(ValueError, match="imu_dropouts must be one of"):
        kitti.read_run(run, imu=imu / "06.mat", imu_dropouts="dropped")
