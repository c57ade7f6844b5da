"""What bounds the street world's KITTI-style error: the street preset's attitude against the road,
or what DPC makes of the street's images once the projection is exact.

The KITTI-style experiment's test drives (KITTI 09 and 10 whole, the motion of their pose files,
simulated IMU, rendered with seed ``LONG_SEED`` as ``benchmarks/street_drives.py`` renders them) in
the street world and the flat world, hand-set, warm start, on the KITTI-style grid:

* ``street + robust bands``: the street preset (:func:`jbevo.models.presets.street_model`);
* ``street + robust bands, mounting known``: the same with its road view set to the world's camera
  mounting (pitch, roll and height), which the hand-set preset does not know (street world only:
  the flat world's camera is the nominal one);
* ``street + robust bands, level road``: the preset with its BEV projected on the road's plane,
  the bands' tilt its only pitch (``street_model(..., level_road=True)``,
  :attr:`jbevo.models.road_tilt.RoadTilt.level`), hand-set, its mounting unknown;
* ``street + robust bands, tilt not measured by the speed``: the preset with the road tilt
  updated by the bands' slope alone (:attr:`jbevo.models.road_tilt.RoadTilt.speed_coupling`
  off), an ablation: below the bands' travel gate the tilt then only walks;
* ``odometry at the preset's attitude``: the preset's odometry without bands (road view, yaw
  fusion, DPC) projected at the attitude the preset projected each frame's BEV with (its filter's
  pitch plus its road tilt, and its roll): the control for the next row, which differs from it in
  the attitude alone;
* ``odometry at the true attitude against the road``: the preset's odometry without bands (road
  view with the mounting known, yaw fusion, DPC) projected at the truth's pitch and roll less the
  road's grade and banking under each frame, as the world rendered them
  (:func:`jbevo.data.synthetic.street.street_tilt`), its attitude filter warm-started from the
  truth against gravity as the others' (its gyro bias estimate sets the gyro's turn): the error
  that is left when the projection's attitude is exact (the camera's height still wanders with
  the drive's bumps, as in every row);
* ``odometry at the true pitch against the road, the preset's roll`` and ``odometry at the
  preset's pitch, the true roll against the road``: the same odometry with one axis of the
  camera's attitude the oracle's and the other the preset's (as the preset's road view and
  projection put it): which of the two the preset's error lies in;
* ``odometry at the true pitch plus the preset's slow pitch error, the preset's roll`` and ``...
  fast pitch error ...``: the same odometry at the true pitch against the road plus the slow part
  of the preset's pitch error (its mean over a centred window of ``SLOW_WINDOW`` frames,
  :func:`split_pitch`) or plus the rest: which time scale of the preset's pitch error costs.

Scored as ``benchmarks/street_drives.py`` scores (the KITTI devkit's t_err and r_err over
100-800 m segments, per drive and pooled, the metrics of ``real_kitti.scores`` and
``forward_fusion.along_across``, and the distance ratio's spread over 100 m pieces), and how far
the camera attitude each BEV was projected with is from the true one against the road (its
pitch's mean and RMS, its roll's RMS; zero for the oracle by construction) and, for the rows
whose filter runs, how far the filter's pitch is from the truth's against gravity
(``filter_pitch_rmse_deg``): the part of the projection's pitch error that is not the road
tilt's. Nothing is fitted.
Keys: ``drives[<drive>][<world>][<model>][<metric>]``, ``<drive>`` 09, 10 or pooled.

    JBEVO_REFERENCE_DATA=../shared/data python benchmarks/street_oracle.py [--frames N]
"""

from __future__ import annotations

import dataclasses
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from forward_fusion import KITTI_GRID, LONG_DRIVES, LONG_SEED, along_across
from jbevo.data.catalog import load_sequences
from jbevo.data.pose_files import read_kitti
from jbevo.data.sequence import Sequence
from jbevo.data.synthetic.street import STREET, Street, street_tilt
from jbevo.data.synthetic.trajectories import kitti_drive
from jbevo.eval.batch import run_many
from jbevo.eval.devkit import SEGMENT_LENGTHS
from jbevo.eval.scores import score
from jbevo.files import write_json_atomic
from jbevo.geometry.camera import Camera
from jbevo.models import Bevo, BevoOutput
from jbevo.models.presets import street_model
from jbevo.vision.road_view import RoadView
from real_kitti import scores
from street_drives import PIECE_M, drive_arguments, spread

