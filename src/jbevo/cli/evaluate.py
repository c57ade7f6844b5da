"""Run BEVO over many sequences at once and score it.

    python -m jbevo.evaluate --checkpoint runs/bevo                    # built-in synthetic drives
    python -m jbevo.evaluate --dataset kitti-synthetic --kitti-poses $JBEVO_REFERENCE_DATA/kitti_odom/gt_poses --sequences 09 10
    python -m jbevo.evaluate --dataset kitti --kitti-root /data/kitti/odometry --kitti-imu $JBEVO_REFERENCE_DATA/kitti_odom/imu --sequences 09 10 --checkpoint runs/bevo

Sequences of equal length are stacked and run in one vmapped, jitted call, sharded along the
batch over all local devices (``jax.sharding``; on a CPU, ``XLA_FLAGS=--xla_force_host_platform_device_count=4``
makes four devices).

Writes to ``--out``: ``poses/NAME.txt`` (estimate) and ``poses/NAME_gt.txt`` (truth) as KITTI
pose files of the planar poses lifted to z = 0 (score them with
``python -m jbevo.metrics --up-axis 2``), ``plots/NAME.png`` (top view), and ``metrics.json``
with per-sequence and overall ``t_err_pct``, ``r_err_deg_per_100m``, ``ate_m`` and
``frames_per_s``. Without ``--checkpoint`` the hand-set parameters are evaluated.

With ``--distributed`` the command is one process of several (:mod:`jbevo.training.distributed`):
each loads and runs its share of the sequences (every ``N``-th) on its own devices, and process 0
gathers the trajectories, writes every file and scores them all, as one process would.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

from jbevo.cli import common
from jbevo.data import splits
from jbevo.data.catalog import load_sequences
from jbevo.data.pose_files import write_kitti
from jbevo.eval.batch import run_many
from jbevo.eval.plots import trajectory_top_view
from jbevo.eval.scores import format_scores, score, segment_lengths
from jbevo.files import write_json_atomic
from jbevo.geometry.bev_grid import BevGrid
from jbevo.models.bevo import Bevo
from jbevo.progress import progress
from jbevo.training import checkpoint, distributed

ATTITUDE_SOURCES = ("filter", "zero", "accel", "truth")


def load_model(
    path: Path | None,
    grid: BevGrid,
    imu_dt: float,
    attitude: str,
    bands: bool = False,
    kind: str = "bevo",
    forward_fusion: bool = False,
) -> Bevo:
    """The hand-set model of ``kind`` (``path`` None; :func:`jbevo.cli.common.hand_set_model`) or a
    checkpoint's (its own grid, bands and parts), projecting with ``attitude``."""
    if path is None:
        return common.hand_set_model(kind, grid, imu_dt, bands, attitude, forward_fusion)
    return dataclasses.replace(checkpoint.load_model(path, Bevo), attitude_source=attitude)


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser."""
    p = common.parser(
        "python -m jbevo.evaluate",
        __doc__,
        [
            common.dataset_options(default_frames=120),
            common.grid_option(BevGrid(0.1, (128, 128), near=7.5)),
            common.seed_option(1000, "first seed of the synthetic drives (training uses 0..)"),
            common.distributed_options(),
            common.model_option(),
        ],
    )
    p.add_argument("--checkpoint", type=Path, help="a checkpoint file or a training output folder (its best.ckpt)")
    p.add_argument("--sequences", nargs="+", help="sequence names (KITTI datasets) or count (synthetic; default 4)")
    p.add_argument("--attitude", choices=ATTITUDE_SOURCES, default="filter", help="pitch/roll for the BEV")
    p.add_argument("--warm-start", action="store_true", help="start from the truth's attitude and speed")
    p.add_argument(
        "--bands",
        action="store_true",
        help="hand-set model with the band geometry (jbevo.vision.bands; a checkpoint brings its own)",
    )
    p.add_argument("--out", type=Path, default=Path("runs/evaluation"))
    return p


def evaluate(args: argparse.Namespace) -> int:
    """Evaluate BEVO on the chosen sequences and write poses, plots and metrics."""
    if args.dataset == "synthetic":
        try:
            count = int(args.sequences[0]) if args.sequences else 4
        except ValueError:
            raise common.CommandError(f"--sequences for the synthetic dataset is a count, got {args.sequences[0]!r}") from None
        names: list[str] = [str(args.seed + i) for i in range(count)]
    else:
        names = list(args.sequences or splits.KITTI_TEST)
    common.join_job(args)
    if len(names) < jax.process_count():
        raise common.CommandError(f"{len(names)} sequence(s) cannot be shared by {jax.process_count()} processes")
    # This process's share; each sequence keeps the seed of its place in the whole list.
    mine = distributed.share(list(range(len(names))))
    with common.together():  # every process, or none, goes on
        with common.reading(f"the {args.dataset} dataset"):
            seqs = load_sequences(
                args.dataset,
                [names[i] for i in mine],
                args.frames,
                args.kitti_poses,
                args.kitti_root,
                args.camera,
                args.town,
                seed=args.seed,
                kitti_imu=args.kitti_imu,
                imu_dropouts=args.imu_dropouts,
                positions=mine,
                world=args.world,
            )
        common.require_imu(seqs, [names[i] for i in mine], args.attitude, "--attitude zero|truth")
        if args.dataset == "synthetic":
            names = [f"synthetic_{n}" for n in names]
        lengths = segment_lengths(args.dataset, args.frames)
        imu_dt = seqs[0].imu_dt if np.isfinite(seqs[0].imu_dt) else 0.01
        with common.reading(f"the checkpoint {args.checkpoint}"):
            model = load_model(args.checkpoint, args.grid, imu_dt, args.attitude, args.bands, args.model, args.forward_fusion)
    outputs, fps = run_many(model, seqs, args.warm_start)
    # Process 0 writes and scores every sequence: the trajectories and the truth (not the
    # images) of the others' shares come to it.
    frames = sum(q.num_frames for q in seqs)
    shares = distributed.gather_objects((mine, outputs, [_without_images(q) for q in seqs], frames, frames / fps))
    if not distributed.is_main():
        return 0
    gathered = sorted((item for share in shares for item in zip(*share[:3])), key=lambda item: item[0])
    outputs, seqs = [item[1] for item in gathered], [item[2] for item in gathered]
    # The processes run their shares at once: every frame over the slowest one's time.
    fps = sum(share[3] for share in shares) / max(share[4] for share in shares)
    devices = len(jax.devices())

    per_sequence = {}
    for name, out, seq in progress(list(zip(names, outputs, seqs)), "writing poses and plots"):
        write_kitti(args.out / "poses" / f"{name}.txt", np.asarray(out.poses, float))
        write_kitti(args.out / "poses" / f"{name}_gt.txt", np.asarray(seq.planar, float))
        trajectory_top_view(
            args.out / "plots" / f"{name}.png", np.asarray(seq.planar), {"BEVO": np.asarray(out.poses)}, title=name
        )
        s = score(out, seq, lengths)
        per_sequence[name] = {
            k: s[k] for k in ("t_err_pct", "r_err_deg_per_100m", "ate_m", "motion_rmse_m", "yaw_rmse_deg", "segments")
        }
        print(f"{name}: {format_scores(s)}")
    overall = score(outputs, seqs, lengths)  # the devkit pools the segments of all sequences
    overall = {k: overall[k] for k in ("t_err_pct", "r_err_deg_per_100m", "ate_m", "motion_rmse_m", "yaw_rmse_deg", "segments")}
    overall["frames_per_s"] = fps
    print(f"overall: {format_scores(overall | {'segment_lengths_m': list(lengths)})}  {fps:.0f} frames/s on {devices} device(s)")
    write_json_atomic(
        args.out / "metrics.json",
        {
            "overall": overall,
            "per_sequence": per_sequence,
            "segment_lengths_m": list(lengths),
            "checkpoint": str(args.checkpoint) if args.checkpoint else None,
            "attitude": args.attitude,
            "bands": model.bands is not None,
            "road_view": model.road is not None,  # the street model's parts (--model street or its checkpoint)
            "forward_fusion": model.forward is not None,
            "world": args.world,
            "warm_start": args.warm_start,
            "devices": [str(d) for d in jax.devices()],
            "processes": jax.process_count(),
        },
    )
    print(f"wrote {args.out}")
    return 0


def _without_images(seq):
    """``seq`` with an empty image stack: what scoring and drawing read, light to gather."""
    return eqx.tree_at(lambda q: q.images, seq, np.zeros((seq.num_frames, 0, 0), np.uint8))


def main(argv: list[str] | None = None) -> int:
    """Run the command with ``argv`` (default: the process's arguments); returns the exit code."""
    return common.run(build_parser(), evaluate, argv)


__all__ = ["build_parser", "evaluate", "load_model", "main"]
