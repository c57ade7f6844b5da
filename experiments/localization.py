"""The BEVO+ map-localization experiments (after the BEVO paper), on synthetic scenes split in
quarters (the first two train, the third validates, the last tests):

* CARLA-style: a car on a satellite-look map; trained in town01 on a sunny day, tested in town02
  under "day", "night" and "dynamic" (moving cars and pedestrians).
* AeroGround-style: a ground robot's front camera on a map rendered from a drone's viewpoint;
  trained in town01, tested in town02 under the same three conditions.

    python experiments/localization.py [--seeds 0 1 2] [--epochs 3] [--kinds carla aeroground] [--world street]
        [--model street]

For each kind and training seed (the training drive and the shuffling): ``python -m jbevo.localize
train`` (checkpoint selection on the validation quarter, the hand-set parameters included), then
``evaluate`` on the test quarter of drive 0 in town02; BEVO+ hand-set, BEVO odometry alone and
map matching alone are evaluated once. Writes ``experiments/results/localization.json`` and the
trajectory figures ``experiments/results/localization_<kind>_<condition>.png`` (the first seed);
with ``--world street`` every scene is in the street world (:mod:`jbevo.data.synthetic.street`:
structures beside the road, on the map as their tops, slopes, a camera mounted off its nominal
pose, exposure changes) and the names end in ``_street``. ``--model street`` starts BEVO+ from
the odometry of the street preset (its road view, whose camera attitude and height the map match
uses too, and the gyro's turn fused with DPC's; the names end in ``_preset``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

from jbevo.cli import localize
from jbevo.cli.common import MODELS
from jbevo.data.synthetic.street import WORLDS
from jbevo.files import write_json_atomic

RESULTS = Path(__file__).resolve().parent / "results"


def evaluate(kind: str, out: Path, world: str, model: str, checkpoint: Path | None = None) -> dict:
    argv = ["evaluate", "--kind", kind, "--world", world, "--model", model, "--out", str(out)]
    argv += ["--checkpoint", str(checkpoint)] if checkpoint else []
    return localize.evaluate(localize.build_parser().parse_args(argv))


def record_suffix(world: str, model: str) -> str:
    """What the record's and figures' names end in: ``_street`` in the street world, ``_preset``
    with the street preset's odometry."""
    return ("_street" if world == "street" else "") + ("_preset" if model == "street" else "")


def conditions(result: dict) -> dict:
    return {name.split("_")[2]: entry for name, entry in result["scenes"].items()}


def run_kind(kind: str, seeds: list[int], epochs: int, out: Path, world: str, model: str = "bevo") -> dict:
    suffix = record_suffix(world, model)
    base = out / f"localization{suffix}_{kind}_run"
    hand = conditions(evaluate(kind, base / "eval_hand_set", world, model))
    learned, training = {}, {}
    for seed in seeds:
        run = base / f"seed{seed}"
        t0 = time.perf_counter()
        localize.main(
            ["train", "--kind", kind, "--world", world, "--model", model, "--epochs", str(epochs), "--seed", str(seed)]
            + ["--out", str(run)]
        )
        metrics = json.loads((run / "metrics.json").read_text())
        training[str(seed)] = {
            "seconds": time.perf_counter() - t0,
            "best_epoch": metrics["best_epoch"],
            "validation_hand_set": metrics["before"],
            "validation_learned": metrics["after"],
        }
        result = evaluate(kind, run / "eval", world, model, run)
        learned[str(seed)] = {c: e["BEVO+"] for c, e in conditions(result).items()}
        learned[str(seed)]["frames_per_s"] = result["frames_per_s"]
        if seed == seeds[0]:
            for name in result["scenes"]:
                condition = name.split("_")[2]
                shutil.copyfile(run / "eval" / "plots" / f"{name}.png", out / f"localization{suffix}_{kind}_{condition}.png")
    return {
        "hand_set": {c: e["BEVO+"] for c, e in hand.items()},
        "odometry_alone": {c: e["BEVO odometry"] for c, e in hand.items()},
        "map_matching_alone": {c: e["map matching alone"] for c, e in hand.items()},
        "learned": learned,
        "training": training,
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--kinds", nargs="+", default=["carla", "aeroground"])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--epochs", type=int, default=3)
    p.add_argument("--world", choices=sorted(WORLDS), default="flat", help="the synthetic world: flat or street")
    p.add_argument(
        "--model",
        choices=MODELS,
        default="bevo",
        help="the hand-set start: bevo, or street (the odometry with the street preset's road view and yaw fusion)",
    )
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    results = {kind: run_kind(kind, args.seeds, args.epochs, args.out, args.world, args.model) for kind in args.kinds}
    write_json_atomic(
        args.out / f"localization{record_suffix(args.world, args.model)}.json",
        {
            "world": args.world,
            "model": args.model,
            "train": "town01, day, quarters 1-2 of drive S (selection on quarter 3)",
            "test": "town02, quarter 4 of drive 0",
            "epochs": args.epochs,
            "results": results,
            "seconds": time.perf_counter() - t0,
        },
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
