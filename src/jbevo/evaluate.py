"""Run BEVO over many sequences at once and score it.

    python -m jbevo.evaluate --checkpoint runs/bevo                    # built-in synthetic drives
    python -m jbevo.evaluate --dataset kitti-synthetic --kitti-poses $JBEVO_REFERENCE_DATA/kitti_odom/gt_poses --sequences 09 10
    python -m jbevo.evaluate --dataset kitti --kitti-root /data/kitti/odometry --sequences 09 10 --checkpoint runs/bevo

Sequences of equal length are stacked and run in one vmapped, jitted call, sharded along the
batch over all local devices (``jax.sharding``; on a CPU, ``XLA_FLAGS=--xla_force_host_platform_device_count=4``
makes four devices). Across hosts, start every process with ``jax.distributed.initialize()`` and
give each its own ``--sequences``; the per-host ``metrics.json`` files pool by summing segments.

Writes to ``--out``: ``poses/NAME.txt`` (estimate) and ``poses/NAME_gt.txt`` (truth) as KITTI
pose files of the planar poses lifted to z = 0 (score them with
``python -m jbevo.metrics --up-axis 2``), ``plots/NAME.png`` (top view), and ``metrics.json``
with per-sequence and overall ``t_err_pct``, ``r_err_deg_per_100m``, ``ate_m`` and
``frames_per_s``. Without ``--checkpoint`` the hand-set parameters are evaluated.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jbevo import checkpoint, metrics
from jbevo.camera import BevGrid
from jbevo.datasets import sequence as sq
from jbevo.datasets.catalog import DATASETS, load_sequences
from jbevo.files import write_json_atomic
from jbevo.odometry import Bevo, BevoOutput
from jbevo.odometry_metrics import score, segment_errors, segment_lengths
from jbevo.plots import trajectory_top_view
from jbevo.trajectory_io import write_kitti


def shard_batch(batch, devices=None):
    """Place a batched pytree with its leading axis split over ``devices`` (all local ones)."""
    devices = jax.local_devices() if devices is None else devices
    mesh = Mesh(np.array(devices), ("batch",))
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    return jax.device_put(batch, sharding)


def run_many(model: Bevo, seqs: list[sq.Sequence], warm_start: bool = False) -> tuple[list[BevoOutput], float]:
    """Outputs for every sequence (vmapped per group of equal length, sharded over the local
    devices, padded to a multiple of their count) and the steady-state frames per second."""
    n_dev = len(jax.local_devices())
    run = eqx.filter_jit(jax.vmap(lambda m, s: m(s, warm_start=warm_start), in_axes=(None, 0)))
    outputs: list[BevoOutput | None] = [None] * len(seqs)
    frames, seconds = 0, 0.0
    groups: dict[tuple, list[int]] = {}
    for i, s in enumerate(seqs):
        groups.setdefault((s.num_frames, s.camera.image_shape, s.imu_times.shape[-1]), []).append(i)
    for idx in groups.values():
        padded = idx + [idx[-1]] * (-len(idx) % n_dev)
        batch = shard_batch(sq.stack([seqs[i] for i in padded]))
        jax.block_until_ready(run(model, batch))  # compile
        t0 = time.perf_counter()
        out = jax.block_until_ready(run(model, batch))
        seconds += time.perf_counter() - t0
        frames += len(padded) * seqs[idx[0]].num_frames
        for j, i in enumerate(idx):
            outputs[i] = jax.tree_util.tree_map(lambda x, j=j: np.asarray(x[j]), out)
    return outputs, frames / seconds


def load_model(path: Path | None, grid: BevGrid, imu_dt: float, attitude: str, bands: bool = False) -> Bevo:
    """The hand-set model (``path`` None) or a checkpoint's (a file, or a folder's best.ckpt; its
    own grid and bands), projecting with ``attitude``."""
    if path is None:
        return Bevo.create(grid, imu_dt, attitude, bands=bands)
    path = path / "best.ckpt" if path.is_dir() else path
    model, _, _ = checkpoint.load(path)
    if not isinstance(model, Bevo):
        raise SystemExit(f"{path} holds a BEVO+ localizer; evaluate it with python -m jbevo.localize evaluate")
    return dataclasses.replace(model, attitude_source=attitude)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m jbevo.evaluate", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", type=Path, help="a checkpoint file or a training output folder (its best.ckpt)")
    p.add_argument("--dataset", choices=DATASETS, default="synthetic")
    p.add_argument("--sequences", nargs="+", help="sequence names (KITTI datasets) or count (synthetic; default 4)")
    p.add_argument("--kitti-poses", type=Path)
    p.add_argument("--kitti-root", type=Path)
    p.add_argument("--frames", type=int, default=120, help="frames per sequence (synthetic; cap for kitti-synthetic, 0 = all)")
    p.add_argument("--camera", choices=("small", "kitti"), default="small")
    p.add_argument("--seed", type=int, default=1000, help="first seed of the synthetic drives (training uses 0..)")
    p.add_argument("--attitude", choices=("filter", "zero", "accel", "truth"), default="filter", help="pitch/roll for the BEV")
    p.add_argument("--warm-start", action="store_true", help="start from the truth's attitude and speed")
    p.add_argument("--grid", type=float, nargs=3, default=(0.1, 128, 7.5), metavar=("RES", "SIZE", "NEAR"))
    p.add_argument("--bands", action="store_true", help="hand-set model with the band geometry (jbevo.bands; a checkpoint brings its own)")
    p.add_argument("--out", type=Path, default=Path("runs/evaluation"))
    args = p.parse_args(argv)

    if args.dataset == "synthetic":
        count = int(args.sequences[0]) if args.sequences else 4
        names = [str(args.seed + i) for i in range(count)]
    else:
        names = args.sequences or list(sq.KITTI_TEST)
    try:
        seqs = load_sequences(args.dataset, names, args.frames, args.kitti_poses, args.kitti_root, args.camera, seed=args.seed)
    except (ValueError, FileNotFoundError) as error:
        raise SystemExit(str(error)) from None
    if args.dataset == "synthetic":
        names = [f"synthetic_{n}" for n in names]
    lengths = segment_lengths(args.dataset, args.frames)
    imu_dt = seqs[0].imu_dt if np.isfinite(seqs[0].imu_dt) else 0.01
    res, size, near = args.grid
    model = load_model(args.checkpoint, BevGrid(res, (int(size), int(size)), near=near), imu_dt, args.attitude, args.bands)
    outputs, fps = run_many(model, seqs, args.warm_start)

    (args.out / "poses").mkdir(parents=True, exist_ok=True)
    (args.out / "plots").mkdir(parents=True, exist_ok=True)
    per_sequence = {}
    for name, out, seq in zip(names, outputs, seqs):
        write_kitti(args.out / "poses" / f"{name}.txt", np.asarray(out.poses, float))
        write_kitti(args.out / "poses" / f"{name}_gt.txt", np.asarray(seq.planar, float))
        trajectory_top_view(args.out / "plots" / f"{name}.png", np.asarray(seq.planar), {"BEVO": np.asarray(out.poses)}, title=name)
        s = score(BevoOutput(*map(np.asarray, out)), seq, lengths)
        per_sequence[name] = {k: s[k] for k in ("t_err_pct", "r_err_deg_per_100m", "ate_m", "motion_rmse_m", "yaw_rmse_deg", "segments")}
        print(f"{name}: t_err {s['t_err_pct']:.3f} %  r_err {s['r_err_deg_per_100m']:.3f} deg/100m  ATE {s['ate_m']:.3f} m")
    # Overall: the devkit pools the segments of all sequences.
    pooled = metrics.kitti_errors([segment_errors(o.poses, q.planar, lengths) for o, q in zip(outputs, seqs)])
    sq_err = np.concatenate([np.sum((np.asarray(o.poses)[:, :2] - np.asarray(q.planar)[:, :2]) ** 2, -1) for o, q in zip(outputs, seqs)])
    overall = {"t_err_pct": float(pooled.t_err_pct), "r_err_deg_per_100m": float(pooled.r_err_deg_per_100m),
               "ate_m": float(np.sqrt(sq_err.mean())), "frames_per_s": fps, "segments": int(pooled.segments)}
    print(f"overall: t_err {overall['t_err_pct']:.3f} %  r_err {overall['r_err_deg_per_100m']:.3f} deg/100m  "
          f"ATE {overall['ate_m']:.3f} m  {fps:.0f} frames/s on {len(jax.local_devices())} device(s)")
    write_json_atomic(args.out / "metrics.json", {
        "overall": overall, "per_sequence": per_sequence, "segment_lengths_m": list(lengths),
        "checkpoint": str(args.checkpoint) if args.checkpoint else None, "attitude": args.attitude, "bands": model.bands is not None,
        "warm_start": args.warm_start, "devices": [str(d) for d in jax.local_devices()],
    })
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
