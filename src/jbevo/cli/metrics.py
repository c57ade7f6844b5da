"""``python -m jbevo.metrics``: KITTI devkit t_err/r_err, ATE and RPE of an estimated trajectory
(KITTI or TUM pose files), computed in float64.

    python -m jbevo.metrics --gt GT.txt --est EST.txt [--align sim3|se3|4dof|se2|none]
        [--rpe-delta 1 --rpe-unit frames|m] [--json out.json] [--plot out.png]

A drive shorter than the shortest devkit segment (100 m) has no t_err or r_err: the command
says so and ``--json`` writes ``null`` for them.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax
import jax.numpy as jnp

from jbevo.cli import common
from jbevo.data.pose_files import match_frames, read_poses
from jbevo.eval import plots
from jbevo.eval.trajectory_metrics import evaluate, summary
from jbevo.files import write_json_atomic


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser."""
    p = common.parser("python -m jbevo.metrics", __doc__)
    p.add_argument("--gt", type=Path, required=True, help="ground-truth poses (KITTI 12/13 columns or TUM)")
    p.add_argument("--est", type=Path, required=True, help="estimated poses (same formats)")
    p.add_argument(
        "--align",
        choices=["sim3", "se3", "4dof", "se2", "none"],
        default="none",
        help="alignment of the estimate before the metrics (se2 = 4dof about the gravity axis)",
    )
    p.add_argument(
        "--up-axis",
        type=int,
        choices=(0, 1, 2),
        default=1,
        help="gravity axis for 4dof/se2: 1 = KITTI camera y (default), 2 = z-up",
    )
    p.add_argument("--rpe-delta", type=common.positive_float, default=1.0)
    p.add_argument("--rpe-unit", choices=["frames", "m"], default="frames")
    p.add_argument("--json", type=Path, help="write the numbers to this JSON file")
    p.add_argument("--plot", type=Path, help="write a top-view PNG of both trajectories")
    return p


def metrics(args: argparse.Namespace) -> int:
    """Score one estimated trajectory against its ground truth."""
    with common.reading("the pose files"):
        gt, est, valid = match_frames(read_poses(args.gt), read_poses(args.est))
    if args.rpe_unit == "frames" and args.rpe_delta != int(args.rpe_delta):
        raise common.CommandError(f"--rpe-delta in frames must be a whole number, got {args.rpe_delta}")
    kind = "4dof" if args.align == "se2" else args.align
    with jax.enable_x64(True):
        ev = evaluate(jnp.asarray(gt), jnp.asarray(est), jnp.asarray(valid), kind, args.up_axis, args.rpe_delta, args.rpe_unit)
        numbers = summary(ev)
    numbers["alignment"] = args.align
    if numbers["segments"]:
        print(f"t_err  {numbers['t_err_pct']:.6f} %   ({numbers['segments']} segments)")
        print(f"r_err  {numbers['r_err_deg_per_100m']:.6f} deg/100m")
    else:
        print("t_err  none: no segment of 100 m or more in this drive")
        print("r_err  none")
    print(f"ATE    {numbers['ate_m']:.6f} m   (alignment: {args.align})")
    print(f"RPE    {numbers['rpe_trans_m']:.6f} m, {numbers['rpe_rot_deg']:.6f} deg   (delta {args.rpe_delta:g} {args.rpe_unit})")
    if args.json:
        write_json_atomic(args.json, numbers)
    if args.plot:
        v = valid.astype(bool)
        plane = (0, 2) if args.up_axis == 1 else (0, 1)
        plots.trajectory_top_view(args.plot, ev.gt[v], {args.est.stem: ev.aligned[v]}, plane=plane)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command with ``argv`` (default: the process's arguments); returns the exit code."""
    return common.run(build_parser(), metrics, argv)


__all__ = ["build_parser", "main", "metrics"]
