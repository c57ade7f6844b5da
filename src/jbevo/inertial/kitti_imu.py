"""The real KITTI odometry IMU made ready for a filter: each recording day's calibration (fitted
on that day's training drives), applied, resampled into frame blocks, and the ground truth
levelled by the gravity the drive's own accelerometer finds.

KITTI recorded its odometry sequences on two days and calibrated its rig per day: 00-02 on
2011_10_03, 04-10 on 2011_09_30 (03's raw data is not public, so it has no IMU). A day's
:func:`~jbevo.inertial.calibration.calibrate` uses only its drives among 00-08
(:data:`jbevo.data.splits.KITTI_TRAIN`), so 09 and 10 are never fitted on. Frames are timed at
:data:`FRAME_STEP_S` (the mean step of sequence 00's ``times.txt``; the gyro scale absorbs the
0.3 % by which other sequences differ).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jbevo.data.imu_stream import resample_blocks
from jbevo.data.kitti import blank_dropout_rows, check_imu_dropouts, dropout_spans, read_kitti_imu, read_run
from jbevo.data.kitti_frames import body_poses_from_kitti
from jbevo.data.pose_files import read_kitti
from jbevo.data.sequence import Sequence, check
from jbevo.data.splits import KITTI_TRAIN
from jbevo.inertial import calibration as cal

#: KITTI's raw recording day of each odometry sequence with a public IMU.
RECORDING_DAYS = {"2011_10_03": ("00", "01", "02"), "2011_09_30": ("04", "05", "06", "07", "08", "09", "10")}
#: Frame step (s) for sequences read without their ``times.txt``.
FRAME_STEP_S = 0.10365
#: IMU samples per frame block (the published rows: 10 per frame).
SAMPLES_PER_FRAME = 10


class CalibratedImuDrive(NamedTuple):
    """A drive's levelled truth and its calibrated IMU in frame blocks (block ``t``: the frame
    interval before frame ``t``; body frame; NaN rows outside the IMU's span)."""

    frame_times: np.ndarray  # (N,)
    body_poses: np.ndarray  # (N, 4, 4) T_world_body, world levelled against gravity
    imu_times: np.ndarray  # (N, S)
    gyro: np.ndarray  # (N, S, 3)
    accel: np.ndarray  # (N, S, 3)
    gravity: cal.Gravity  # the drive's world tilt (before levelling)


def recording_day(name: str) -> str:
    """The recording day of odometry sequence ``name`` (``ValueError`` for one without IMU)."""
    for day, names in RECORDING_DAYS.items():
        if name in names:
            return day
    raise ValueError(
        f"KITTI sequence {name!r} has no public IMU (known: {', '.join(n for v in RECORDING_DAYS.values() for n in v)})"
    )


def calibration_drive(poses_folder: str | Path, imu_folder: str | Path, name: str) -> cal.CalibrationDrive:
    """Sequence ``name``'s ground truth (``poses_folder/NN.txt``) and IMU (``imu_folder/NN.mat``)."""
    path = Path(poses_folder) / f"{name}.txt"
    if not path.is_file():
        raise FileNotFoundError(f"no KITTI pose file {path}")
    body = body_poses_from_kitti(read_kitti(path).poses)
    t = FRAME_STEP_S * np.arange(len(body))
    return cal.CalibrationDrive(t, body, read_kitti_imu(Path(imu_folder) / f"{name}.mat", t))


@functools.cache
def day_calibration(
    poses_folder: str, imu_folder: str, day: str, groups: int = 0, exclude: tuple[str, ...] = ()
) -> cal.ImuCalibration:
    """The calibration of ``day``'s IMU from its drives among 00-08 less ``exclude`` (cached per
    process; ``groups`` for the jackknife, 0: none)."""
    names = [n for n in RECORDING_DAYS[day] if n in KITTI_TRAIN and n not in exclude]
    if not names:
        raise ValueError(f"no training drive of {day} is left to calibrate on after excluding {exclude}")
    return cal.calibrate([calibration_drive(poses_folder, imu_folder, n) for n in names], groups=groups)