WORLDS: dict[str, Street | None] = {"street world": STREET, "flat world": None}
PRESET = "street + robust bands"
KNOWN = "street + robust bands, mounting known"
LEVEL = "street + robust bands, level road"
UNCOUPLED = "street + robust bands, tilt not measured by the speed"
REPLAY = "odometry at the preset's attitude"
ORACLE = "odometry at the true attitude against the road"
TRUE_PITCH = "odometry at the true pitch against the road, the preset's roll"
TRUE_ROLL = "odometry at the preset's pitch, the true roll against the road"
SLOW = "odometry at the true pitch plus the preset's slow pitch error, the preset's roll"
FAST = "odometry at the true pitch plus the preset's fast pitch error, the preset's roll"
#: frames in the centred window whose mean of the preset's pitch error is its slow part (about
#: 10 s, 100 m at KITTI's speeds)
SLOW_WINDOW = 101


def mounting(street: Street | None) -> RoadView:
    """The road view of the camera as ``street`` mounts it (the nominal camera on the flat world)."""
    if street is None:
        return RoadView.create()
    nominal = float(Camera.kitti().height)
    return RoadView.create(
        float(np.radians(street.mount_pitch_deg)),
        float(np.radians(street.mount_roll_deg)),
        (nominal + street.height_error) / nominal,
    )


def against_road(seq: Sequence, kitti_poses: np.ndarray, street: Street | None, seed: int) -> np.ndarray:
    """The pitch and roll against the road, ``(T, 2)``, of ``seq`` (rendered by ``load_sequences``
    from ``kitti_poses`` with ``seed`` in the world of ``street``): its truth's less the road's
    grade and banking under each frame, the attitude the images were rendered at less the
    mounting."""
    truth = np.asarray(seq.pitch_roll, float)
    if street is None:
        return truth
    _, level = kitti_drive(kitti_poses)
    return truth - street_tilt(street, None, level[: seq.num_frames + 1], seed)[1:]


@eqx.filter_jit
def run_on_road(model: Bevo, seq: Sequence, pitch_roll: Array) -> BevoOutput:
    """``model`` (``attitude_source="truth"``) over ``seq``, warm-started from the truth against
    gravity, with each frame's BEV projected at ``pitch_roll`` instead of the truth's."""
    carry, frames, seq = model.start(seq, warm_start=True)
    frames = frames._replace(true_pitch_roll=pitch_roll.astype(frames.true_pitch_roll.dtype))
    frame_dt = model.frame_dt(seq)
    return jax.lax.scan(lambda c, f: model.step(c, f, seq.camera, frame_dt), carry, frames)[1]


def projection_error(out: BevoOutput, model: Bevo, road: np.ndarray, street: Street | None) -> dict[str, float]:
    """How far the camera attitude each BEV was first projected with is from the true one against
    the road (``road`` plus the mounting; degrees): its pitch's mean and RMS, its roll's RMS.
    With bands, the BEV is projected once more at the updated attitude before the next frame's
    registration (``Bevo.advance``); that projection is not scored."""
    view, true_view = model.road or RoadView.create(), mounting(street)
    pitch = np.asarray(out.projection, float)[:, 0] + float(view.pitch)
    roll = np.asarray(out.projection, float)[:, 1] + float(view.roll)
    pitch_error = np.degrees(pitch - road[:, 0] - float(true_view.pitch))
    roll_error = np.degrees(roll - road[:, 1] - float(true_view.roll))
    return {
        "projection_pitch_mean_deg": float(pitch_error.mean()),
        "projection_pitch_rmse_deg": float(np.sqrt(np.mean(pitch_error**2))),
        "projection_roll_rmse_deg": float(np.sqrt(np.mean(roll_error**2))),
    }


def filter_pitch_error(out: BevoOutput, seq: Sequence) -> dict[str, float]:
    """The RMS of the filter's pitch against the truth's against gravity (degrees)."""
    error = np.degrees(np.asarray(out.pitch_roll, float)[:, 0] - np.asarray(seq.pitch_roll, float)[:, 0])
    return {"filter_pitch_rmse_deg": float(np.sqrt(np.mean(error**2)))}


def mixed(projection: np.ndarray, road: np.ndarray, preset: Bevo, street: Street | None, true_axis: int) -> np.ndarray:
    """The body attitude that, under the mounting's road view, projects the camera at the true
    attitude against the road (``road``) on axis ``true_axis`` (0 pitch, 1 roll) and at the
    ``preset``'s (its ``projection`` under its own road view) on the other."""
    view, true_view = preset.road or RoadView.create(), mounting(street)
    out = np.asarray(projection, float) + np.array([float(view.pitch - true_view.pitch), float(view.roll - true_view.roll)])
    out[:, true_axis] = road[:, true_axis]
    return out


