"""BEVO+ map localization: train end to end, and evaluate against odometry alone and map matching
alone.

    python -m jbevo.localize train                               # CARLA-style, town01, day
    python -m jbevo.localize train --kind aeroground --out runs/aeroground
    python -m jbevo.localize evaluate --checkpoint runs/localize --town town02 --conditions day night dynamic

``train`` renders the scene's first two quarters (training) and third quarter (validation)
(:mod:`jbevo.data.synthetic.scenes`), cuts the training part into windows of ``--window`` frames and
learns every parameter of :class:`jbevo.models.bevo_plus.BevoPlus` (the odometry's and the
localizer's) with Adam on :func:`jbevo.models.losses.localization_loss`: the robot's location as
supervision. Each window starts at the true pose, with the attitude filter warm-started (as if it
had run before) and the pose filter's initial standard deviations. After every epoch the whole
validation quarter is localized; ``OUT/best.ckpt`` keeps the lowest mean position error and
``OUT/last.ckpt`` the latest state (atomic); ``--resume`` continues from ``OUT/last.ckpt``;
``OUT/metrics.json`` holds the validation metrics before and after. Each batch is split over
every device, of every process with ``--distributed`` (as ``python -m jbevo.train``: each
process renders the scene and slices its devices' windows; process 0 writes).

``evaluate`` localizes the test quarter (``--part``) of the scene under each ``--conditions``
(one vmapped call: the conditions share the drive and the map) with the checkpoint (hand-set
without one), and also runs BEVO odometry alone (no map) and map matching alone (each frame's
fix from a crop at the previous fix, no odometry, no filter). It writes ``poses/NAME_{gt,bevo_plus,odometry,map_only}.txt``
(KITTI format, z = 0), ``plots/NAME.png`` and ``metrics.json``: per condition and method the mean
and max position error (m), the mean yaw error (deg), the final position error, the distance
driven and, for BEVO+, the fraction of accepted map fixes. With ``--smooth`` it also smooths
BEVO+'s trajectory offline (:mod:`jbevo.models.localization_smoother`, the unscented RTS smoother
over the pose filter) and reports it as "BEVO+ smoothed" beside the filtered one.

``--model street`` starts from the street preset's odometry (road view and yaw fusion,
:func:`jbevo.models.presets.localization_model`) instead of the paper's; a checkpoint brings its
own model, and ``metrics.json`` names the one that ran.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jbevo.cli import common
from jbevo.data import sequence as sq
from jbevo.data.pose_files import write_kitti
from jbevo.data.splits import PARTS
from jbevo.data.synthetic.conditions import CONDITIONS
from jbevo.data.synthetic.scenes import SCENE_KINDS, scene
from jbevo.data.synthetic.street import WORLDS, street_named
from jbevo.data.synthetic.world import TOWNS, World
from jbevo.eval.plots import trajectory_top_view
from jbevo.eval.scores import pose_errors
from jbevo.files import write_json_atomic
from jbevo.models.baselines import map_matching_alone
from jbevo.models.bevo_plus import BevoPlus
from jbevo.models.localization_smoother import smooth_localization
from jbevo.models.losses import localization_loss
from jbevo.models.presets import localization_model
from jbevo.models.runners import run_bevo_batch, run_bevo_plus_batch
from jbevo.progress import progress
from jbevo.training import checkpoint, distributed
from jbevo.training.data_parallel import DataParallel
from jbevo.training.loop import make_step, save_epoch, start_run, train_epochs
from jbevo.training.validation import validate_localization
from jbevo.training.windows import training_windows

FILE_TAGS = {
    "BEVO+": "bevo_plus",
    "BEVO+ smoothed": "bevo_plus_smoothed",
    "BEVO odometry": "odometry",
    "map matching alone": "map_only",
}


def _print(label: str, m: dict) -> None:
    print(
        f"{label}: mean {m['mean_position_error_m']:.3f} m  max {m['max_position_error_m']:.3f} m  "
        f"yaw {m['mean_yaw_error_deg']:.3f} deg  final {m['final_position_error_m']:.3f} m over {m['distance_m']:.0f} m"
    )


# ----------------------------------------------------------------------------- train


def train(args: argparse.Namespace) -> int:
    """Train BEVO+ end to end on a scene's first two quarters, validating on the third."""
    t_start = time.perf_counter()
    common.join_job(args)
    parallel = DataParallel.create()
    world = World.create(args.town)
    frames = args.frames or None
    with common.together():  # every process, or none, goes on
        with common.reading("the scene"):
            street = street_named(args.world)
            train_scene = scene(args.kind, args.town, args.condition, "train", args.seed, world, frames, street)
            val_scene = scene(args.kind, args.town, args.condition, "val", args.seed, world, frames, street)
        with common.reading(f"the run in {args.out}"):
            hand_set = localization_model(args.kind, args.model == "street")
            model, params, static, optimizer, opt_state, progress_ = start_run(
                hand_set,
                args.out,
                args.lr,
                args.clip,
                args.resume,
                "best_mean_position_error_m",
            )
        seq = train_scene.sequence
        if seq.num_frames < args.window:
            raise common.CommandError(f"the training part has {seq.num_frames} frames, fewer than --window {args.window}")
        windows = training_windows([seq], args.window, args.window // 2)
        common.check_batch(parallel, args.batch, len(windows))
    print(
        f"BEVO+: {model.num_learnable()} learnable parameters; {args.kind} scene in {args.town} ({args.condition}): "
        f"{train_scene.sequence.num_frames} training and {val_scene.sequence.num_frames} validation frames"
    )
    before = validate_localization(hand_set, val_scene.sequence, val_scene.map)
    _print("validation before training (hand-set)", before)
    if progress_["epoch"] == 0:
        # The hand-set parameters are the first candidate: a learned checkpoint replaces them
        # only where it validates better.
        save_epoch(args.out, model, opt_state, progress_, "best_mean_position_error_m", before["mean_position_error_m"])

    map_ = train_scene.map

    def loss(m, batch):
        out = jax.vmap(lambda s: m(s, map_, warm_start=True))(batch)
        return jnp.mean(jax.vmap(lambda o, s: localization_loss(o, s, args.yaw_weight))(out, batch))

    step = make_step(static, optimizer, loss, parallel)
    epochs = train_epochs(step, params, static, opt_state, windows, args.batch, args.seed, progress_, args.epochs, parallel)
    with common.diverged_as_command_error():
        for model, opt_state, mean_loss in epochs:
            val = validate_localization(model, val_scene.sequence, val_scene.map)
            epoch = progress_["epoch"]
            progress_["history"].append({"epoch": epoch, "loss": mean_loss, **{f"val_{k}": v for k, v in val.items()}})
            print(
                f"epoch {epoch}: loss {mean_loss:.5f}  val mean {val['mean_position_error_m']:.3f} m  "
                f"max {val['max_position_error_m']:.3f} m  yaw {val['mean_yaw_error_deg']:.3f} deg"
            )
            save_epoch(args.out, model, opt_state, progress_, "best_mean_position_error_m", val["mean_position_error_m"])

    if not distributed.is_main():
        return 0  # process 0 reports the run and writes its metrics
    best_model, best_epoch = common.best_checkpoint(args.out)
    after = validate_localization(best_model, val_scene.sequence, val_scene.map)
    _print(f"validation after training (best checkpoint, epoch {best_epoch})", after)
    write_json_atomic(
        args.out / "metrics.json",
        {
            "kind": args.kind,
            "town": args.town,
            "world": args.world,
            "condition": args.condition,
            "before": before,
            "after": after,
            "best_epoch": best_epoch,
            "learnable_parameters": model.num_learnable(),
            "epochs": progress_["epoch"],
            "skipped_steps": progress_.get("skipped_steps", 0),
            "history": progress_["history"],
            "seconds": time.perf_counter() - t_start,
            "devices": parallel.size,
            "processes": jax.process_count(),
            "args": common.json_args(args),
        },
    )
    print(f"wrote {args.out / 'metrics.json'} ({time.perf_counter() - t_start:.0f} s)")
    return 0


# ----------------------------------------------------------------------------- evaluate


def evaluate(args: argparse.Namespace) -> dict:
    """Localize the ``--part`` of the scene under every condition; returns the metrics written."""
    with common.reading(f"the checkpoint {args.checkpoint}"):
        if args.checkpoint is None:
            model = localization_model(args.kind, args.model == "street")
        else:
            model = checkpoint.load_model(args.checkpoint, BevoPlus)
    world = World.create(args.town)
    frames = args.frames or None
    with common.reading("the scene"):
        scenes = [
            scene(args.kind, args.town, c, args.part, args.seed, world, frames, street_named(args.world))
            for c in progress(args.conditions, "rendering scenes")
        ]
    batch = sq.stack([s.sequence for s in scenes])
    map_ = scenes[0].map  # the conditions share the drive, hence the map
    jax.block_until_ready(run_bevo_plus_batch(model, batch, map_, True))
    t0 = time.perf_counter()
    out = jax.block_until_ready(run_bevo_plus_batch(model, batch, map_, True))
    fps = batch.frame_times.size / (time.perf_counter() - t0)
    odometry = run_bevo_batch(model.odometry, batch, True).poses
    map_only = eqx.filter_jit(jax.vmap(map_matching_alone, in_axes=(None, 0, None)))(model, batch, map_)
    smoothed = jax.jit(jax.vmap(smooth_localization))(out).smoothed_mean if args.smooth else None

    results = {}
    for i, sc in enumerate(progress(scenes, "writing poses and plots")):
        truth = np.asarray(sc.sequence.planar)
        estimates = {
            "BEVO+": np.asarray(out.poses[i]),
            "BEVO odometry": np.asarray(odometry[i]),
            "map matching alone": np.asarray(map_only[i]),
        }
        if smoothed is not None:
            estimates["BEVO+ smoothed"] = np.asarray(smoothed[i])
        entry = {name: pose_errors(est, truth) for name, est in estimates.items()}
        entry["BEVO+"]["accepted"] = float(np.mean(np.asarray(out.accepted[i])))
        entry["final_error_ratio_odometry_to_bevo_plus"] = entry["BEVO odometry"]["final_position_error_m"] / max(
            entry["BEVO+"]["final_position_error_m"], 1e-9
        )
        results[sc.name] = entry
        write_kitti(args.out / "poses" / f"{sc.name}_gt.txt", truth)
        for name, est in estimates.items():
            write_kitti(args.out / "poses" / f"{sc.name}_{FILE_TAGS[name]}.txt", est)
        trajectory_top_view(args.out / "plots" / f"{sc.name}.png", truth, estimates, title=sc.name)
        for name in estimates:
            _print(f"{sc.name} {name}", entry[name])
    summary = {
        "scenes": results,
        "frames_per_s": fps,
        "checkpoint": str(args.checkpoint) if args.checkpoint else None,
        "kind": args.kind,
        "town": args.town,
        "world": args.world,
        "model": "street" if model.odometry.road is not None else "bevo",
        "part": args.part,
    }
    write_json_atomic(args.out / "metrics.json", summary)
    print(f"BEVO+ at {fps:.0f} frames/s; wrote {args.out}")
    return summary


# ----------------------------------------------------------------------------- command line


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser."""
    p = common.parser("python -m jbevo.localize", __doc__)
    sub = p.add_subparsers(dest="command", required=True)
    scene_options = argparse.ArgumentParser(add_help=False)
    scene_options.add_argument("--kind", choices=sorted(SCENE_KINDS), default="carla", help="scene kind (platform and map)")
    scene_options.add_argument(
        "--frames", type=common.non_negative_int, default=0, help="frames of the whole drive (0: the kind's default)"
    )
    scene_options.add_argument(
        "--world",
        choices=sorted(WORLDS),
        default="flat",
        help="flat, or street (structures, slopes, camera mounting, exposure; the map shows the structures' tops)",
    )
    scene_options.add_argument(
        "--model",
        choices=common.MODELS,
        default="bevo",
        help="the hand-set start: bevo (BEVO+ as the paper has it) or street (the odometry with the street preset's road "
        "view, whose camera attitude and height the map match uses too, and the gyro's turn fused with DPC's)",
    )
    seed = common.seed_option(0, "the drive")
    t = sub.add_parser(
        "train",
        parents=[
            scene_options,
            seed,
            common.optimizer_options(lr=0.02, epochs=3, window=64, batch=4),
            common.distributed_options(),
        ],
        help="learn BEVO+ end to end",
    )
    t.add_argument("--town", choices=sorted(TOWNS), default="town01")
    t.add_argument("--condition", choices=sorted(CONDITIONS), default="day")
    t.add_argument("--out", type=Path, default=Path("runs/localize"))
    t.set_defaults(func=train)
    e = sub.add_parser(
        "evaluate", parents=[scene_options, seed], help="localize the test quarter; compare with odometry and map matching alone"
    )
    e.add_argument("--checkpoint", type=Path, help="a checkpoint file or a training output folder (its best.ckpt)")
    e.add_argument("--town", choices=sorted(TOWNS), default="town02")
    e.add_argument("--conditions", nargs="+", choices=sorted(CONDITIONS), default=["day", "night", "dynamic"])
    e.add_argument("--part", choices=PARTS, default="test")
    e.add_argument("--out", type=Path, default=Path("runs/localize_eval"))
    e.add_argument("--smooth", action="store_true", help="also smooth BEVO+'s trajectory offline (unscented RTS smoother)")
    e.set_defaults(func=evaluate)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the command with ``argv`` (default: the process's arguments); returns the exit code."""
    return common.run(build_parser(), lambda args: args.func(args), argv)


__all__ = ["build_parser", "evaluate", "main", "train"]
