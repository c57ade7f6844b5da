"""The KITTI-style odometry experiment (after the BEVO paper): train on sequences 00-08, test on
09 and 10, here with the synthetic world driven by the real KITTI ground-truth motion and a
simulated ADIS16448 IMU (or real KITTI data with ``--kitti-root``).

    python experiments/kitti_odometry.py --reference $JBEVO_REFERENCE_DATA [--epochs 3] [--frames 500]
        [--camera kitti|small] [--grid 0.1 256 4.0]

The synthetic camera is KITTI camera 0 at full size and the BEV 256x256 at 0.1 m/px by default.
Training uses 00-07 (``--frames`` first frames of each) and selects the checkpoint on 08; the
test sequences 09 and 10 are run whole, every variant starting from the true attitude and speed
at frame 0 (a filter initialised at a known state, as in the devkit's protocol the trajectories
start together). Variants on 09 and 10: BEVO learned and hand-set (with the band geometry of
``jbevo.bands`` unless ``--no-bands``), BEVO hand-set without bands, DPC with zero pitch/roll (no
IMU) with and without bands, accelerometer-only attitude, and ground-truth attitude (the upper
bound). Writes
``experiments/results/kitti_odometry.{json,md}`` and a trajectory figure per test sequence.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from jbevo.cli import evaluate, train
from jbevo.data.catalog import load_sequences
from jbevo.eval.batch import run_many
from jbevo.eval.devkit import SEGMENT_LENGTHS
from jbevo.eval.plots import trajectory_top_view
from jbevo.eval.scores import score
from jbevo.files import write_json_atomic, write_text_atomic
from jbevo.geometry import BevGrid

# label: (parameters, attitude source, band geometry)
VARIANTS = {
    "BEVO learned": ("learned", "filter", True),
    "BEVO hand-set": ("hand-set", "filter", True),
    "BEVO hand-set, no bands (session 4's model)": ("hand-set", "filter", False),
    "DPC + bands, zero pitch/roll (no IMU)": ("hand-set", "zero", True),
    "DPC, zero pitch/roll (no IMU)": ("hand-set", "zero", False),
    "accelerometer-only attitude": ("hand-set", "accel", False),
    "ground-truth attitude (upper bound)": ("hand-set", "truth", False),
}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reference", type=Path, default=os.environ.get("JBEVO_REFERENCE_DATA"))
    p.add_argument("--kitti-root", type=Path, help="real KITTI odometry data instead of the synthetic world")
    p.add_argument("--epochs", type=int, default=3)
    p.add_argument("--frames", type=int, default=500, help="training frames per sequence (0: all)")
    p.add_argument("--camera", choices=("small", "kitti"), default="kitti", help="synthetic camera: 128x416 or KITTI's 376x1241")
    p.add_argument("--grid", type=float, nargs=3, default=(0.1, 256, 4.0), metavar=("RES", "SIZE", "NEAR"), help="BEV")
    p.add_argument("--window", type=int, default=96, help="training window (frames); long enough for the bias to matter")
    p.add_argument(
        "--val-window", type=int, default=0, help="validation windows of 08 (0: the whole capped drive from a cold start)"
    )
    p.add_argument("--no-bands", action="store_true", help="train BEVO without the band geometry (jbevo.bands)")
    p.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = p.parse_args()
    if args.kitti_root is None and args.reference is None:
        sys.exit("give --reference (the shared data folder) or set JBEVO_REFERENCE_DATA")
    dataset = "kitti" if args.kitti_root else "kitti-synthetic"
    poses = None if args.kitti_root else args.reference / "kitti_odom" / "gt_poses"
    run_dir = args.out / "kitti_odometry_run"
    t0 = time.perf_counter()
    res, size, near = args.grid
    common = [
        "--dataset",
        dataset,
        "--frames",
        str(args.frames),
        "--out",
        str(run_dir),
        "--camera",
        args.camera,
        "--grid",
        str(res),
        str(int(size)),
        str(near),
    ]
    common += ["--kitti-root", str(args.kitti_root)] if args.kitti_root else ["--kitti-poses", str(poses)]
    bands = [] if args.no_bands else ["--bands"]
    train.main(
        [
            *common,
            *bands,
            "--train",
            *[f"{i:02d}" for i in range(8)],
            "--val",
            "08",
            "--epochs",
            str(args.epochs),
            "--window",
            str(args.window),
            "--val-window",
            str(args.val_window),
        ]
    )
    train_seconds = time.perf_counter() - t0

    test_names = ["09", "10"]
    seqs = load_sequences(dataset, test_names, 0, poses, args.kitti_root, args.camera, seed=900)
    grid = BevGrid(res, (int(size), int(size)), near=near)
    rows, outputs = {}, {}
    for label, (params, attitude, with_bands) in VARIANTS.items():
        ckpt = run_dir / "best.ckpt" if params == "learned" else None
        model = evaluate.load_model(ckpt, grid, seqs[0].imu_dt, attitude, with_bands and not args.no_bands)
        outs, fps = run_many(model, seqs, warm_start=True)
        outputs[label] = outs
        rows[label] = {}
        for name, out, seq in zip(test_names, outs, seqs):
            s = score(out, seq, SEGMENT_LENGTHS)
            rows[label][name] = {k: s[k] for k in ("t_err_pct", "r_err_deg_per_100m", "ate_m")}
        # Both test sequences together: the devkit pools their segments.
        pooled = score(outs, seqs, SEGMENT_LENGTHS)
        rows[label]["pooled"] = {k: pooled[k] for k in ("t_err_pct", "r_err_deg_per_100m")}
        rows[label]["frames_per_s"] = fps
        print(label, rows[label])
    for i, name in enumerate(test_names):
        trajectory_top_view(
            args.out / f"kitti_odometry_{name}.png",
            np.asarray(seqs[i].planar),
            {k: np.asarray(v[i].poses) for k, v in outputs.items()},
            title=f"sequence {name} ({dataset})",
        )
    lines = [
        "| variant | 09 t_err % | 09 r_err deg/100m | 09 ATE m | 10 t_err % | 10 r_err deg/100m | 10 ATE m "
        "| 09+10 t_err % | 09+10 r_err deg/100m |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for label, r in rows.items():
        cells = [f"{r[n][k]:.2f}" for n in test_names for k in ("t_err_pct", "r_err_deg_per_100m", "ate_m")]
        cells += [f"{r['pooled'][k]:.2f}" for k in ("t_err_pct", "r_err_deg_per_100m")]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    table = "\n".join(lines) + "\n"
    print(table)
    write_text_atomic(args.out / "kitti_odometry.md", table)
    write_json_atomic(
        args.out / "kitti_odometry.json",
        {
            "dataset": dataset,
            "train": [f"{i:02d}" for i in range(8)],
            "checkpoint_selection": "08",
            "test": test_names,
            "training_frames_per_sequence": args.frames,
            "epochs": args.epochs,
            "window": args.window,
            "val_window": args.val_window,
            "training_seconds": train_seconds,
            "results": rows,
            "bev": {"resolution": res, "shape": [int(size)] * 2, "near": near},
            "camera": args.camera if dataset == "kitti-synthetic" else "KITTI",
            "bands": not args.no_bands,
        },
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
