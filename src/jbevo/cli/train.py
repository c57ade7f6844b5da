"""Train BEVO's parameters with optax through ``jax.grad`` of the whole recursion.

    python -m jbevo.train                       # the built-in synthetic drives
    python -m jbevo.train --dataset kitti-synthetic --kitti-poses poses/ --window 96 --start warm --val-start warm
    python -m jbevo.train --dataset kitti --kitti-root /data/kitti/odometry --kitti-imu $JBEVO_REFERENCE_DATA/kitti_odom/imu --train 00 01 --val 08 --window 96 --start warm

Training runs on windows of ``--window`` frames (stride half a window; 0, the default: the whole
sequences), shuffled into batches of ``--batch`` (vmapped), each started from a cold start (the
IMU alone, as a drive from rest; the default) or warm (``--start warm``: the truth's attitude and
speed at its first frame, as if the filter had run before: for windows cut from the middle of a
drive); the loss is :func:`jbevo.models.losses.motion_loss` averaged over the batch. After every
epoch the model runs over the validation sequences the way they are scored: whole, from a cold
start (``--val-start warm`` for warm), or cut into warm-started windows of ``--val-window``
frames. The hand-set parameters are the first candidate; ``OUT/best.ckpt`` keeps whichever
validates best (``t_err_pct``, or ATE where the validation drives are too short for any segment)
and ``OUT/last.ckpt`` the latest state (both atomic); ``--resume`` continues from
``OUT/last.ckpt``. The validation metrics before and after training are printed and written to
``OUT/metrics.json``.

Each batch is split over every device (``--batch`` a multiple of their count; on a CPU,
``XLA_FLAGS=--xla_force_host_platform_device_count=4`` makes four), the gradient averaged across
them: the result equals one device's to round-off. With ``--distributed`` the command is one
process of several (:mod:`jbevo.training.distributed`): each reads the training drives, slices
only its devices' windows of each batch, and validates like the others; process 0 writes the
checkpoints and metrics.

    python -m jbevo.train --coordinator localhost:6789 --num-processes 2 --process-id 0 &
    python -m jbevo.train --coordinator localhost:6789 --num-processes 2 --process-id 1
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jbevo.cli import common
from jbevo.data import splits
from jbevo.data.catalog import load_sequences
from jbevo.data.sequence import Sequence
from jbevo.eval.scores import SHORT_SEGMENTS, criterion, format_scores, segment_lengths
from jbevo.files import write_json_atomic
from jbevo.geometry.bev_grid import BevGrid
from jbevo.models.losses import motion_loss
from jbevo.training import distributed
from jbevo.training.data_parallel import DataParallel
from jbevo.training.loop import make_step, save_epoch, start_run, train_epochs
from jbevo.training.validation import validate
from jbevo.training.windows import training_windows

DEFAULT_GRID = BevGrid(0.1, (128, 128), near=7.5)


def load_datasets(args: argparse.Namespace) -> tuple[list[Sequence], list[Sequence], tuple[float, ...]]:
    """``(train, validation, segment lengths)`` for the chosen dataset."""
    if args.dataset == "synthetic":
        seeds = [str(args.seed + i) for i in range(args.sequences)]
        n_val = max(1, args.sequences // 5)
        train_names, val_names = seeds[:-n_val], seeds[-n_val:]
    else:
        train_names, val_names = args.train, args.val
        if shared := sorted(set(train_names) & set(val_names)):
            raise common.CommandError(f"sequences {', '.join(shared)} would both train and select the checkpoint")
    options = dict(
        frames=args.frames,
        kitti_poses=args.kitti_poses,
        kitti_root=args.kitti_root,
        kitti_imu=args.kitti_imu,
        imu_dropouts=args.imu_dropouts,
        camera=args.camera,
        town=args.town,
        world=args.world,
    )
    with common.reading(f"the {args.dataset} dataset"):
        train = load_sequences(args.dataset, train_names, seed=args.seed, **options)
        val = load_sequences(args.dataset, val_names, seed=args.seed + 100, **options)
    common.require_imu(train + val, list(train_names) + list(val_names), "filter")
    return train, val, segment_lengths(args.dataset, args.frames)


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser."""
    p = common.parser(
        "python -m jbevo.train",
        __doc__,
        [
            common.dataset_options(default_frames=120),
            common.grid_option(DEFAULT_GRID),
            common.optimizer_options(lr=0.03, epochs=24, window=0, batch=4, whole=True),
            common.seed_option(),
            common.distributed_options(),
            common.model_option(),
        ],
    )
    p.add_argument(
        "--train", nargs="+", default=list(splits.KITTI_FIT), help="training sequence names (KITTI datasets; default 00-07)"
    )
    p.add_argument(
        "--val", nargs="+", default=list(splits.KITTI_VALIDATION), help="validation sequence names (KITTI datasets; default 08)"
    )
    p.add_argument(
        "--sequences", type=common.positive_int, default=5, help="number of built-in synthetic drives (one fifth validate)"
    )
    p.add_argument(
        "--start",
        choices=("warm", "cold"),
        default="cold",
        help="training windows start from the IMU alone (cold, as a drive from rest) or from the truth's attitude and speed (warm)",
    )
    p.add_argument(
        "--val-window",
        type=common.non_negative_int,
        default=0,
        help="validate on windows of this many frames, warm-started (0: whole sequences, started as --val-start)",
    )
    p.add_argument(
        "--val-start",
        choices=("cold", "warm"),
        default="cold",
        help="how whole validation sequences start (the scored run: cold from rest, or warm from the truth)",
    )
    p.add_argument(
        "--bands",
        action="store_true",
        help="refine each frame with the BEV's near and far bands (jbevo.vision.bands; KITTI-size images)",
    )
    p.add_argument("--out", type=Path, default=Path("runs/bevo"))
    return p


