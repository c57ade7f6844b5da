"""The built-in training (``python -m jbevo.train`` with its defaults) over several training seeds:
the validation drive's scores for the hand-set and the learned parameters (the checkpoint that
validates best, the hand-set ones included), and the same two on held-out test drives that
neither training nor selection saw (procedural drives 1000-1003, 120 frames, from a cold start,
as the validation drive runs).

    python experiments/builtin_training.py [--seeds 0 1 2]

A training seed picks the drives (seeds s .. s + 4: four train, the last validates), their IMU
noise and the shuffling. Writes ``experiments/results/builtin_training.json``; the runs'
checkpoints go to ``experiments/results/builtin_run/seedS/``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from jbevo.cli import train
from jbevo.data.catalog import load_sequences
from jbevo.eval.scores import SHORT_SEGMENTS, score
from jbevo.files import write_json_atomic
from jbevo.models import Bevo, run_bevo
from jbevo.training import checkpoint

RESULTS = Path(__file__).resolve().parent / "results"
TEST_DRIVES = ["1000", "1001", "1002", "1003"]
KEYS = ("t_err_pct", "r_err_deg_per_100m", "ate_m", "motion_rmse_m", "yaw_rmse_deg", "segments")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    test = load_sequences("synthetic", TEST_DRIVES, frames=120, seed=1000)
    runs = {}
    for seed in args.seeds:
        run = args.out / "builtin_run" / f"seed{seed}"
        t0 = time.perf_counter()
        train.main(["--seed", str(seed), "--out", str(run)])
        seconds = time.perf_counter() - t0
        metrics = json.loads((run / "metrics.json").read_text())
        learned = checkpoint.load_model(run / "best.ckpt", Bevo)
        hand_set = Bevo.create(learned.grid, 0.01, bands=learned.bands is not None)
        scores = {
            name: score([run_bevo(model, s, False) for s in test], test, SHORT_SEGMENTS)
            for name, model in (("hand_set", hand_set), ("learned", learned))
        }
        runs[str(seed)] = {
            "validation": {
                "hand_set": {k: metrics["before"][k] for k in KEYS},
                "learned": {k: metrics["after"][k] for k in KEYS},
            },
            "test": {name: {k: s[k] for k in KEYS} for name, s in scores.items()},
            "best_epoch": metrics["best_epoch"],
            "epochs": metrics["epochs"],
            "command_seconds": metrics["seconds"],
            "seconds": seconds,
        }
        print(seed, json.dumps(runs[str(seed)]["test"]))
    write_json_atomic(
        args.out / "builtin_training.json",
        {
            "command": "python -m jbevo.train --seed S (defaults otherwise)",
            "validation": "the drive of seed S + 4, whole, cold start",
            "test_drives": [int(t) for t in TEST_DRIVES],
            "test": "whole drives, cold start, devkit errors over 10-50 m segments",
            "seeds": runs,
        },
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
