"""BEVO+ filtered against smoothed offline, on the localization experiment's test scenes.

    python experiments/localization_smoothing.py [--kinds carla aeroground] [--checkpoint-dir DIR]

For each kind: ``python -m jbevo.localize evaluate --smooth`` on the test quarter of drive 0 in
town02 under "day", "night" and "dynamic", with the hand-set parameters (nothing here is tuned on
the test quarter) or, with ``--checkpoint-dir``, with ``DIR/localization_<kind>_run/seed0``'s
checkpoint from ``experiments/localization.py``. Writes
``experiments/results/localization_smoothing.json``: per kind and condition, the errors of BEVO+
filtered and smoothed, and the smoothed-to-filtered ratios.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from jbevo.cli import localize
from jbevo.files import write_json_atomic

RESULTS = Path(__file__).resolve().parent / "results"
METRICS = ("mean_position_error_m", "max_position_error_m", "final_position_error_m", "mean_yaw_error_deg")


def run_kind(kind: str, out: Path, checkpoint: Path | None) -> dict:
    argv = ["evaluate", "--kind", kind, "--smooth", "--out", str(out)]
    if checkpoint is not None:
        argv += ["--checkpoint", str(checkpoint)]
    result = localize.evaluate(localize.build_parser().parse_args(argv))
    by_condition = {}
    for name, entry in result["scenes"].items():
        filtered, smoothed = entry["BEVO+"], entry["BEVO+ smoothed"]
        by_condition[name.split("_")[2]] = {
            "filtered": {k: filtered[k] for k in METRICS},
            "smoothed": {k: smoothed[k] for k in METRICS},
            "smoothed_over_filtered": {k: smoothed[k] / max(filtered[k], 1e-12) for k in METRICS},
            "accepted": filtered["accepted"],
        }
    return {"parameters": "hand-set" if checkpoint is None else str(checkpoint), "conditions": by_condition}


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--kinds", nargs="+", default=["carla", "aeroground"])
    p.add_argument("--checkpoint-dir", type=Path, help="the work folder of experiments/localization.py (seed 0's checkpoints)")
    p.add_argument("--out", type=Path, default=RESULTS / "localization_smoothing.json")
    args = p.parse_args(argv)
    results = {"town": "town02", "part": "test", "kinds": {}}
    with tempfile.TemporaryDirectory() as work:
        for kind in args.kinds:
            checkpoint = None if args.checkpoint_dir is None else args.checkpoint_dir / f"localization_{kind}_run" / "seed0"
            results["kinds"][kind] = run_kind(kind, Path(work) / kind, checkpoint)
    write_json_atomic(args.out, results)
    print(f"wrote {args.out}")
    return results


if __name__ == "__main__":
    main()
