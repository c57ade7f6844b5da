"""What the BEV band geometry (``jbevo.vision.bands``) does on KITTI-size images: BEVO hand-set
with and without bands, with the IMU filter's attitude and with the true attitude, on the first
frames of KITTI 08 (real KITTI motion in the synthetic world, KITTI camera 0 at 376 x 1241, a
256 x 256 BEV at 0.1 m/px from 4 m, warm start; 08 trains, it is no test sequence).

    python experiments/bands.py --reference $JBEVO_REFERENCE_DATA [--frames 600]

Writes ``experiments/results/bands.json``: the devkit's errors (100-800 m), the per-frame motion
error and the RMS of the BEVs' pitch and roll errors.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from jbevo.data.catalog import load_sequences
from jbevo.eval.devkit import SEGMENT_LENGTHS
from jbevo.eval.scores import score
from jbevo.files import write_json_atomic
from jbevo.geometry import BevGrid
from jbevo.models import Bevo, run_bevo

RESULTS = Path(__file__).resolve().parent / "results"
VARIANTS = {  # label: (attitude source, bands)
    "IMU filter, no bands": ("filter", False),
    "IMU filter + bands": ("filter", True),
    "true attitude, no bands": ("truth", False),
    "true attitude + bands": ("truth", True),
}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reference", type=Path, default=os.environ.get("JBEVO_REFERENCE_DATA"))
    p.add_argument("--sequence", default="08")
    p.add_argument("--frames", type=int, default=600)
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if args.reference is None:
        raise SystemExit("give --reference (the shared data folder) or set JBEVO_REFERENCE_DATA")
    poses = args.reference / "kitti_odom" / "gt_poses"
    (seq,) = load_sequences("kitti-synthetic", [args.sequence], args.frames, kitti_poses=poses, camera="kitti", seed=800)
    grid = BevGrid(0.1, (256, 256), near=4.0)
    rows = {}
    for label, (source, bands) in VARIANTS.items():
        out = run_bevo(Bevo.create(grid, seq.imu_dt, source, bands=bands), seq, True)
        s = score(out, seq, SEGMENT_LENGTHS)
        err = np.degrees(np.sqrt(np.mean((np.asarray(out.pitch_roll) - np.asarray(seq.pitch_roll)) ** 2, axis=0)))
        rows[label] = {k: s[k] for k in ("t_err_pct", "r_err_deg_per_100m", "ate_m", "motion_rmse_m", "yaw_rmse_deg", "segments")}
        rows[label] |= {"pitch_rms_deg": float(err[0]), "roll_rms_deg": float(err[1])}
        print(label, rows[label])
    write_json_atomic(
        args.out / "bands.json",
        {
            "sequence": args.sequence,
            "frames": args.frames,
            "camera": "KITTI camera 0, 376 x 1241",
            "bev": {"resolution": 0.1, "shape": [256, 256], "near": 4.0},
            "start": "warm",
            "results": rows,
        },
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
