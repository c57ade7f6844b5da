"""The forward motion fused from the accelerometer and DPC, on the real KITTI camera runs.

The street preset (:func:`jbevo.models.presets.street_model`, robust bands) against the same model
with :class:`jbevo.models.forward_fusion.ForwardFusion` (hand-set), on the runs and with the
calibrated IMU of ``benchmarks/real_kitti.py`` (its data, metrics and halves: every model runs
over the whole run, each half is scored on its own increments). Besides the metrics there, the
per-frame motion error split along the heading and across it (``along_cm``, ``across_cm``, RMS).

Rows: the preset and the preset with forward fusion, both warm-started (the truth's pitch, roll
and speed at frame 0, as ``real_kitti.py``'s rows) and both cold (the accelerometer's tilt, speed
zero); forward fusion without its bias state, and with the update it had before its linear one
(:class:`RobustRelativeFusion`: DPC's noise 5 % of the increment, robust); and a sweep of the
fusion's accelerometer noise (``accel_std``), which was looked at on these runs before the
hand-set value was written down: it says how much the rows depend on that choice, not which
value is best; and the same model without the accelerometer (:class:`ConstantSpeedPrior`: DPC's
increments under a constant-speed prior alone, for each speed walk of ``SPEED_WALKS``), which says
what of the fusion's gain is the accelerometer's and what is smoothing. The warm rows but the
sweep and the prior also run on the street world's copies of the runs
(``benchmarks/street_world.py``'s street world: the real IMU, truth and frame times, rendered
images).

Long drives: the street world's KITTI 09 and 10 whole, rendered as
``experiments/kitti_odometry.py --world street`` renders them (its test drives, simulated IMU),
with the preset and the same fusion rows; scored by the KITTI devkit (``t_err_pct``,
``r_err_deg_per_100m``, 100-800 m segments) and the metrics above. ``bias_walk_sweep``: the
bias's walk among 0.005, 0.02 and 0.05 m/s^2 per square root of a second, beside the same rows, on
the street world's KITTI 00 and 08 (the first 800 frames, rendered with seed 100; a training and
the validation drive of that experiment; devkit errors per drive and pooled), where the hand-set
value (:data:`jbevo.models.forward_fusion.BIAS_WALK`) and the linear update were chosen.
``held_out``: the long-drive rows on the street world's KITTI 02 and 05, which took no part in
forward fusion's design, run as the sweep's drives are (the first 800 frames, seed 100).

Keys: ``runs[<run>][<variant>][<metric>]``, ``street_world[<run>][<variant>][<metric>]`` (``<run>``
as in ``real_kitti.json``), ``kitti_street[<drive>][<variant>][<metric>]`` (``<drive>`` 09, 10 or
pooled), ``bias_walk_sweep[<drive>][<variant>][<metric>]`` and
``held_out[<drive>][<variant>][<metric>]`` (``<drive>`` also pooled).

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

from jbevo.data.catalog import load_sequences
from jbevo.data.synthetic.sequences import synthetic_copy
from jbevo.data.synthetic.street import Street
from jbevo.data.synthetic.world import World
from jbevo.eval.batch import run_many
from jbevo.eval.devkit import SEGMENT_LENGTHS
from jbevo.eval.scores import score
from jbevo.files import write_json_atomic
from jbevo.filtering import ukf
from jbevo.geometry import BevGrid
from jbevo.models import Bevo, relative_motion
from jbevo.models.forward_fusion import BIAS_WALK, ForwardFusion
from jbevo.models.presets import street_model
from jbevo.models.runners import run_bevo
from real_kitti import RESULTS, half_frames, load_runs, scores, segments
from street_world import STREET

#: The rows also run on the street world's copies of the runs and its long drives.
ON_STREET_WORLD = (
    "street + robust bands",
    "street + robust bands, forward fusion",
    "street + robust bands, forward fusion without its bias state",
    "street + robust bands, forward fusion, robust relative update",
)

#: The bias walks of the sweep (m/s^2 per square root of a second).
BIAS_WALK_SWEEP = (0.005, 0.02, 0.05)

#: The long drives: the KITTI-style experiment's test drives and their rendering seed, and the
#: sweep's drives, frames and seed.
LONG_DRIVES, LONG_SEED = ("09", "10"), 900
SWEEP_DRIVES, SWEEP_FRAMES, SWEEP_SEED = ("00", "08"), 800, 100

#: Drives that took no part in forward fusion's design (training drives of the KITTI-style
#: experiment), run as the sweep's drives are: the first 800 frames, seed 100.
HELD_OUT_DRIVES = ("02", "05")

#: The KITTI-style experiment's BEV grid.
KITTI_GRID = BevGrid(0.1, (256, 256), near=4.0)

#: The accelerometer noise values of the sweep (m/s^2 per IMU sample): 1.58 is the attitude
#: filter's own speed walk (0.05 m/s per 10-sample frame) in these units.
SWEEP = (0.02, 0.05, 0.2, 0.5, 1.58)


#: The constant-speed prior's speed walks (m/s^2 per sample): the sweep's largest value (the
#: attitude filter's own speed walk), about a third of it, and two larger ones.
SPEED_WALKS = (0.5, 1.58, 3.0, 5.0)


def along_across(increments: np.ndarray, seq, start: int, stop: int) -> dict:
    """RMS of the per-frame motion error along the heading (body x) and across it, cm."""
    err = np.asarray(increments, float)[start + 1 : stop] - np.asarray(relative_motion(seq), float)[start + 1 : stop]
    return {"along_cm": 100 * float(np.sqrt(np.mean(err[:, 0] ** 2))), "across_cm": 100 * float(np.sqrt(np.mean(err[:, 1] ** 2)))}


class RobustRelativeFusion(ForwardFusion):
    """:class:`ForwardFusion` with the update it had before its linear one: DPC's forward increment
    ``z`` weighted with the variance ``(displacement_std max(|z|, 5 cm))^2 + innovation^2``
    (``displacement_std`` relative, 5 %: a noise that grows with the increment, robust against
    gross ones)."""

    def update(self, state: ukf.GaussianState, displacement, use=True) -> ukf.GaussianState:
        dtype = state.mean.dtype
        z = jnp.asarray(displacement, dtype)
        ok = jnp.isfinite(z) & use
        z = jnp.where(ok, z, 0.0)
        innovation = z - state.mean[1]
        scale = jnp.maximum(jnp.abs(z), 0.05)
        variance = (jnp.exp(self.log_displacement_std).astype(dtype) * scale) ** 2 + innovation**2
        return ukf.linear_update(state, jnp.asarray((0.0, 1.0, 0.0), dtype), innovation, variance, ok)

    @classmethod
    def hand_set(cls) -> RobustRelativeFusion:
        """The hand-set noise values of :meth:`ForwardFusion.create` (5 % where it has 5 cm)."""
        f = ForwardFusion.create()
        return cls(f.log_accel_std, f.log_displacement_std, f.log_bias_walk, f.bias_std)


class ConstantSpeedPrior(ForwardFusion):
    """:class:`ForwardFusion` without the accelerometer: every sample's forward acceleration is
    taken as zero, the speed walking by ``accel_std`` per sample (a car's unknown acceleration),
    so DPC's increments are smoothed under a constant-speed prior alone. Built without the bias
    state (:meth:`create_prior`)."""

    def predict(self, state: ukf.GaussianState, accel, pitch, dt: float) -> ukf.GaussianState:
        zero = jnp.zeros_like(accel)
        return super().predict(state, zero, jnp.zeros((), state.mean.dtype), dt)

    @classmethod
    def create_prior(cls, speed_walk: float) -> ConstantSpeedPrior:
        """The prior with ``speed_walk`` m/s^2 per sample, DPC's hand-set noise, no bias state."""
        f = ForwardFusion.create(accel_std=speed_walk, bias_walk=1e-9, bias_std=0.0)
        return cls(f.log_accel_std, f.log_displacement_std, f.log_bias_walk, f.bias_std)


def without_bias(model):
    """``model``'s forward fusion without its bias state (no prior, a negligible walk)."""
    return dataclasses.replace(
        model, forward=dataclasses.replace(model.forward, bias_std=0.0, log_bias_walk=jnp.log(jnp.float32(1e-9)))
    )


def rows(imu_dt: float, grid: BevGrid | None = None) -> dict[str, tuple]:
    """Label -> (model, warm start)."""
    grid = grid or street_model(imu_dt).grid
    preset = street_model(imu_dt, grid, bands=True)
    fused = street_model(imu_dt, grid, bands=True, forward_fusion=True)
    out = {
        "street + robust bands": (preset, True),
        "street + robust bands, forward fusion": (fused, True),
        "street + robust bands, forward fusion without its bias state": (without_bias(fused), True),
        "street + robust bands, forward fusion, robust relative update": (
            dataclasses.replace(fused, forward=RobustRelativeFusion.hand_set()),
            True,
        ),
        "street + robust bands, cold start": (preset, False),
        "street + robust bands, forward fusion, cold start": (fused, False),
    }
    for accel_std in SWEEP:
        model = dataclasses.replace(fused, forward=ForwardFusion.create(accel_std=accel_std))
        out[f"forward fusion, accel_std {accel_std} (sweep)"] = (model, True)
    for walk in SPEED_WALKS:
        model = dataclasses.replace(fused, forward=ConstantSpeedPrior.create_prior(walk))
        out[f"constant-speed prior without the accelerometer, speed walk {walk}"] = (model, True)
    return out


def long_models(imu_dt: float) -> dict[str, Bevo]:
    """The long drives' rows: :data:`ON_STREET_WORLD` on the KITTI-style grid."""
    models = rows(imu_dt, KITTI_GRID)
    return {label: models[label][0] for label in ON_STREET_WORLD}


def sweep_models(imu_dt: float) -> dict[str, Bevo]:
    """The bias walk sweep's rows: the preset, forward fusion without the bias state, with the
    robust relative update, and with each walk of :data:`BIAS_WALK_SWEEP`."""
    models = long_models(imu_dt)
    fused = models.pop("street + robust bands, forward fusion")
    walks = {
        f"forward fusion, bias_walk {w}": dataclasses.replace(fused, forward=ForwardFusion.create(bias_walk=w))
        for w in BIAS_WALK_SWEEP
    }
    return models | walks


def long_drives(
    reference: Path,
    names,
    frames: int,
    seed: int,
    make_models,
    devkit: bool,
    street: Street | None = STREET,
    extra=lambda out, seq: {},
) -> dict[str, dict]:
    """The models ``make_models(imu_dt)`` (label -> model) on the KITTI drives ``names`` rendered
    in the world of ``street`` (the street world by default): the metrics of ``real_kitti.scores``
    per drive and those ``extra(output, sequence)`` returns, with ``devkit`` also the devkit's
    t_err and r_err per drive and pooled."""
    seqs = load_sequences(
        "kitti-synthetic", list(names), frames, reference / "kitti_odom" / "gt_poses", camera="kitti", seed=seed, world=street
    )
    table: dict[str, dict] = {}
    for label, model in make_models(seqs[0].imu_dt).items():
        outs, _ = run_many(model, seqs, warm_start=True)
        for name, out, seq in zip(names, outs, seqs):
            row = scores(out.increments, out.pitch_roll, seq, 0, seq.num_frames)
            row |= along_across(out.increments, seq, 0, seq.num_frames) | extra(out, seq)
            if devkit:
                row |= {k: score(out, seq, SEGMENT_LENGTHS)[k] for k in ("t_err_pct", "r_err_deg_per_100m")}
            table.setdefault(name, {})[label] = row
            print(f"{name} {label}: final {row['final_pct']:.2f} %, motion {row['motion_cm']:.1f} cm", flush=True)
        if devkit:
            pooled = score(outs, seqs, SEGMENT_LENGTHS)
            table.setdefault("pooled", {})[label] = {k: pooled[k] for k in ("t_err_pct", "r_err_deg_per_100m")}
    return table


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
    tables["kitti_street"] = long_drives(Path(root), LONG_DRIVES, 0, LONG_SEED, long_models, devkit=True)
    tables["bias_walk_sweep"] = long_drives(Path(root), SWEEP_DRIVES, SWEEP_FRAMES, SWEEP_SEED, sweep_models, devkit=True)
    tables["held_out"] = long_drives(Path(root), HELD_OUT_DRIVES, SWEEP_FRAMES, SWEEP_SEED, long_models, devkit=True)
    settings = {
        "accel_std": float(jnp.exp(ForwardFusion.create().log_accel_std)),
        "displacement_std": float(jnp.exp(ForwardFusion.create().log_displacement_std)),
        "bias_walk": BIAS_WALK,
        "sweep": list(SWEEP),
        "speed_walks": list(SPEED_WALKS),
        "bias_walk_sweep": list(BIAS_WALK_SWEEP),
        "town": args.town,
    }
    write_json_atomic(args.out, tables | {"settings": settings, "seconds": time.time() - started})


if __name__ == "__main__":
    main()
