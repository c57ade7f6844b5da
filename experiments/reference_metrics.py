"""The trajectory metrics on real reference data, beside the figures published for it: the KITTI
devkit protocol on a real visual-odometry estimate of KITTI 09 (Sim(3) alignment; the figures of
the tool that ships it, from the data's README) and on a real ORB-SLAM2 stereo estimate of
KITTI 00 (no alignment; the ORB-SLAM2 paper's Table for stereo 00, to two digits).

    python experiments/reference_metrics.py --reference $JBEVO_REFERENCE_DATA

Writes ``experiments/results/reference_metrics.json`` (float64).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import jax
import jax.numpy as jnp

from jbevo.data.pose_files import match_frames, read_poses
from jbevo.eval.trajectory_metrics import evaluate, summary
from jbevo.files import write_json_atomic

RESULTS = Path(__file__).resolve().parent / "results"
CASES = {
    "vo_example_09": (
        "gt_poses/09.txt",
        "vo_example/09.txt",
        "sim3",
        {"t_err_pct": 2.884113, "r_err_deg_per_100m": 0.249056, "ate_m": 8.386619},
    ),
    "orbslam2_00": ("gt_poses/00.txt", "orbslam2_00/00.txt", "none", {"t_err_pct": 0.70, "r_err_deg_per_100m": 0.25}),
}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reference", type=Path, default=os.environ.get("JBEVO_REFERENCE_DATA"))
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if args.reference is None:
        raise SystemExit("give --reference (the shared data folder) or set JBEVO_REFERENCE_DATA")
    root = args.reference / "kitti_odom"
    results = {}
    with jax.enable_x64(True):
        for name, (gt, est, alignment, published) in CASES.items():
            g, e, valid = match_frames(read_poses(root / gt), read_poses(root / est))
            numbers = summary(evaluate(jnp.asarray(g), jnp.asarray(e), jnp.asarray(valid), alignment))
            results[name] = {"alignment": alignment, "measured": numbers, "published": published}
            print(name, {k: numbers[k] for k in ("t_err_pct", "r_err_deg_per_100m", "ate_m", "segments")})
    write_json_atomic(args.out / "reference_metrics.json", results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
