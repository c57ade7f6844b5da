"""BEVO+ map localization: train end to end, and evaluate against odometry alone and map matching
alone.

    python -m jbevo.localize train                               # CARLA-style, town01, day
    python -m jbevo.localize train --kind aeroground --out runs/aeroground
    python -m jbevo.localize evaluate --checkpoint runs/localize --town town02 --conditions day night dynamic

``train`` renders the scene's first two quarters (training) and third quarter (validation)
(:mod:`jbevo.datasets.scenes`), cuts the training part into windows of ``--window`` frames and
learns every parameter of :class:`jbevo.localization.BevoPlus` (the odometry's and the
localizer's) with Adam on :func:`jbevo.localization.localization_loss`: the robot's location as
supervision. Each window starts at the true pose, with the attitude filter warm-started (as if it
had run before) and the pose filter's initial standard deviations. After every epoch the whole
validation quarter is localized; ``OUT/best.ckpt`` keeps the lowest mean position error and
``OUT/last.ckpt`` the latest state (atomic); ``--resume`` continues from ``OUT/last.ckpt``;
``OUT/metrics.json`` holds the validation metrics before and after.

``evaluate`` localizes the test quarter (``--part``) of the scene under each ``--conditions``
(one vmapped call: the conditions share the drive and the map) with the checkpoint (hand-set
without one), and also runs BEVO odometry alone (no map) and map matching alone (each frame's
fix from a crop at the previous fix, no odometry, no filter). It writes ``poses/NAME_{gt,bevo_plus,odometry,map_only}.txt``
(KITTI format, z = 0), ``plots/NAME.png`` and ``metrics.json``: per condition and method the mean
and max position error (m), the mean yaw error (deg), the final position error, the distance
driven and, for BEVO+, the fraction of accepted map fixes.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jbevo import checkpoint
from jbevo.datasets import sequence as sq
from jbevo.datasets.conditions import CONDITIONS
from jbevo.datasets.maps import Map
from jbevo.datasets.scenes import SCENE_KINDS, scene
from jbevo.datasets.world import TOWNS, World
from jbevo.epochs import make_step, run_epoch, save_epoch, start_run
from jbevo.files import write_json_atomic
from jbevo.localization import BevoPlus, localization_loss
from jbevo.odometry import Bevo
from jbevo.plots import trajectory_top_view
from jbevo.trajectory_io import write_kitti

GYRO_WINDOW = np.radians(2.0)
FILE_TAGS = {"BEVO+": "bevo_plus", "BEVO odometry": "odometry", "map matching alone": "map_only"}


def create_model(kind: str) -> BevoPlus:
    """The hand-set BEVO+ for a scene kind (its BEV grids; odometry rotation searched within 2 deg
    of the gyro's turn)."""
    odometry_grid, map_grid = SCENE_KINDS[kind].grids()
    return BevoPlus.create(Bevo.create(odometry_grid, gyro_window=GYRO_WINDOW), map_grid)


def pose_errors(poses, truth) -> dict:
    """Mean, max and final position error (m), mean yaw error (deg) and the distance driven."""
    poses, truth = np.asarray(poses, float), np.asarray(truth, float)
    pos = np.hypot(*(poses[:, :2] - truth[:, :2]).T)
    yaw = np.abs(np.degrees(np.angle(np.exp(1j * (poses[:, 2] - truth[:, 2])))))
    return {
        "mean_position_error_m": float(pos.mean()), "max_position_error_m": float(pos.max()),
        "final_position_error_m": float(pos[-1]), "mean_yaw_error_deg": float(yaw.mean()),
        "distance_m": float(np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T))),
    }


def map_matching_alone(model: BevoPlus, seq: sq.Sequence, map_: Map) -> jax.Array:
    """Track by map matching only: each frame's crop at the previous frame's fix (the truth at
    frame 0), pitch and roll from BEVO's attitude filter (without the map's pitch); a fix below
    the confidence floor keeps the previous pose."""
    odo = model.odometry
    carry0, frames, seq = odo.start(seq, warm_start=True)
    frame_dt = odo.frame_dt(seq)

    def step(carry, frame):
        odo_carry, pose = carry
        odo_carry, (_, pitch_roll, _, _) = odo.step(odo_carry, frame, seq.camera, frame_dt)
        match = model.match(frame[0], pitch_roll, seq.camera, map_, pose)
        ok = (match.confidence >= model.min_confidence) & jnp.all(jnp.isfinite(match.fix))
        pose = jnp.where(ok, match.fix, pose).astype(pose.dtype)
        return (odo_carry, pose), pose

    _, poses = jax.lax.scan(step, (carry0, carry0.pose), frames)
    return poses


