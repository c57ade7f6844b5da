"""The BEVO+ map-localization experiments (after the BEVO paper), on synthetic scenes with the
seed's splits (first two quarters train, third validates, last tests):

* CARLA-style: a car on a satellite-look map; trained in town01 on a sunny day, tested in town02
  under "day", "night" and "dynamic" (moving cars and pedestrians).
* AeroGround-style: a ground robot's front camera on a map rendered from a drone's viewpoint
  (another look); trained in town01, tested in town02 under the same three conditions.

    python experiments/localization.py [--epochs 3] [--kinds carla aeroground]

For each kind: ``python -m jbevo.localize train`` then ``evaluate`` (BEVO+ learned, BEVO+
hand-set, BEVO odometry alone, map matching alone). Writes
``experiments/results/localization.{json,md}`` and the trajectory figures
``experiments/results/localization_<kind>_<condition>.png``.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from jbevo.cli import localize
from jbevo.files import write_json_atomic, write_text_atomic

RESULTS = Path(__file__).resolve().parent / "results"
METHODS = ("BEVO+", "BEVO odometry", "map matching alone")


def run_kind(kind: str, epochs: int, out: Path) -> dict:
    run = out / f"localization_{kind}_run"
    localize.main(["train", "--kind", kind, "--epochs", str(epochs), "--out", str(run)])
    learned = localize.evaluate(
        localize.build_parser().parse_args(["evaluate", "--kind", kind, "--checkpoint", str(run), "--out", str(run / "eval")])
    )
    hand = localize.evaluate(
        localize.build_parser().parse_args(["evaluate", "--kind", kind, "--out", str(run / "eval_hand_set")])
    )
    rows = {}
    for name, entry in learned["scenes"].items():
        condition = name.split("_")[2]
        rows[condition] = {
            "BEVO+ learned": entry["BEVO+"],
            "BEVO+ hand-set": hand["scenes"][name]["BEVO+"],
            "BEVO odometry alone": entry["BEVO odometry"],
            "map matching alone": entry["map matching alone"],
            "final_error_ratio_odometry_to_bevo_plus": entry["final_error_ratio_odometry_to_bevo_plus"],
        }
        shutil.copyfile(run / "eval" / "plots" / f"{name}.png", out / f"localization_{kind}_{condition}.png")
    return {"conditions": rows, "frames_per_s": learned["frames_per_s"], "training": str(run / "metrics.json")}


def table(results: dict) -> str:
    lines = [
        "| scene | condition | method | mean pos. err (m) | max pos. err (m) | mean yaw err (deg) | final pos. err (m) | distance (m) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for kind, res in results.items():
        for condition, rows in res["conditions"].items():
            for method, m in rows.items():
                if not isinstance(m, dict):
                    continue
                lines.append(
                    f"| {kind} | {condition} | {method} | {m['mean_position_error_m']:.3f} | {m['max_position_error_m']:.3f} | "
                    f"{m['mean_yaw_error_deg']:.3f} | {m['final_position_error_m']:.3f} | {m['distance_m']:.0f} |"
                )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--kinds", nargs="+", default=["carla", "aeroground"])
    p.add_argument("--epochs", type=int, default=3)
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    results = {kind: run_kind(kind, args.epochs, args.out) for kind in args.kinds}
    write_json_atomic(args.out / "localization.json", {"results": results, "seconds": time.perf_counter() - t0})
    write_text_atomic(args.out / "localization.md", table(results))
    print(table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