def calibrated_drive(
    poses_folder: str | Path,
    imu_folder: str | Path,
    name: str,
    calibration: cal.ImuCalibration | None = None,
    imu_dropouts: str = "published",
) -> CalibratedImuDrive:
    """Sequence ``name`` with its day's calibration (or ``calibration``) applied. ``imu_dropouts``
    ``missing``: the resampled rows that take their values from a dropout's straight line NaN
    (:func:`jbevo.data.kitti.blank_dropout_rows` at the calibration's time offset; the calibration
    itself is fitted on the published rows)."""
    check_imu_dropouts(imu_dropouts)
    drive = calibration_drive(poses_folder, imu_folder, name)
    c = calibration or day_calibration(str(poses_folder), str(imu_folder), recording_day(name))
    gravity = cal.gravity_up(drive, c)
    times, gyro, accel = resample_blocks(cal.apply(drive.imu, c), drive.frame_times, SAMPLES_PER_FRAME)
    if imu_dropouts == "missing":
        gyro, accel = blank_dropout_rows(times, gyro, accel, dropout_spans(drive.imu), c.time_offset_s)
    return CalibratedImuDrive(drive.frame_times, cal.level_poses(drive.body_poses, gravity.up), times, gyro, accel, gravity)


def calibrated_sequence(seq: Sequence, drive: CalibratedImuDrive) -> Sequence:
    """``seq``, the first frames of a KITTI odometry sequence (e.g. read with
    :func:`jbevo.data.kitti.read_run`), with its IMU and ground truth replaced by those of the
    same sequence's calibrated ``drive`` (:func:`calibrated_drive`): the calibrated IMU in frame
    blocks, and the truth levelled against gravity, so that its pitch and roll are the body's
    against gravity (KITTI's own are against the first camera pose). Frame times are the drive's
    (nominal :data:`FRAME_STEP_S`)."""
    n = seq.num_frames
    if len(drive.frame_times) < n:
        raise ValueError(f"the calibrated drive has {len(drive.frame_times)} frames, the sequence {n}")
    positions = np.asarray(seq.poses[:2, :3, 3], float)
    if n > 1 and np.all(np.isfinite(positions)):
        # The drive's truth must be this sequence's: the same motion from frame 0 to frame 1.
        step = np.linalg.norm(positions[1] - positions[0])
        drive_step = np.linalg.norm(drive.body_poses[1, :3, 3] - drive.body_poses[0, :3, 3])
        if abs(step - drive_step) > 1e-3:
            raise ValueError(
                f"the calibrated drive's first step is {drive_step:.4f} m, the sequence's {step:.4f} m: not the same drive"
            )
    arrays = (
        jnp.asarray(drive.frame_times[:n]),
        jnp.asarray(drive.imu_times[:n]),
        jnp.asarray(drive.gyro[:n]),
        jnp.asarray(drive.accel[:n]),
        jnp.asarray(drive.body_poses[:n], jnp.float32),
    )
    return check(eqx.tree_at(lambda q: (q.frame_times, q.imu_times, q.gyro, q.accel, q.poses), seq, arrays))


def read_calibrated_run(
    run_folder: str | Path, poses_folder: str | Path, imu_folder: str | Path, name: str, calibration: cal.ImuCalibration
) -> tuple[Sequence, Sequence]:
    """A real run of sequence ``name`` kept in one folder (:func:`jbevo.data.kitti.read_run`)
    with the sequence's IMU file from ``imu_folder``: as shipped, and with ``calibration``
    applied and the truth levelled (:func:`calibrated_sequence`; the sequence's whole pose file
    from ``poses_folder`` finds its gravity)."""
    raw = read_run(run_folder, imu=Path(imu_folder) / f"{name}.mat")
    drive = calibrated_drive(poses_folder, imu_folder, name, calibration=calibration)
    return raw, calibrated_sequence(raw, drive)


__all__ = [
    "FRAME_STEP_S",
    "RECORDING_DAYS",
    "SAMPLES_PER_FRAME",
    "CalibratedImuDrive",
    "calibrated_drive",
    "calibrated_sequence",
    "calibration_drive",
    "day_calibration",
    "read_calibrated_run",
    "recording_day",
]
