"""The forward motion fused from the accelerometer and DPC, on the real KITTI camera runs.

The street preset (:func:`jbevo.models.presets.street_model`, robust bands) against the same model
with :class:`jbevo.models.forward_fusion.ForwardFusion` (hand-set), on the runs and with the
calibrated IMU of ``benchmarks/real_kitti.py`` (its data, metrics and halves: every model runs
over the whole run, each half is scored on its own increments). Besides the metrics there, the
per-frame motion error split along the heading and across it (``along_cm``, ``across_cm``, RMS).

Rows: the preset and the preset with forward fusion, both warm-started (the truth's pitch, roll
and speed at frame 0, as ``real_kitti.py``'s rows) and both cold (the accelerometer's tilt, speed
zero); and a sweep of the fusion's accelerometer noise (``accel_std``), which was looked at on
these runs before the hand-set value was written down: it says how much the rows depend on that
choice, not which value is best. The two warm rows also run on the street world's copies of the
runs (``benchmarks/street_world.py``'s street world: the real IMU, truth and frame times, rendered
images). Keys: ``runs[<run>][<variant>][<metric>]`` and ``street_world[<run>][<variant>][<metric>]``,
``<run>`` as in ``real_kitti.json``.

    JBEVO_REFERENCE_DATA=../shared/data python benchmarks/forward_fusion.py
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from jbevo.data.synthetic.sequences import synthetic_copy
from jbevo.data.synthetic.world import World
from jbevo.files import write_json_atomic
from jbevo.models import relative_motion
from jbevo.models.forward_fusion import ForwardFusion
from jbevo.models.presets import street_model
from jbevo.models.runners import run_bevo
from real_kitti import RESULTS, half_frames, load_runs, segments
from street_world import STREET

#: The rows also run on the street world's copies of the runs.
ON_STREET_WORLD = ("street + robust bands", "street + robust bands, forward fusion")

#: The accelerometer noise values of the sweep (m/s^2 per IMU sample): 1.58 is the attitude
#: filter's own speed walk (0.05 m/s per 10-sample frame) in these units.
SWEEP = (0.02, 0.05, 0.2, 0.5, 1.58)


def along_across(increments: np.ndarray, seq, start: int, stop: int) -> dict:
    """RMS of the per-frame motion error along the heading (body x) and across it, cm."""
    err = np.asarray(increments, float)[start + 1 : stop] - np.asarray(relative_motion(seq), float)[start + 1 : stop]
    return {"along_cm": 100 * float(np.sqrt(np.mean(err[:, 0] ** 2))), "across_cm": 100 * float(np.sqrt(np.mean(err[:, 1] ** 2)))}


def rows(imu_dt: float) -> dict[str, tuple]:
    """Label -> (model, warm start)."""
    preset = street_model(imu_dt, bands=True)
    fused = street_model(imu_dt, bands=True, forward_fusion=True)
    out = {
        "street + robust bands": (preset, True),
        "street + robust bands, forward fusion": (fused, True),
        "street + robust bands, cold start": (preset, False),
        "street + robust bands, forward fusion, cold start": (fused, False),
    }
    for accel_std in SWEEP:
        model = dataclasses.replace(fused, forward=ForwardFusion.create(accel_std=accel_std))
        out[f"forward fusion, accel_std {accel_std} (sweep)"] = (model, True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--town", default="town01")
    parser.add_argument("--out", type=Path, default=RESULTS / "forward_fusion.json")
    args = parser.parse_args()
    root = os.environ.get("JBEVO_REFERENCE_DATA")
    if not root or not (Path(root) / "realdata").is_dir():
        raise SystemExit("set JBEVO_REFERENCE_DATA to the reference data folder (with realdata/ and kitti_odom/)")
    started = time.time()
    world = World.create(args.town)
    tables: dict[str, dict[str, dict]] = {"runs": {}, "street_world": {}}

    def put(kind: str, name: str, label: str, out, seq) -> None:
        n = seq.num_frames
        per_segment = segments(out.increments, out.pitch_roll, seq)
        bounds = {"whole": (0, n), **{half: half_frames(n, half) for half in per_segment if half != "whole"}}
        for segment, metrics in per_segment.items():
            metrics |= along_across(out.increments, seq, *bounds[segment])
            tables[kind].setdefault(name if segment == "whole" else f"{name} {segment}", {})[label] = metrics
        m = tables[kind][name][label]
        print(f"{kind} {name} {label}: final {m['final_pct']:.2f} %, motion {m['motion_cm']:.1f} cm", flush=True)

    for name, (_, seq) in load_runs(Path(root)).items():
        models = rows(seq.imu_dt)
        for label, (model, warm) in models.items():
            put("runs", name, label, run_bevo(model, seq, warm_start=warm), seq)
        copy = synthetic_copy(seq, world, STREET, seed=int(name))
        for label in ON_STREET_WORLD:
            put("street_world", name, label, run_bevo(models[label][0], copy, warm_start=True), seq)
    settings = {
        "accel_std": float(jnp.exp(ForwardFusion.create().log_accel_std)),
        "displacement_std": float(jnp.exp(ForwardFusion.create().log_displacement_std)),
        "sweep": list(SWEEP),
        "town": args.town,
    }
    write_json_atomic(args.out, tables | {"settings": settings, "seconds": time.time() - started})


if __name__ == "__main__":
    main()
