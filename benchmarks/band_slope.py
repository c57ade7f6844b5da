"""What the bands' slope and DPC's forward motion respond to in the street world: the pitch error
that the two BEVs of a pair share, or the pitch of one relative to the other.

On the KITTI-style test drives (09 and 10, the first ``--frames`` frames of each, default
``FRAMES``; simulated IMU, rendered in the street world with seed ``LONG_SEED`` as
``benchmarks/street_drives.py`` renders them), every pair of consecutive frames between which the
car moved at least the street preset's band gate (:data:`jbevo.models.presets.STREET_BANDS_MIN_TRAVEL`)
is projected by the street preset's odometry with the camera's mounting known, each BEV at the
true attitude against the road (the truth's pitch and roll less the road's grade and banking under
that frame, as the world rendered them), and registered as the preset registers, its rotation
searched near the pair's true turn (the preset's gyro turn), and then:

* ``exact``: as is;
* ``both +OFFSET``: both BEVs' pitch raised by ``OFFSET_DEG`` (a pitch error the pair shares, the
  ``e`` of :mod:`jbevo.vision.bands`);
* ``earlier +OFFSET``: the earlier BEV's pitch alone (the pair's relative pitch, the ``d`` there).

For each: the bands' slope read as a pitch error (the slope over its pitch coefficient ``2 D / h``,
degrees; the true pitch less the projection's, so a raised pitch reads negative): median, robust
scatter (1.4826 times the median absolute deviation), standard deviation and the share beyond
1 degree; and the full registration's forward motion over the true travel (median). At ``exact``
also the slope's scatter per fifth of the pairs by the full registration's DPC confidence. The
band model's ratio of the slope's coefficient on the earlier BEV's pitch to that on a shared one,
``c / (2 D)`` (:mod:`jbevo.vision.bands`), at each pair's true travel (median). And what the filter
would have to follow: per frame, the change of the camera's true pitch against the road, and of
the road tilt (that pitch less the body's pitch against gravity, which the gyro integrates), RMS
over the drive's frames and over the pairs', and the RMS of the tilt's change averaged over 10
frames (near the per-frame RMS: the change is slow). Nothing is fitted.
Keys: ``drives[<drive>]``, with ``pairs``, ``frames``, ``model_ratio_median``,
``conditions[<condition>][<metric>]``, ``by_confidence`` and ``tilt``.

    JBEVO_REFERENCE_DATA=../shared/data python benchmarks/band_slope.py [--frames N]
"""

from __future__ import annotations

import dataclasses
import time

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from forward_fusion import KITTI_GRID, LONG_DRIVES, LONG_SEED
from jbevo.data.catalog import load_sequences
from jbevo.data.pose_files import read_kitti
from jbevo.data.synthetic.street import STREET
from jbevo.files import write_json_atomic
from jbevo.geometry.camera import Camera
from jbevo.models import Bevo
from jbevo.models.presets import STREET_BANDS_MIN_TRAVEL, street_model
from jbevo.vision.bands import band_moments
from jbevo.vision.bev import bev_increment
from street_drives import drive_arguments
from street_oracle import against_road, mounting

FRAMES = 800
OFFSET_DEG = 0.05
#: (earlier BEV's, later BEV's) pitch offsets per condition, degrees
CONDITIONS = {
    "exact": (0.0, 0.0),
    f"both +{OFFSET_DEG} deg": (OFFSET_DEG, OFFSET_DEG),
    f"earlier +{OFFSET_DEG} deg": (OFFSET_DEG, 0.0),
}


@eqx.filter_jit
def read_pair(model: Bevo, camera: Camera, images, attitudes, offsets, turn):
    """The slope as a pitch error (radians), the full registration's forward motion (metres) and
    its confidence for the pair ``images`` projected at ``attitudes`` with ``offsets`` added to
    their pitch (earlier, later), registered near the yaw ``turn`` between them (radians)."""
    earlier = model.bev(images[0], attitudes[0].at[0].add(offsets[0]), camera)
    later = model.bev(images[1], attitudes[1].at[0].add(offsets[1]), camera)
    reg = model._register(earlier, later, jnp.asarray(turn, earlier.dtype))
    assert model.bands is not None
    shifts = model.bands.shifts(earlier, later, reg, model.grid, model.dpc)
    height = model.camera_height(camera, earlier.dtype)
    slope = model.bands.slope_measurement(shifts, model.grid, model.dpc, height, 0.1)
    return slope.value / slope.pitch, bev_increment(model.grid, reg.rotation, reg.translation)[0], reg.confidence


