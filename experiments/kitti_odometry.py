"""The KITTI-style odometry experiment (after the BEVO paper): train on sequences 00-07, select
the checkpoint on 08, test on 09 and 10, here with the synthetic world driven by the real KITTI
ground-truth motion and a simulated ADIS16448 IMU, or with ``--real-imu`` the real KITTI IMU
(calibrated per recording day on 00-08, the frames rendered at the attitude it sees; 03 has no
IMU and is left out of training), or real KITTI data with ``--kitti-root`` (and ``--kitti-imu``).

    python experiments/kitti_odometry.py --reference $JBEVO_REFERENCE_DATA [--seeds 0 1 2] [--epochs 3] [--real-imu]
        [--world street] [--model street]

KITTI camera 0 at full size, a 256 x 256 BEV at 0.1 m/px from 4 m, BEVO with the band geometry.
Each training seed (the rendering's and IMU's noise, and the shuffling) trains on the first
``--frames`` frames of 00-07 in windows of 96 frames, each warm-started, and keeps the checkpoint
(the hand-set parameters included) with the lowest t_err on the first ``--frames`` frames of 08
run whole from a warm start, as the test runs. The test sequences 09 and 10 are run whole,
every variant from the true attitude and speed at frame 0 (the devkit's trajectories start
together), and scored with the devkit (100-800 m; 09+10 pools both sequences' segments).
Variants: BEVO learned (each seed), BEVO hand-set with and without bands, DPC with zero
pitch/roll (no IMU) with and without bands, accelerometer-only attitude, the true attitude
(an upper bound) and the street preset (:func:`jbevo.models.presets.street_model`, hand-set).
``--world street`` renders every sequence in the street world (:mod:`jbevo.data.synthetic.street`:
structures beside the road, the drive's own grade and banking, a camera mounted off its nominal
pose, exposure changes and vignetting). Writes ``experiments/results/kitti_odometry.json``
(``_real_imu`` with the real IMU, ``_street`` in the street world) and a trajectory figure per
sequence, 00-10: the test sequences whole, the training and validation sequences over the
frames the first seed trained or validated on, as rendered for it (seed 0's rendering where no
seed trained; their scores under ``training_sequences``). A seed whose training fails (the
command stops on non-finite values) is recorded as failed; ``--seeds`` with no value runs the
hand-set rows only. ``--model street`` trains the street preset (its camera-to-road calibration,
road view and bands learned) instead of BEVO.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from jbevo.cli import train
from jbevo.cli.common import MODELS
from jbevo.data.catalog import load_sequences
from jbevo.data.synthetic.street import WORLDS
from jbevo.eval.batch import run_many
from jbevo.eval.devkit import SEGMENT_LENGTHS
from jbevo.eval.plots import trajectory_top_view
from jbevo.eval.scores import score
from jbevo.files import write_json_atomic
from jbevo.geometry import BevGrid
from jbevo.models import Bevo
from jbevo.models.presets import street_model
from jbevo.training import checkpoint

RESULTS = Path(__file__).resolve().parent / "results"
TEST = ("09", "10")
# what the learned rows are, per --model
LEARNED = {"bevo": "BEVO learned", "street": "street preset learned"}
# label: (attitude source, band geometry)
HAND_SET = {
    "BEVO hand-set": ("filter", True),
    "BEVO hand-set without bands": ("filter", False),
    "DPC + bands, zero pitch/roll (no IMU)": ("zero", True),
    "DPC, zero pitch/roll (no IMU)": ("zero", False),
    "accelerometer-only attitude": ("accel", False),
    "true attitude (upper bound)": ("truth", False),
}


def scores(model: Bevo, seqs, names=TEST) -> dict:
    outs, fps = run_many(model, seqs, warm_start=True)
    row = {
        name: {k: score(o, s, SEGMENT_LENGTHS)[k] for k in ("t_err_pct", "r_err_deg_per_100m", "ate_m")}
        for name, o, s in zip(names, outs, seqs)
    }
    pooled = score(outs, seqs, SEGMENT_LENGTHS)
    row["pooled"] = {k: pooled[k] for k in ("t_err_pct", "r_err_deg_per_100m")}
    row["frames_per_s"] = fps
    return row | {"_outputs": outs}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reference", type=Path, default=os.environ.get("JBEVO_REFERENCE_DATA"))
    p.add_argument("--kitti-root", type=Path, help="real KITTI odometry data instead of the synthetic world")
    p.add_argument(
        "--kitti-imu",
        type=Path,
        help="with --kitti-root: the folder of the real KITTI IMU files NN.mat (03 has none: not trained on)",
    )
    p.add_argument(
        "--real-imu",
        action="store_true",
        help="the synthetic world with the real KITTI IMU (reference kitti_odom/imu, calibrated per day on 00-08; 03 has none: "
        "not trained on); writes kitti_odometry_real_imu.json",
    )
    p.add_argument(
        "--world",
        choices=sorted(WORLDS),
        default="flat",
        help="the synthetic world: flat, or street (structures, slopes, camera mounting, exposure; records *_street.json)",
    )
    p.add_argument(
        "--model",
        choices=MODELS,
        default="bevo",
        help="the model the seeds train: bevo (BEVO with bands) or street (the street preset, camera against the road "
        "learned too)",
    )
    p.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 2], help="training seeds (none: the hand-set rows only)")
    p.add_argument("--epochs", type=int, default=3)
    p.add_argument("--frames", type=int, default=500, help="training and validation frames per sequence (0: all)")
    p.add_argument("--window", type=int, default=96, help="training window (frames); long enough for the bias to matter")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if args.kitti_root is None and args.reference is None:
        sys.exit("give --reference (the shared data folder) or set JBEVO_REFERENCE_DATA")
    dataset = "kitti" if args.kitti_root else "kitti-synthetic"
    poses = None if args.kitti_root else args.reference / "kitti_odom" / "gt_poses"
    source = ["--kitti-root", str(args.kitti_root)] if args.kitti_root else ["--kitti-poses", str(poses)]
    if args.real_imu and not args.kitti_root:
        args.kitti_imu = args.reference / "kitti_odom" / "imu"
    if args.kitti_imu:
        source += ["--kitti-imu", str(args.kitti_imu)]
    fit = [f"{i:02d}" for i in range(8) if not (args.kitti_imu and i == 3)]
    record = ("kitti_odometry_real_imu" if args.kitti_imu else "kitti_odometry") + ("_street" if args.world == "street" else "")
    source += ["--world", args.world]
    grid = BevGrid(0.1, (256, 256), near=4.0)

    learned, training = {}, {}
    seqs = load_sequences(
        dataset, list(TEST), 0, poses, args.kitti_root, "kitti", seed=900, kitti_imu=args.kitti_imu, world=args.world
    )
    for seed in args.seeds:
        run = args.out / f"{record}_run" / f"seed{seed}"
        t0 = time.perf_counter()
        status = train.main(
            [
                "--dataset",
                dataset,
                *source,
                "--frames",
                str(args.frames),
                "--camera",
                "kitti",
                "--grid",
                "0.1",
                "256",
                "4.0",
                "--bands",
                "--model",
                args.model,
                "--train",
                *fit,
                "--val",
                "08",
                "--epochs",
                str(args.epochs),
                "--window",
                str(args.window),
                "--start",
                "warm",
                "--val-window",
                "0",
                "--val-start",
                "warm",
                "--seed",
                str(seed),
                "--out",
                str(run),
            ]
        )
        if status != 0:  # the command printed why (e.g. the model diverged); the seed is recorded as failed
            training[str(seed)] = {"seconds": time.perf_counter() - t0, "failed": True}
            continue
        metrics = json.loads((run / "metrics.json").read_text())
        training[str(seed)] = {
            "seconds": time.perf_counter() - t0,
            "best_epoch": metrics["best_epoch"],
            "skipped_steps": metrics.get("skipped_steps", 0),
            "validation_hand_set": metrics["before"],
            "validation_learned": metrics["after"],
        }
        learned[str(seed)] = scores(checkpoint.load_model(run / "best.ckpt", Bevo), seqs)
        print("learned", seed, {k: v for k, v in learned[str(seed)].items() if k != "_outputs"})
    hand = {}
    models = hand_set_models(grid, seqs[0].imu_dt)
    for label, model in models.items():
        hand[label] = scores(model, seqs)
        print(label, {k: v for k, v in hand[label].items() if k != "_outputs"})
    first = next(iter(learned), None)  # the first seed that trained
    drawn = {label: models[label] for label in ("BEVO hand-set", "BEVO hand-set without bands", "true attitude (upper bound)")}
    if first is not None:
        learned_model = checkpoint.load_model(args.out / f"{record}_run" / f"seed{first}" / "best.ckpt", Bevo)
        drawn = {f"{LEARNED[args.model]} (seed {first})": learned_model} | drawn
    if args.world == "street":
        drawn["street preset (hand-set)"] = models["street preset (hand-set)"]
    title = f"({dataset}{', real IMU' if args.kitti_imu else ''}{', street world' if args.world == 'street' else ''})"
    draw(
        args.out / record,
        seqs,
        list(TEST),
        {label: learned[first] if label.startswith(LEARNED[args.model]) else hand[label] for label in drawn},
        title,
    )
    # The training and validation sequences as the first seed trained on them (its rendering).
    seen_scores: dict[str, dict] = {}
    rendered = int(first) if first is not None else (args.seeds[0] if args.seeds else 0)
    for names, seed in ((fit, rendered), (["08"], rendered + 100)):
        part = load_sequences(
            dataset, names, args.frames, poses, args.kitti_root, "kitti", seed=seed, kitti_imu=args.kitti_imu, world=args.world
        )
        rows = {label: scores(model, part, names) for label, model in drawn.items()}
        draw(args.out / record, part, names, rows, title + ", the frames trained or validated on")
        for label, row in rows.items():
            seen_scores.setdefault(label, {}).update({n: row[n] for n in names})
        del part
    strip = lambda rows: {k: {kk: vv for kk, vv in v.items() if kk != "_outputs"} for k, v in rows.items()}
    write_json_atomic(
        args.out / f"{record}.json",
        {
            "dataset": dataset,
            "imu": "real KITTI IMU, calibrated per recording day on 00-08" if args.kitti_imu else "simulated ADIS16448",
            "train": fit,
            "checkpoint_selection": "08, whole, warm start",
            "test": list(TEST),
            "frames_per_training_sequence": args.frames,
            "epochs": args.epochs,
            "window": args.window,
            "bev": {"resolution": 0.1, "shape": [256, 256], "near": 4.0},
            "camera": "KITTI camera 0" if dataset == "kitti" else "kitti",
            "model": args.model,
            "learned_label": LEARNED[args.model],
            "learned": strip(learned),
            "hand_set": strip(hand),
            "training": training,
            "world": args.world,
            "training_sequences": seen_scores,
        },
    )
    return 0


def hand_set_models(grid: BevGrid, imu_dt: float) -> dict[str, Bevo]:
    """The hand-set rows (``HAND_SET``) and the street preset."""
    models = {
        label: dataclasses.replace(Bevo.create(grid, imu_dt, bands=bands), attitude_source=attitude)
        for label, (attitude, bands) in HAND_SET.items()
    }
    return models | {"street preset (hand-set)": street_model(imu_dt, grid)}


def draw(prefix: Path, seqs, names, rows: dict[str, dict], title: str) -> None:
    """One top view per sequence (``<prefix>_<name>.png``), the legend below the axes."""
    for i, name in enumerate(names):
        trajectory_top_view(
            f"{prefix}_{name}.png",
            np.asarray(seqs[i].planar),
            {label: np.asarray(row["_outputs"][i].poses) for label, row in rows.items()},
            title=f"sequence {name} {title}",
            legend_below=True,
        )


if __name__ == "__main__":
    raise SystemExit(main())
