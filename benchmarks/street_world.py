"""The street world against the real frames: does the synthetic world with real streets' failure
modes (:mod:`jbevo.data.synthetic.street`) fail the way the real KITTI frames do, and does a model
learned there alone hold on the real frames?

Side by side. Each real run of ``realdata/`` (06, 07; read and calibrated as in
``real_kitti.py``) is copied into the synthetic world with the same frame times, calibrated real
IMU, camera and levelled truth (:func:`jbevo.data.synthetic.sequences.synthetic_copy`): in the
flat world (a level plane, the camera at the truth's attitude) and in the street world (its
structures, a camera mounted 0.6 deg down and 0.3 deg rolled and 5 cm higher than nominal, the
run's own grade and banking, exposure changes and vignetting), and in the street world less one
failure mode at a time. The same hand-set models run on every copy and on the real frames
(``HAND_SET``): plain BEVO with the true attitude, BEVO with the filter's attitude with and
without bands, the street model without bands and the preset (robust bands, road tilt), also
with keyframes for its bands.

Zero-shot. The preset street model learns its road view, yaw fusion, DPC and bands (14 numbers)
on street-world drives only: the first ``--frames`` frames of KITTI 00, 02, 05 and 08's motion
(simulated IMU, the street's random grade and banking; none of them is a real run scored here), ``--steps``
Adam steps, ``--seeds`` seeds, keeping the checkpoint (among the hand-set parameters and every
``--every`` steps) with the lowest final error on a held-out street-world drive (00's motion after
its training frames, ``VALIDATION_FRAMES`` of them); it is then run on the real frames. Metrics
and keys as ``real_kitti.py``: ``runs[<run>][<world>][<model>][<metric>]`` with ``<run>`` 06, 07
and their halves, and ``zero_shot[<run>][<metric>]`` (mean, std, seeds); ``zero_shot_checkpoints``:
per seed, the chosen ``step`` and the validation error at each checkpoint. The same fit with the
camera's calibration frozen at the hand-set values (the road view's pitch, roll and height; the
other 11 numbers learn): ``zero_shot_calibration_frozen``, ``..._parameters``, ``..._checkpoints``.

Keyframes, held out. The preset with and without keyframes on the zero-shot drives themselves
(street world, no real run): ``keyframes_check[<drive>][<model>][<segment>][<metric>]``, with
``<segment>`` whole, first half and second half.

    JBEVO_REFERENCE_DATA=../shared/data python benchmarks/street_world.py [--seeds 3] [--steps 40]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

import jax

from jbevo.data.pose_files import read_kitti
from jbevo.data.synthetic.sequences import kitti_sequence, synthetic_copy
from jbevo.data.synthetic.street import STREET
from jbevo.data.synthetic.world import World
from jbevo.files import write_json_atomic
from jbevo.models import Bevo
from jbevo.models.presets import STREET_GRID, street_model
from jbevo.models.runners import run_bevo
from real_kitti import (
    CHECK_EVERY,
    LEARNED,
    RESULTS,
    Trainer,
    fit_held_out,
    learned_parameters,
    load_runs,
    segments,
    summarise,
)

#: The street world less one failure mode at a time.
ABLATIONS = {
    "street world": STREET,
    "street world, no structures": dataclasses.replace(
        STREET, facades=False, parked_car_probability=0.0, poles_per_metre=0.0, kerb_height=0.0
    ),
    "street world, no slopes": dataclasses.replace(STREET, slopes=False),
    "street world, camera mounted as nominal": dataclasses.replace(
        STREET, mount_pitch_deg=0.0, mount_roll_deg=0.0, height_error=0.0
    ),
    "street world, no exposure changes or vignetting": dataclasses.replace(STREET, exposure_std=0.0, vignetting=0.0),
    "flat world": None,
}
ZERO_SHOT_DRIVES = ("00", "02", "05", "08")
#: The zero-shot fit's held-out drive: this many frames of 00's motion after its training frames.
VALIDATION_FRAMES = 100
#: The zero-shot fits: every learnable number of the preset, and all but the camera's calibration.
ZERO_SHOT = "learned in the street world only"
ZERO_SHOT_FROZEN = "learned in the street world only, calibration frozen"
#: The rows run on the zero-shot drives themselves (``keyframes_check``).
KEYFRAMES_CHECK = ("street + robust bands", "street + robust bands, keyframes")


def frozen_calibration(select):
    """``select``'s leaves less the road view's calibration (the camera's pitch, roll and height
    against the road): the corridor and everything else ``select`` picks stay learnable."""

    def chosen(model: Bevo):
        picked = select(model)
        assert picked[0] is model.road, "select must pick the road view first"
        return (model.road.log_corridor, *picked[1:])

    return chosen


def hand_set(imu_dt: float) -> dict[str, Bevo]:
    """The rows run on every world: label -> hand-set model."""
    plain = Bevo.create(STREET_GRID, imu_dt)
    return {
        "BEVO, true attitude": dataclasses.replace(plain, attitude_source="truth"),
        "BEVO": plain,
        "BEVO + bands": Bevo.create(STREET_GRID, imu_dt, bands=True),
        "street": street_model(imu_dt, bands=False),
        "street + robust bands": street_model(imu_dt, bands=True),
        "street + robust bands, keyframes": street_model(imu_dt, bands=True, bands_keyframes=True),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=40, help="Adam steps of the zero-shot fit")
    parser.add_argument("--every", type=int, default=CHECK_EVERY, help="steps between the checkpoints validation chooses among")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--frames", type=int, default=200, help="frames of each street-world training drive")
    parser.add_argument("--window", type=int, default=8)
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--town", default="town01")
    parser.add_argument("--out", type=Path, default=RESULTS / "street_world.json")
    args = parser.parse_args()
    root = os.environ.get("JBEVO_REFERENCE_DATA")
    if not root or not (Path(root) / "realdata").is_dir():
        raise SystemExit("set JBEVO_REFERENCE_DATA to the reference data folder (with realdata/ and kitti_odom/)")
    started = time.time()
    runs = load_runs(Path(root))
    world = World.create(args.town)
    table: dict[str, dict] = {}

    def put(run: str, world_name: str, model: str, per_segment: dict[str, dict]) -> None:
        for segment, metrics in per_segment.items():
            key = run if segment == "whole" else f"{run} {segment}"
            table.setdefault(key, {}).setdefault(world_name, {})[model] = metrics

    for name, (_, seq) in runs.items():
        models = hand_set(seq.imu_dt)
        worlds = {"real frames": seq} | {
            label: synthetic_copy(seq, world, street, seed=int(name)) for label, street in ABLATIONS.items()
        }
        for world_name, data in worlds.items():
            for label, model in models.items():
                out = run_bevo(model, data, warm_start=True)
                put(name, world_name, label, segments(out.increments, out.pitch_roll, seq))
            row = table[name][world_name]
            print(
                f"{name} {world_name}: "
                + ", ".join(f"{m} {row[m]['final_pct']:.1f} % / {row[m]['distance_ratio']:.3f}" for m in models),
                flush=True,
            )

    # Zero-shot: learned in the street world only.
    camera = next(iter(runs.values()))[1].camera
    poses_folder = Path(root) / "kitti_odom" / "gt_poses"
    drives = [
        kitti_sequence(
            read_kitti(poses_folder / f"{d}.txt").poses, 0, args.frames, camera=camera, world=world, seed=i, street=STREET
        )
        for i, d in enumerate(ZERO_SHOT_DRIVES)
    ]
    # The preset with and without keyframes on the street-world drives (none of them a scored run).
    imu_dt = next(iter(runs.values()))[1].imu_dt
    keyframes_check: dict[str, dict] = {}
    for d, drive in zip(ZERO_SHOT_DRIVES, drives, strict=True):
        for label in KEYFRAMES_CHECK:
            out = run_bevo(hand_set(imu_dt)[label], drive, warm_start=True)
            keyframes_check.setdefault(d, {})[label] = segments(out.increments, out.pitch_roll, drive)
        print(
            f"keyframes check, street-world {d}: "
            + ", ".join(f"{m} {v['whole']['final_pct']:.2f} %" for m, v in keyframes_check[d].items()),
            flush=True,
        )

    held_out = kitti_sequence(
        read_kitti(poses_folder / f"{ZERO_SHOT_DRIVES[0]}.txt").poses,
        args.frames,
        VALIDATION_FRAMES,
        camera=camera,
        world=world,
        seed=len(ZERO_SHOT_DRIVES),
        street=STREET,
    )
    bands, select = LEARNED["street + robust bands, learned"]
    zero_shot: dict[str, dict[str, list]] = {}
    parameters: dict[str, list] = {}
    checkpoints: dict[str, list] = {}
    for fit_name, chosen in {ZERO_SHOT: select, ZERO_SHOT_FROZEN: frozen_calibration(select)}.items():
        trainer = Trainer(street_model(imu_dt, bands=bands), chosen, args.lr)
        for seed in range(args.seeds):
            fitted = fit_held_out(trainer, drives, held_out, seed, args)
            model = fitted.model
            parameters.setdefault(fit_name, []).append(learned_parameters(model))
            checkpoints.setdefault(fit_name, []).append({"step": fitted.step, "validation_final_pct": fitted.validation})
            rows = zero_shot.setdefault(fit_name, {})
            for name, (_, seq) in runs.items():
                out = run_bevo(model, seq, warm_start=True)
                for segment, metrics in segments(out.increments, out.pitch_roll, seq).items():
                    rows.setdefault(name if segment == "whole" else f"{name} {segment}", []).append(metrics)
            print(
                f"{fit_name}, seed {seed}: " + ", ".join(f"{k} {v[-1]['final_pct']:.2f} %" for k, v in rows.items()), flush=True
            )

    write_json_atomic(
        args.out,
        {
            "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}
            | {"street": dataclasses.asdict(STREET), "zero_shot_drives": list(ZERO_SHOT_DRIVES)},
            "runs": table,
            "zero_shot": {k: summarise(v) for k, v in zero_shot[ZERO_SHOT].items()},
            "zero_shot_calibration_frozen": {k: summarise(v) for k, v in zero_shot[ZERO_SHOT_FROZEN].items()},
            "keyframes_check": keyframes_check,
            "zero_shot_parameters": parameters[ZERO_SHOT],
            "zero_shot_checkpoints": checkpoints[ZERO_SHOT],
            "zero_shot_calibration_frozen_parameters": parameters[ZERO_SHOT_FROZEN],
            "zero_shot_calibration_frozen_checkpoints": checkpoints[ZERO_SHOT_FROZEN],
            "seconds": time.time() - started,
            "device": jax.devices()[0].device_kind,
        },
    )
    print(f"wrote {args.out} in {time.time() - started:.0f} s")


if __name__ == "__main__":
    main()