def scatter(values: np.ndarray) -> dict[str, float]:
    """Median, robust scatter, standard deviation and share beyond 1 of ``values`` (degrees)."""
    median = float(np.median(values))
    return {
        "median_deg": median,
        "robust_scatter_deg": float(1.4826 * np.median(np.abs(values - median))),
        "std_deg": float(np.std(values)),
        "share_beyond_1_deg": float(np.mean(np.abs(values) > 1.0)),
    }


def main() -> None:
    args, root = drive_arguments(__doc__, "band_slope.json")
    frames = args.frames or FRAMES
    gt = root / "kitti_odom" / "gt_poses"
    started = time.time()
    seqs = load_sequences("kitti-synthetic", list(LONG_DRIVES), frames, gt, camera="kitti", seed=LONG_SEED, world=STREET)
    drives: dict[str, dict] = {}
    for i, (name, seq) in enumerate(zip(LONG_DRIVES, seqs)):
        # load_sequences renders the drive at place i with seed LONG_SEED + i.
        road = against_road(seq, read_kitti(gt / f"{name}.txt").poses, STREET, LONG_SEED + i)
        model = dataclasses.replace(street_model(seq.imu_dt, KITTI_GRID, bands=True), road=mounting(STREET))
        images, attitudes = np.asarray(seq.images), jnp.asarray(road, jnp.float32)
        planar = np.asarray(seq.planar, float)
        travel = np.linalg.norm(np.diff(planar[:, :2], axis=0), axis=1)
        turn = np.angle(np.exp(1j * np.diff(planar[:, 2])))
        pairs = np.flatnonzero(travel >= STREET_BANDS_MIN_TRAVEL) + 1
        conditions, read = {}, {}
        for label, (earlier, later) in CONDITIONS.items():
            offsets = jnp.radians(jnp.asarray([earlier, later], jnp.float32))
            read[label] = np.array(
                [
                    read_pair(
                        model, seq.camera, images[t - 1 : t + 1], attitudes[t - 1 : t + 1], offsets, jnp.float32(turn[t - 1])
                    )
                    for t in pairs
                ],
                float,
            )
            if not np.isfinite(read[label]).all():
                raise SystemExit(f"{name} {label}: a pair's slope or motion is not finite")
            pitch, forward = np.degrees(read[label][:, 0]), read[label][:, 1] / travel[pairs - 1]
            conditions[label] = scatter(pitch) | {"forward_over_true_median": float(np.median(forward))}
            print(
                f"{name} {label}: slope as pitch median {np.median(pitch):+.3f} deg, forward {np.median(forward):.4f}", flush=True
            )
        exact, confidence = np.degrees(read["exact"][:, 0]), read["exact"][:, 2]
        fifths = np.array_split(np.argsort(confidence), 5)
        by_confidence = [
            {"confidence": [float(confidence[part].min()), float(confidence[part].max())]} | scatter(exact[part])
            for part in fifths
        ]
        (x_far, x_near), (m2_far, m2_near) = (band_moments(model.grid, model.dpc.window_taper, k) for k in (1, 2))
        distance = travel[pairs - 1]
        model_ratio = ((m2_far - m2_near) / (x_far - x_near) + 2.0 * distance) / (2.0 * distance)
        truth = np.asarray(seq.pitch_roll, float)[:, 0]
        tilt_change = np.diff(road[:, 0] - truth)
        drives[name] = {
            "pairs": len(pairs),
            "frames": seq.num_frames,
            "model_ratio_median": float(np.median(model_ratio)),
            "conditions": conditions,
            "by_confidence": by_confidence,
            "tilt": {
                "camera_pitch_change_rms_deg": float(np.degrees(np.sqrt(np.mean(np.diff(road[:, 0]) ** 2)))),
                "road_tilt_change_rms_deg": float(np.degrees(np.sqrt(np.mean(tilt_change**2)))),
                "road_tilt_change_rms_on_pairs_deg": float(np.degrees(np.sqrt(np.mean(tilt_change[pairs - 1] ** 2)))),
                "road_tilt_change_10_frame_mean_rms_deg": float(
                    np.degrees(np.sqrt(np.mean(np.convolve(tilt_change, np.full(10, 0.1), "valid") ** 2)))
                ),
            },
        }
    settings = {"drives": list(LONG_DRIVES), "seed": LONG_SEED, "frames": frames, "offset_deg": OFFSET_DEG}
    settings |= {"min_travel_m": STREET_BANDS_MIN_TRAVEL}
    write_json_atomic(args.out, {"drives": drives, "settings": settings, "seconds": time.time() - started})


if __name__ == "__main__":
    main()