def train(args: argparse.Namespace) -> int:
    """Train BEVO and write the checkpoints and the validation metrics."""
    t_start = time.perf_counter()
    if args.dataset == "synthetic" and args.sequences < 2:
        raise common.CommandError("the synthetic dataset needs --sequences >= 2 (one fifth, at least one, validates)")
    common.join_job(args)
    parallel = DataParallel.create()
    with common.together():  # every process, or none, goes on
        train_seqs, val_seqs, lengths = load_datasets(args)
        if args.val_window:  # windows of a few seconds hold no 100 m segments
            lengths = SHORT_SEGMENTS
        imu_dt = train_seqs[0].imu_dt if np.isfinite(train_seqs[0].imu_dt) else 0.01
        with common.reading(f"the run in {args.out}"):
            model, params, static, optimizer, opt_state, progress = start_run(
                common.hand_set_model(args.model, args.grid, imu_dt, args.bands, forward_fusion=args.forward_fusion),
                args.out,
                args.lr,
                args.clip,
                args.resume,
                "best_t_err_pct",
            )
            windows = training_windows(train_seqs, args.window)
        common.check_batch(parallel, args.batch, len(windows))
    del train_seqs  # the windows hold the drives; a window is sliced from them when drawn
    print(
        f"BEVO: {model.num_learnable()} learnable parameters; {len(windows.drives)} training and {len(val_seqs)} validation "
        f"sequences ({args.dataset}); segment lengths {list(lengths)} m; {len(windows)} windows in batches of {args.batch} "
        f"over {parallel.size} device(s) in {jax.process_count()} process(es)"
    )

    hand_set = common.hand_set_model(
        args.model, model.grid, imu_dt, model.bands is not None, forward_fusion=model.forward is not None
    )
    val_warm = args.val_start == "warm"
    before = validate(hand_set, val_seqs, lengths, args.val_window, val_warm)
    print(f"validation before training (hand-set): {format_scores(before)}")
    if progress["epoch"] == 0:
        # The hand-set parameters are the first candidate: a learned checkpoint replaces them
        # only where it validates better.
        save_epoch(args.out, hand_set, opt_state, progress, "best_t_err_pct", criterion(before))
    warm = args.start == "warm"

    def loss(m, batch):
        # A warm window starts from the truth at its first frame, as if the filter had run
        # before (Bevo.__call__); a cold one from the IMU alone, as a drive from rest does.
        out = jax.vmap(lambda q: m(q, warm_start=warm))(batch)
        return jnp.mean(jax.vmap(lambda o, s: motion_loss(o, s, args.yaw_weight))(out, batch))

    step = make_step(static, optimizer, loss, parallel)
    epochs = train_epochs(step, params, static, opt_state, windows, args.batch, args.seed, progress, args.epochs, parallel)
    with common.diverged_as_command_error():
        for model, opt_state, mean_loss in epochs:
            val = validate(model, val_seqs, lengths, args.val_window, val_warm)
            epoch = progress["epoch"]
            progress["history"].append(
                {"epoch": epoch, "loss": mean_loss, "val_t_err_pct": val["t_err_pct"], "val_ate_m": val["ate_m"]}
            )
            print(f"epoch {epoch}: loss {mean_loss:.5f}  validation {format_scores(val)}")
            save_epoch(args.out, model, opt_state, progress, "best_t_err_pct", criterion(val))

    if not distributed.is_main():
        return 0  # process 0 reports the run and writes its metrics
    best, best_epoch = common.best_checkpoint(args.out)
    after = validate(best, val_seqs, lengths, args.val_window, val_warm)
    print(f"validation after training (best checkpoint, epoch {best_epoch}): {format_scores(after)}")
    whole = {}
    if args.val_window:
        whole = {
            "hand_set": validate(hand_set, val_seqs, lengths, 0, val_warm),
            "learned": validate(best, val_seqs, lengths, 0, val_warm),
        }
        print(f"whole validation sequences ({args.val_start} start), hand-set: {format_scores(whole['hand_set'])}")
        print(f"whole validation sequences ({args.val_start} start), learned:  {format_scores(whole['learned'])}")
    write_json_atomic(
        args.out / "metrics.json",
        {
            "dataset": args.dataset,
            "validation": f"windows of {args.val_window} frames, warm start"
            if args.val_window
            else f"whole sequences, {args.val_start} start",
            "best_epoch": best_epoch,
            "before": before,
            "after": after,
            "whole_sequences": whole,
            "learnable_parameters": model.num_learnable(),
            "epochs": progress["epoch"],
            "skipped_steps": progress.get("skipped_steps", 0),
            "history": progress["history"],
            "seconds": time.perf_counter() - t_start,
            "devices": parallel.size,
            "processes": jax.process_count(),
            "args": common.json_args(args),
        },
    )
    print(f"wrote {args.out / 'metrics.json'} ({time.perf_counter() - t_start:.0f} s)")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command with ``argv`` (default: the process's arguments); returns the exit code."""
    return common.run(build_parser(), train, argv)


__all__ = ["build_parser", "load_datasets", "main", "train"]