def validate(model: BevoPlus, seq: sq.Sequence, map_: Map) -> dict:
    out = eqx.filter_jit(lambda m, s, mp: m(s, mp, warm_start=True))(model, seq, map_)
    return pose_errors(out.poses, seq.planar) | {"accepted": float(np.mean(np.asarray(out.accepted)))}


def _print(label: str, m: dict) -> None:
    print(f"{label}: mean {m['mean_position_error_m']:.3f} m  max {m['max_position_error_m']:.3f} m  "
          f"yaw {m['mean_yaw_error_deg']:.3f} deg  final {m['final_position_error_m']:.3f} m over {m['distance_m']:.0f} m")


# ----------------------------------------------------------------------------- train


def train(args) -> int:
    t_start = time.perf_counter()
    world = World.create(args.town)
    frames = args.frames or None
    train_scene = scene(args.kind, args.town, args.condition, "train", args.seed, world, frames)
    val_scene = scene(args.kind, args.town, args.condition, "val", args.seed, world, frames)
    model, params, static, optimizer, opt_state, progress = start_run(
        create_model(args.kind), args.out, args.lr, args.clip, args.resume, "best_mean_position_error_m")
    print(f"BEVO+: {model.num_learnable()} learnable parameters; {args.kind} scene in {args.town} ({args.condition}): "
          f"{train_scene.sequence.num_frames} training and {val_scene.sequence.num_frames} validation frames")
    before = validate(create_model(args.kind), val_scene.sequence, val_scene.map)
    _print("validation before training (hand-set)", before)

    seq = train_scene.sequence
    if seq.num_frames < args.window:
        raise SystemExit(f"the training part has {seq.num_frames} frames, fewer than --window {args.window}")
    windows = sq.windows(seq, args.window, args.window // 2)
    map_ = train_scene.map

    def loss(m, batch):
        out = jax.vmap(lambda s: m(s, map_, warm_start=True))(batch)
        return jnp.mean(jax.vmap(lambda o, s: localization_loss(o, s, args.yaw_weight))(out, batch))

    step = make_step(static, optimizer, loss)
    rng = np.random.default_rng(args.seed + progress["epoch"])
    for epoch in range(progress["epoch"], args.epochs):
        params, opt_state, mean_loss, steps = run_epoch(step, params, opt_state, windows, args.batch, rng, f"epoch {epoch + 1}/{args.epochs}")
        model = eqx.combine(params, static)
        val = validate(model, val_scene.sequence, val_scene.map)
        progress["epoch"], progress["step"] = epoch + 1, progress["step"] + steps
        progress["history"].append({"epoch": epoch + 1, "loss": mean_loss, **{f"val_{k}": v for k, v in val.items()}})
        print(f"epoch {epoch + 1}: loss {mean_loss:.5f}  val mean {val['mean_position_error_m']:.3f} m  "
              f"max {val['max_position_error_m']:.3f} m  yaw {val['mean_yaw_error_deg']:.3f} deg")
        save_epoch(args.out, model, opt_state, progress, "best_mean_position_error_m", val["mean_position_error_m"])

    best_model = checkpoint.load(args.out / "best.ckpt")[0] if (args.out / "best.ckpt").is_file() else model
    after = validate(best_model, val_scene.sequence, val_scene.map)
    _print("validation after training (best checkpoint)", after)
    write_json_atomic(args.out / "metrics.json", {
        "kind": args.kind, "town": args.town, "condition": args.condition, "before": before, "after": after,
        "learnable_parameters": model.num_learnable(), "epochs": progress["epoch"], "history": progress["history"],
        "seconds": time.perf_counter() - t_start,
        "args": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items() if k != "func"},
    })
    print(f"wrote {args.out / 'metrics.json'} ({time.perf_counter() - t_start:.0f} s)")
    return 0


# ----------------------------------------------------------------------------- evaluate


def load_model(path: Path | None, kind: str) -> BevoPlus:
    if path is None:
        return create_model(kind)
    path = path / "best.ckpt" if path.is_dir() else path
    model = checkpoint.load(path)[0]
    if not isinstance(model, BevoPlus):
        raise SystemExit(f"{path} holds a BEVO odometry model, not a BEVO+ localizer; train one with python -m jbevo.localize train")
    return model