def split_pitch(projection: np.ndarray, road: np.ndarray, preset: Bevo, street: Street | None, slow: bool) -> np.ndarray:
    """The body attitude that, under the mounting's road view, projects the camera at the true
    pitch against the road plus the slow part of the ``preset``'s pitch error (its mean over a
    centred window of :data:`SLOW_WINDOW` frames, the ends padded with the end values), or with
    ``slow`` False plus the rest of that error; the roll the ``preset``'s."""
    out = mixed(projection, road, preset, street, 0)
    error = mixed(projection, road, preset, street, 1)[:, 0] - road[:, 0]
    half = SLOW_WINDOW // 2
    smooth = np.convolve(np.pad(error, half, mode="edge"), np.full(SLOW_WINDOW, 1.0 / SLOW_WINDOW), "valid")
    out[:, 0] = road[:, 0] + (smooth if slow else error - smooth)
    return out


def models(imu_dt: float, street: Street | None) -> dict[str, Bevo]:
    preset = street_model(imu_dt, KITTI_GRID, bands=True)
    odometry = dataclasses.replace(street_model(imu_dt, KITTI_GRID, bands=False), attitude_source="truth")
    out = {PRESET: preset}
    if street is not None:  # the preset's road view is the flat world's nominal camera already
        out[KNOWN] = dataclasses.replace(preset, road=mounting(street))
    out[LEVEL] = street_model(imu_dt, KITTI_GRID, bands=True, level_road=True)
    assert preset.road_tilt is not None
    out[UNCOUPLED] = dataclasses.replace(preset, road_tilt=dataclasses.replace(preset.road_tilt, speed_coupling=False))
    oracle = dataclasses.replace(odometry, road=mounting(street))
    return out | {REPLAY: odometry, ORACLE: oracle, TRUE_PITCH: oracle, TRUE_ROLL: oracle, SLOW: oracle, FAST: oracle}


def main() -> None:
    args, root = drive_arguments(__doc__, "street_oracle.json")
    gt = root / "kitti_odom" / "gt_poses"
    started = time.time()
    drives: dict[str, dict] = {}
    for world, street in WORLDS.items():
        seqs = load_sequences("kitti-synthetic", list(LONG_DRIVES), args.frames, gt, camera="kitti", seed=LONG_SEED, world=street)
        # load_sequences renders the drive at place i with seed LONG_SEED + i.
        road = [
            against_road(seq, read_kitti(gt / f"{name}.txt").poses, street, LONG_SEED + i)
            for i, (name, seq) in enumerate(zip(LONG_DRIVES, seqs))
        ]
        # The attitudes each replayed row projects at; the preset's come once it has run (first).
        replays: dict[str, list[np.ndarray]] = {ORACLE: road}
        for label, model in models(seqs[0].imu_dt, street).items():
            attitudes = replays.get(label)
            if attitudes is None:
                outs, _ = run_many(model, seqs, warm_start=True)
            else:
                outs = [run_on_road(model, seq, jnp.asarray(pr)) for seq, pr in zip(seqs, attitudes)]
            if label == PRESET:
                preset = [np.asarray(out.projection, float) for out in outs]
                replays |= {
                    REPLAY: preset,
                    TRUE_PITCH: [mixed(p, r, model, street, 0) for p, r in zip(preset, road)],
                    TRUE_ROLL: [mixed(p, r, model, street, 1) for p, r in zip(preset, road)],
                    SLOW: [split_pitch(p, r, model, street, True) for p, r in zip(preset, road)],
                    FAST: [split_pitch(p, r, model, street, False) for p, r in zip(preset, road)],
                }
            for name, out, seq, pitch_roll in zip(LONG_DRIVES, outs, seqs, road):
                # A replayed attitude is not the filter's against gravity: no pitch/roll error.
                row = scores(out.increments, None if attitudes is not None else out.pitch_roll, seq, 0, seq.num_frames)
                row |= along_across(out.increments, seq, 0, seq.num_frames) | spread(out, seq)
                row |= projection_error(out, model, pitch_roll, street)
                if attitudes is None:
                    row |= filter_pitch_error(out, seq)
                row |= {k: score(out, seq, SEGMENT_LENGTHS)[k] for k in ("t_err_pct", "r_err_deg_per_100m")}
                drives.setdefault(name, {}).setdefault(world, {})[label] = row
                print(f"{world} {name} {label}: t_err {row['t_err_pct']:.2f} %, ratio {row['distance_ratio']:.3f}", flush=True)
            pooled = score(outs, seqs, SEGMENT_LENGTHS)
            drives.setdefault("pooled", {}).setdefault(world, {})[label] = {
                k: pooled[k] for k in ("t_err_pct", "r_err_deg_per_100m")
            }
    settings = {"drives": list(LONG_DRIVES), "seed": LONG_SEED, "frames": args.frames, "piece_m": PIECE_M}
    write_json_atomic(args.out, {"drives": drives, "settings": settings, "seconds": time.time() - started})


if __name__ == "__main__":
    main()
