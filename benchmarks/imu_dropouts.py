"""The real KITTI IMU's dropouts: the street preset's attitude filter on the published rows, which
fill each OXTS dropout with a straight line, against the same rows with the lines marked missing.

Every KITTI odometry drive with a public IMU is searched for interpolated frames
(:func:`jbevo.data.kitti.interpolated_frames`); the drives that have any are scored whole. Each is
read as :mod:`jbevo.inertial.kitti_imu` reads it (its recording day's calibration, fitted on the
day's drives among 00-08 on the published rows; resampled into frame blocks; the truth levelled
against gravity). The filter is the street preset's (:func:`jbevo.models.presets.street_model`'s
``attitude``), fed as ``benchmarks/attitude_real.py`` feeds it: the truth's planar velocity plus
N(0, ``--speed-noise``) per frame stands in for the odometry's speed, and it starts from the true
attitude at frame 0. Variants:

* ``published``: the rows as published (the preset's widening never engages: no block is missing);
* ``held``: the rows on a dropout's line NaN (read with ``imu_dropouts="missing"``:
  :func:`jbevo.inertial.kitti_imu.calibrated_drive`), the filter holding its attitude through
  them, not widened (``gap_rate_std`` 0);
* ``widened``: the same, with the preset's ``gap_rate_std``
  (:data:`jbevo.models.presets.STREET_GAP_RATE_STD`).

Scores (degrees, pitch and roll pooled, against the levelled truth, frames 1 .. N-1): the RMSE and
the largest error over the whole drive, and over the frames from each dropout's first frame to
``AFTER`` frames past its last (``gaps``: each dropout's first and last frame; ``gap_max_deg``:
the largest error in each one's window). ``truth_bend_deg``: the truth's pitch and roll's second
difference per frame (the largest of the two, degrees), its largest inside the dropouts and its
median elsewhere: the truth comes from the same OXTS unit. Windows of dropouts less than
``AFTER`` frames apart overlap (on 00), and share their largest error. Nothing is fitted here, but
the drives are not held out from what the filter was given: each day's calibration is fitted on
drives that include the day's scored ones, and the preset's gap rate is the RMS tilt rate of
KITTI's training drives, 00, 02 and 05 among them; 06's first frames are a real camera run
(``benchmarks/real_kitti.py``).
Keys: ``drives[<drive>]`` with ``frames``, ``gaps``, ``rows_marked`` (the resampled rows marked
missing), ``truth_bend_deg`` and ``[<variant>][<metric>]``; ``pooled["rmse_deg"][<variant>]``
(over the drives' frames); ``settings``; ``seconds``.

    JBEVO_REFERENCE_DATA=../shared/data python benchmarks/imu_dropouts.py
"""

from __future__ import annotations

import dataclasses
import time

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import attitude as sim  # the attitude benchmarks' runners and options (sets jax_enable_x64)
from attitude_real import drive_data, kitti_folders, planar_velocity
from jbevo.data import kitti
from jbevo.files import write_json_atomic
from jbevo.geometry.euler import euler_zyx
from jbevo.inertial.kitti_imu import (
    FRAME_STEP_S,
    RECORDING_DAYS,
    SAMPLES_PER_FRAME,
    calibrated_drive,
    calibration_drive,
    day_calibration,
    recording_day,
)
from jbevo.models.presets import street_model

#: Frames after a dropout's last frame that its window keeps.
AFTER = 50
VARIANTS = ("published", "held", "widened")


def scores(error: np.ndarray, gaps: list[tuple[int, int]]) -> dict:
    """``error``: absolute pitch/roll error (deg) at frames 1 .. N-1, shape ``(N - 1, 2)``."""
    frame = np.arange(1, len(error) + 1)
    near = np.zeros(len(error), bool)
    for first, last in gaps:
        near |= (frame >= first) & (frame <= last + AFTER)
    return {
        "rmse_deg": float(np.sqrt(np.mean(error**2))),
        "max_deg": float(error.max()),
        "near_gaps_rmse_deg": float(np.sqrt(np.mean(error[near] ** 2))),
        "near_gaps_max_deg": float(error[near].max()),
        "gap_max_deg": [float(error[(frame >= a) & (frame <= b + AFTER)].max()) for a, b in gaps],
    }


def main() -> None:
    args = sim.options(__doc__ or "", 0, "imu_dropouts.json").parse_args()
    sim.reference_data(args)
    started = time.time()
    poses, imu = kitti_folders(args.data)
    names = [n for members in RECORDING_DAYS.values() for n in members]
    dt = FRAME_STEP_S / SAMPLES_PER_FRAME
    preset = street_model(dt).attitude
    filters = {"published": preset, "held": dataclasses.replace(preset, gap_rate_std=0.0), "widened": preset}
    run = eqx.filter_jit(lambda f, s: sim.run_speed_aided(f, s["gyro"], s["accel"], s["initial"], s["velocity"]))
    drives: dict = {}
    squared: dict = {v: [] for v in VARIANTS}
    for name in sorted(names):
        published = calibration_drive(poses, imu, name).imu
        flags = kitti.interpolated_frames(published)
        if not flags.any():
            continue
        calibration = day_calibration(str(poses), str(imu), recording_day(name))
        drive = calibrated_drive(poses, imu, name, calibration=calibration)
        marked = calibrated_drive(poses, imu, name, calibration=calibration, imu_dropouts="missing")
        on_line = np.isnan(marked.gyro).any(-1) & np.isfinite(drive.gyro).all(-1)
        truth = euler_zyx(drive.body_poses[:, :3, :3])[:, 1:3]
        velocity = planar_velocity(drive.body_poses, FRAME_STEP_S, args.speed_noise, 100 + int(name))
        gaps = [(int(first), int(last)) for first, last in kitti.dropout_frames(flags)]
        # The truth comes from the same unit: its pitch and roll's second difference per frame
        # (deg), inside the dropouts and elsewhere.
        bend = np.degrees(np.abs(truth[:-2] - 2 * truth[1:-1] + truth[2:]).max(1))
        inside = flags[1:-1]
        out: dict = {
            "frames": len(truth),
            "gaps": [list(g) for g in gaps],
            "rows_marked": int(on_line.sum()),
            "truth_bend_deg": {"dropouts_max": float(bend[inside].max()), "elsewhere_median": float(np.median(bend[~inside]))},
        }
        for variant in VARIANTS:
            read = drive if variant == "published" else marked
            data = {k: jnp.asarray(v) for k, v in drive_data(truth, read.gyro, read.accel, velocity).items()}
            error = np.degrees(np.abs(np.asarray(run(filters[variant], data)) - truth[1:]))
            out[variant] = scores(error, gaps)
            squared[variant].append(error**2)
        drives[name] = out
        print(
            f"{name}: {len(gaps)} dropouts; RMSE "
            + ", ".join(f"{v} {out[v]['rmse_deg']:.3f}" for v in VARIANTS)
            + " deg; near the dropouts, largest "
            + ", ".join(f"{v} {out[v]['near_gaps_max_deg']:.2f}" for v in VARIANTS),
            flush=True,
        )
    pooled = {v: float(np.sqrt(np.mean(np.concatenate(squared[v])))) for v in VARIANTS}
    write_json_atomic(
        args.out,
        {
            "drives": drives,
            "pooled": {"rmse_deg": pooled},
            "settings": {"after_frames": AFTER, "speed_noise_m_s": args.speed_noise, "frame_step_s": FRAME_STEP_S},
            "seconds": time.time() - started,
        },
    )


if __name__ == "__main__":
    main()