def evaluate(args) -> dict:
    model = load_model(args.checkpoint, args.kind)
    world = World.create(args.town)
    frames = args.frames or None
    scenes = [scene(args.kind, args.town, c, args.part, args.seed, world, frames) for c in args.conditions]
    batch = sq.stack([s.sequence for s in scenes])
    map_ = scenes[0].map  # the conditions share the drive, hence the map
    run = eqx.filter_jit(jax.vmap(lambda m, s, mp: m(s, mp, warm_start=True), in_axes=(None, 0, None)))
    jax.block_until_ready(run(model, batch, map_))
    t0 = time.perf_counter()
    out = jax.block_until_ready(run(model, batch, map_))
    fps = batch.frame_times.size / (time.perf_counter() - t0)
    odometry = eqx.filter_jit(jax.vmap(lambda m, s: m(s, warm_start=True).poses, in_axes=(None, 0)))(model.odometry, batch)
    map_only = eqx.filter_jit(jax.vmap(map_matching_alone, in_axes=(None, 0, None)))(model, batch, map_)

    (args.out / "poses").mkdir(parents=True, exist_ok=True)
    (args.out / "plots").mkdir(parents=True, exist_ok=True)
    results = {}
    for i, sc in enumerate(scenes):
        truth = np.asarray(sc.sequence.planar)
        estimates = {"BEVO+": np.asarray(out.poses[i]), "BEVO odometry": np.asarray(odometry[i]), "map matching alone": np.asarray(map_only[i])}
        entry = {name: pose_errors(est, truth) for name, est in estimates.items()}
        entry["BEVO+"]["accepted"] = float(np.mean(np.asarray(out.accepted[i])))
        entry["final_error_ratio_odometry_to_bevo_plus"] = entry["BEVO odometry"]["final_position_error_m"] / max(entry["BEVO+"]["final_position_error_m"], 1e-9)
        results[sc.name] = entry
        write_kitti(args.out / "poses" / f"{sc.name}_gt.txt", truth)
        for name, est in estimates.items():
            write_kitti(args.out / "poses" / f"{sc.name}_{FILE_TAGS[name]}.txt", est)
        trajectory_top_view(args.out / "plots" / f"{sc.name}.png", truth, estimates, title=sc.name)
        for name in estimates:
            _print(f"{sc.name} {name}", entry[name])
    summary = {"scenes": results, "frames_per_s": fps, "checkpoint": str(args.checkpoint) if args.checkpoint else None,
               "kind": args.kind, "town": args.town, "part": args.part}
    write_json_atomic(args.out / "metrics.json", summary)
    print(f"BEVO+ at {fps:.0f} frames/s; wrote {args.out}")
    return summary


# ----------------------------------------------------------------------------- command line


def parse_args(argv):
    p = argparse.ArgumentParser(prog="python -m jbevo.localize", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--kind", choices=sorted(SCENE_KINDS), default="carla", help="scene kind (platform and map)")
    common.add_argument("--seed", type=int, default=0, help="the drive")
    common.add_argument("--frames", type=int, default=0, help="frames of the whole drive (0: the kind's default)")
    t = sub.add_parser("train", parents=[common], help="learn BEVO+ end to end")
    t.add_argument("--town", choices=sorted(TOWNS), default="town01")
    t.add_argument("--condition", choices=sorted(CONDITIONS), default="day")
    t.add_argument("--window", type=int, default=64, help="training window length (frames)")
    t.add_argument("--batch", type=int, default=4, help="windows per step (vmapped)")
    t.add_argument("--epochs", type=int, default=3)
    t.add_argument("--lr", type=float, default=0.02, help="Adam learning rate (the parameters are logs)")
    t.add_argument("--clip", type=float, default=1.0, help="global gradient-norm clip")
    t.add_argument("--yaw-weight", type=float, default=10.0, help="metres per radian of yaw error in the loss")
    t.add_argument("--out", type=Path, default=Path("runs/localize"))
    t.add_argument("--resume", action="store_true", help="continue from OUT/last.ckpt")
    t.set_defaults(func=train)
    e = sub.add_parser("evaluate", parents=[common], help="localize the test quarter; compare with odometry and map matching alone")
    e.add_argument("--checkpoint", type=Path, help="a checkpoint file or a training output folder (its best.ckpt)")
    e.add_argument("--town", choices=sorted(TOWNS), default="town02")
    e.add_argument("--conditions", nargs="+", choices=sorted(CONDITIONS), default=["day", "night", "dynamic"])
    e.add_argument("--part", choices=("train", "val", "test", "all"), default="test")
    e.add_argument("--out", type=Path, default=Path("runs/localize_eval"))
    e.set_defaults(func=evaluate)
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        result = args.func(args)
    except (ValueError, FileNotFoundError) as error:
        raise SystemExit(str(error)) from None
    return result if isinstance(result, int) else 0


if __name__ == "__main__":
    raise SystemExit(main())
