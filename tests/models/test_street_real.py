"""The real-street model on real KITTI frames (skipped without JBEVO_REFERENCE_DATA): the runs
read as shipped, the IMU calibrated on drives the tests do not score, the truth levelled; the
hand-set street model holds the real 06 run to a few percent where BEVO as the synthetic world
tunes it is 27 % off, and its robust bands do not diverge on 07's slow start where the plain
bands do. (The full table, with learned variants and peers: benchmarks/real_kitti.py.)"""

import numpy as np
import pytest

from jbevo.data.sequence import window
from jbevo.inertial import kitti_imu
from jbevo.models.bevo import Bevo
from jbevo.models.losses import relative_motion
from jbevo.models.presets import STREET_GRID, street_model
from jbevo.models.runners import run_bevo

RUNS = {"06": "kitti_odometry_06_first51", "07": "kitti_odometry_07_first160"}


@pytest.fixture(scope="module")
def runs(reference_data):
    poses, imu = reference_data / "kitti_odom" / "gt_poses", reference_data / "kitti_odom" / "imu"
    calibration = kitti_imu.day_calibration(str(poses), str(imu), "2011_09_30", exclude=tuple(RUNS))
    return {
        name: kitti_imu.read_calibrated_run(reference_data / "realdata" / f, poses, imu, name, calibration)
        for name, f in RUNS.items()
    }


def _final_pct_and_ratio(out, seq):
    truth = relative_motion(seq)[1:]
    distance = float(np.sum(np.linalg.norm(truth[:, :2], axis=1)))
    ratio = float(np.sum(np.linalg.norm(out.increments[1:, :2], axis=1))) / distance
    final = float(np.linalg.norm(out.poses[-1, :2] - seq.planar[-1, :2]))
    return 100 * final / distance, ratio


def test_the_street_model_holds_the_real_06_run(runs):
    raw, seq = runs["06"]
    plain = run_bevo(Bevo.create(STREET_GRID, raw.imu_dt), raw, warm_start=True)
    assert _final_pct_and_ratio(plain, raw)[0] > 20.0
    out = run_bevo(street_model(seq.imu_dt, bands=False), seq, warm_start=True)
    final, ratio = _final_pct_and_ratio(out, seq)
    assert final < 4.0 and abs(ratio - 1.0) < 0.05
    turn_error = np.degrees(np.asarray(out.increments[1:, 2]) - np.asarray(relative_motion(seq)[1:, 2]))
    assert np.sqrt(np.mean(turn_error**2)) < 0.05  # the gyro's turn: DPC's alone is ~0.15 deg
    assert np.degrees(np.abs(np.asarray(out.pitch_roll) - np.asarray(seq.pitch_roll))).max() < 1.0


def test_robust_bands_do_not_diverge_on_the_slow_start_of_07(runs):
    _, seq = runs["07"]
    start = window(seq, 0, 60)  # the slow start: 0.1-0.6 m per frame
    truth = np.asarray(start.pitch_roll)
    plain = run_bevo(Bevo.create(STREET_GRID, start.imu_dt, bands=True), start, warm_start=True)
    assert np.degrees(np.abs(np.asarray(plain.pitch_roll) - truth)).max() > 10.0
    # The robust update at any speed (the street model engages its bands from 1 m per frame only,
    # which this stretch never reaches).
    robust = run_bevo(street_model(start.imu_dt, bands=True, bands_min_travel=0.0), start, warm_start=True)
    assert np.degrees(np.abs(np.asarray(robust.pitch_roll) - truth)).max() < 1.0


def test_forward_fusion_holds_the_real_06_motion_per_frame(runs):
    """The accelerometer's speed fused with DPC's forward increment in the street preset: on real 06
    the per-frame motion error, almost all along the heading with DPC alone, falls below 5 cm; the
    turn and the lateral motion are DPC's and the gyro's as before. (The fusion keeps DPC's slow
    scale errors, which the bands' road tilt corrects, and removes the scatter about them.)"""
    _, seq = runs["06"]
    truth = np.asarray(relative_motion(seq))[1:]
    alone = run_bevo(street_model(seq.imu_dt), seq, warm_start=True)
    fused = run_bevo(street_model(seq.imu_dt, forward_fusion=True), seq, warm_start=True)

    def motion_cm(out):
        return 100 * float(np.sqrt(np.mean(np.sum((np.asarray(out.increments)[1:, :2] - truth[:, :2]) ** 2, axis=1))))

    assert motion_cm(alone) > 7.0 and motion_cm(fused) < 5.0
    np.testing.assert_array_equal(fused.increments[:, 1:], alone.increments[:, 1:])
