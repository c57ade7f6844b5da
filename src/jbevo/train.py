"""Train BEVO's parameters with optax through ``jax.grad`` of the whole recursion.

    python -m jbevo.train                       # built-in synthetic drives, < 5 min on 2 cores
    python -m jbevo.train --dataset kitti-synthetic --kitti-poses $JBEVO_REFERENCE_DATA/kitti_odom/gt_poses
    python -m jbevo.train --dataset kitti --kitti-root /data/kitti/odometry --train 00 01 --val 09

Windows of ``--window`` frames (stride half a window) are cut from the training sequences and
shuffled into batches of ``--batch`` (vmapped); each window starts warm (the truth's attitude and
speed at its first frame); the loss is :func:`jbevo.odometry.motion_loss` averaged over the
batch. After every epoch the model runs over the validation sequences, cut into windows of
``--val-window`` frames like the training data (``--val-window 0``: whole sequences from a cold
start; with windows, the whole sequences are also scored at the end);
``OUT/best.ckpt`` keeps the best validation ``t_err_pct`` (ATE where the validation drives are
too short for any segment) and ``OUT/last.ckpt`` the latest state
(both atomic); ``--resume`` continues from ``OUT/last.ckpt``. The validation metrics before and
after training are printed and written to ``OUT/metrics.json``.
"""

from __future__ import annotations

import argparse
import functools
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jbevo import checkpoint
from jbevo.camera import BevGrid
from jbevo.datasets import sequence as sq
from jbevo.datasets.catalog import DATASETS, load_sequences
from jbevo.datasets.world import TOWNS
from jbevo.epochs import make_step, run_epoch, save_epoch, start_run
from jbevo.files import write_json_atomic
from jbevo.odometry import Bevo, motion_loss
from jbevo.odometry_metrics import SHORT_SEGMENTS, score, segment_lengths


def load_datasets(args) -> tuple[list[sq.Sequence], list[sq.Sequence], tuple[float, ...]]:
    """``(train, validation, segment lengths)`` for the chosen dataset."""
    if args.dataset == "synthetic":
        seeds = [args.seed + i for i in range(args.sequences)]
        n_val = max(1, args.sequences // 5)
        train_names, val_names = seeds[:-n_val], seeds[-n_val:]
    else:
        train_names, val_names = args.train, args.val
    try:
        load = functools.partial(
            load_sequences, args.dataset, frames=args.frames, kitti_poses=args.kitti_poses,
            kitti_root=args.kitti_root, camera=args.camera, town=args.town,
        )
        train, val = load(train_names, seed=args.seed), load(val_names, seed=args.seed + 100)
    except (ValueError, FileNotFoundError) as error:
        raise SystemExit(str(error)) from None
    return train, val, segment_lengths(args.dataset, args.frames)


def training_windows(seqs: list[sq.Sequence], window: int, stride: int | None = None) -> sq.Sequence:
    stride = max(1, window // 2) if stride is None else stride
    parts = [sq.windows(s, window, stride) for s in seqs if s.num_frames >= window]
    if not parts:
        raise SystemExit(f"no training sequence has {window} frames; lower --window")
    return jax.tree_util.tree_map(lambda *x: jnp.concatenate(x), *parts)


def validate(model: Bevo, seqs: list[sq.Sequence], lengths, window: int = 0) -> dict:
    """Scores over the validation sequences: whole sequences from a cold start (``window`` 0),
    or windows of ``window`` frames warm-started from the truth (how the model is trained)."""
    if window:
        batch = training_windows(seqs, window, stride=window)
        out = eqx.filter_jit(jax.vmap(lambda m, s: m(s, warm_start=True), in_axes=(None, 0)))(model, batch)
        return score(out, batch, lengths)
    run = eqx.filter_jit(lambda m, s: m(s))
    outputs = [run(model, s) for s in seqs]
    if len({s.num_frames for s in seqs}) == 1:
        return score(sq.stack(outputs), sq.stack(seqs), lengths)
    per = [score(o, s, lengths) for o, s in zip(outputs, seqs)]
    merged = {k: float(np.mean([p[k] for p in per])) for k in ("t_err_pct", "r_err_deg_per_100m", "ate_m", "motion_rmse_m", "yaw_rmse_deg")}
    return merged | {"segments": sum(p["segments"] for p in per)}


def _print_metrics(label: str, m: dict) -> None:
    print(
        f"{label}: t_err {m['t_err_pct']:.3f} %  r_err {m['r_err_deg_per_100m']:.3f} deg/100m  ATE {m['ate_m']:.3f} m  "
        f"per-frame motion {100 * m['motion_rmse_m']:.2f} cm, yaw {m['yaw_rmse_deg']:.3f} deg"
    )


def parse_args(argv):
    p = argparse.ArgumentParser(prog="python -m jbevo.train", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", choices=DATASETS, default="synthetic")
    p.add_argument("--kitti-poses", type=Path, help="folder of KITTI pose files (kitti-synthetic)")
    p.add_argument("--kitti-root", type=Path, help="KITTI odometry root folder (kitti)")
    p.add_argument("--train", nargs="+", default=list(sq.KITTI_TRAIN), help="training sequence names (KITTI datasets)")
    p.add_argument("--val", nargs="+", default=list(sq.KITTI_TEST), help="validation sequence names (KITTI datasets)")
    p.add_argument("--sequences", type=int, default=5, help="number of built-in synthetic drives (one fifth validate)")
    p.add_argument("--frames", type=int, default=120, help="frames per sequence (synthetic; a cap for kitti-synthetic, 0 = all)")
    p.add_argument("--town", choices=sorted(TOWNS), default="town01")
    p.add_argument("--camera", choices=("small", "kitti"), default="small", help="kitti-synthetic camera")
    p.add_argument("--window", type=int, default=32, help="training window length (frames)")
    p.add_argument("--batch", type=int, default=4, help="windows per step (vmapped)")
    p.add_argument("--val-window", type=int, default=40, help="validate on windows of this many frames, warm-started like training (0: whole sequences, cold start)")
    p.add_argument("--epochs", type=int, default=8)
    p.add_argument("--lr", type=float, default=0.03, help="Adam learning rate (the parameters are logs and exponents)")
    p.add_argument("--clip", type=float, default=1.0, help="global gradient-norm clip")
    p.add_argument("--yaw-weight", type=float, default=10.0, help="metres per radian of yaw error in the loss")
    p.add_argument("--grid", type=float, nargs=3, default=(0.1, 128, 7.5), metavar=("RES", "SIZE", "NEAR"), help="BEV metres/pixel, pixels, nearest metres")
    p.add_argument("--bands", action="store_true", help="refine each frame with the BEV's near and far bands (jbevo.bands; KITTI-size images)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("runs/bevo"))
    p.add_argument("--resume", action="store_true", help="continue from OUT/last.ckpt")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    t_start = time.perf_counter()
    train_seqs, val_seqs, lengths = load_datasets(args)
    if args.val_window:  # windows of a few seconds hold no 100 m segments
        lengths = SHORT_SEGMENTS
    imu_dt = train_seqs[0].imu_dt if np.isfinite(train_seqs[0].imu_dt) else 0.01
    res, size, near = args.grid
    model, params, static, optimizer, opt_state, progress = start_run(
        Bevo.create(BevGrid(res, (int(size), int(size)), near=near), imu_dt, bands=args.bands), args.out, args.lr, args.clip, args.resume,
        "best_t_err_pct")
    print(f"BEVO: {model.num_learnable()} learnable parameters; {len(train_seqs)} training and {len(val_seqs)} validation sequences "
          f"({args.dataset}); segment lengths {list(lengths)} m")

    hand_set = Bevo.create(model.grid, imu_dt, bands=model.bands is not None)
    before = validate(hand_set, val_seqs, lengths, args.val_window)
    _print_metrics("validation before training (hand-set)", before)
    windows = training_windows(train_seqs, args.window)

    def loss(m, batch):
        # Windows start mid-drive: warm-started from the truth at their first frame, as if the
        # filter had run before (see Bevo.__call__).
        out = jax.vmap(lambda q: m(q, warm_start=True))(batch)
        return jnp.mean(jax.vmap(lambda o, s: motion_loss(o, s, args.yaw_weight))(out, batch))

    step = make_step(static, optimizer, loss)
    rng = np.random.default_rng(args.seed + progress["epoch"])
    for epoch in range(progress["epoch"], args.epochs):
        params, opt_state, mean_loss, steps = run_epoch(step, params, opt_state, windows, args.batch, rng, f"epoch {epoch + 1}/{args.epochs}")
        model = eqx.combine(params, static)
        val = validate(model, val_seqs, lengths, args.val_window)
        progress["epoch"], progress["step"] = epoch + 1, progress["step"] + steps
        progress["history"].append({"epoch": epoch + 1, "loss": mean_loss, "val_t_err_pct": val["t_err_pct"], "val_ate_m": val["ate_m"]})
        print(f"epoch {epoch + 1}: loss {mean_loss:.5f}  val t_err {val['t_err_pct']:.3f} %  ATE {val['ate_m']:.3f} m")
        criterion = val["t_err_pct"] if val["segments"] else val["ate_m"]
        save_epoch(args.out, model, opt_state, progress, "best_t_err_pct", criterion)

    best, _, _ = checkpoint.load(args.out / "best.ckpt") if (args.out / "best.ckpt").is_file() else (model, None, None)
    after = validate(best, val_seqs, lengths, args.val_window)
    _print_metrics("validation after training (best checkpoint)", after)
    whole = {}
    if args.val_window:
        whole = {"hand_set": validate(hand_set, val_seqs, lengths), "learned": validate(best, val_seqs, lengths)}
        _print_metrics("whole validation sequences from a cold start, hand-set", whole["hand_set"])
        _print_metrics("whole validation sequences from a cold start, learned", whole["learned"])
    write_json_atomic(args.out / "metrics.json", {
        "dataset": args.dataset, "validation": f"windows of {args.val_window} frames, warm start" if args.val_window else "whole sequences, cold start",
        "before": before, "after": after, "whole_sequences": whole, "learnable_parameters": model.num_learnable(),
        "epochs": progress["epoch"], "history": progress["history"], "seconds": time.perf_counter() - t_start,
        "args": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
    })
    print(f"wrote {args.out / 'metrics.json'} ({time.perf_counter() - t_start:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
