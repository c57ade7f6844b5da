"""What bounds the street world's KITTI-style error: the street preset on the long drives with the
street world's failure modes removed one at a time.

The KITTI-style experiment's test drives (KITTI 09 and 10 whole, the motion of their pose files,
simulated IMU, rendered with seed ``LONG_SEED`` as ``benchmarks/forward_fusion.py`` renders them)
in each world of ``benchmarks/street_world.py``'s ``ABLATIONS``: the street world, the street world
less its structures, its slopes, its camera mounting (pitched, rolled and 5 cm high) or its
exposure changes, and the flat world. The hand-set street preset
(:func:`jbevo.models.presets.street_model`, robust bands, warm start) on the KITTI-style grid runs
on each. Scored by the KITTI devkit (``t_err_pct``, ``r_err_deg_per_100m``, 100-800 m segments,
per drive and pooled) and the metrics of ``real_kitti.scores`` and ``forward_fusion.along_across``,
and the spread of the distance ratio over the drive's consecutive 100 m pieces
(``piece_scale_std``, ``piece_scale_min``, ``piece_scale_max``: estimated over true path length
per piece).

Nothing is fitted: every model is hand-set. Keys: ``drives[<drive>][<world>][<metric>]``,
``<drive>`` 09, 10 or pooled.

    JBEVO_REFERENCE_DATA=../shared/data python benchmarks/street_drives.py [--frames N]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from forward_fusion import KITTI_GRID, LONG_DRIVES, LONG_SEED, long_drives
from jbevo.files import write_json_atomic
from jbevo.models import relative_motion
from jbevo.models.presets import street_model
from real_kitti import RESULTS
from street_world import ABLATIONS

#: The length of the pieces whose distance ratios are spread (metres).
PIECE_M = 100.0
PRESET = "street + robust bands"


def piece_scales(increments, seq, piece_m: float = PIECE_M) -> np.ndarray:
    """Estimated over true path length in each consecutive ``piece_m`` of the true path (the last,
    shorter piece dropped)."""
    true = np.linalg.norm(np.asarray(relative_motion(seq), float)[1:, :2], axis=1)
    est = np.linalg.norm(np.asarray(increments, float)[1:, :2], axis=1)
    piece = np.floor(np.cumsum(true) / piece_m).astype(int)
    whole = piece < piece[-1]
    return np.bincount(piece[whole], est[whole]) / np.bincount(piece[whole], true[whole])


def spread(out, seq) -> dict[str, float]:
    """The spread of :func:`piece_scales` (none on a drive shorter than a whole piece and a part)."""
    scales = piece_scales(out.increments, seq)
    if not len(scales):
        return {}
    return {
        "piece_scale_std": float(scales.std()),
        "piece_scale_min": float(scales.min()),
        "piece_scale_max": float(scales.max()),
    }


def drive_arguments(description: str, record: str) -> tuple[argparse.Namespace, Path]:
    """The command line of a long-drive benchmark (``--frames``, ``--out``, default
    ``RESULTS / record``) and the reference data's folder (``JBEVO_REFERENCE_DATA``, with
    ``kitti_odom/gt_poses/``)."""
    parser = argparse.ArgumentParser(description=description.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=0, help="frames per drive (0: all)")
    parser.add_argument("--out", type=Path, default=RESULTS / record)
    args = parser.parse_args()
    root = os.environ.get("JBEVO_REFERENCE_DATA")
    if not root or not (Path(root) / "kitti_odom" / "gt_poses").is_dir():
        raise SystemExit("set JBEVO_REFERENCE_DATA to the reference data folder (with kitti_odom/gt_poses/)")
    return args, Path(root)


def main() -> None:
    args, root = drive_arguments(__doc__, "street_drives.json")
    started = time.time()
    drives: dict[str, dict] = {}
    for world, street in ABLATIONS.items():
        print(f"{world}:", flush=True)
        table = long_drives(
            root,
            LONG_DRIVES,
            args.frames,
            LONG_SEED,
            lambda imu_dt: {PRESET: street_model(imu_dt, KITTI_GRID, bands=True)},
            devkit=True,
            street=street,
            extra=spread,
        )
        for drive, rows in table.items():
            drives.setdefault(drive, {})[world] = rows[PRESET]
    settings = {"model": PRESET, "drives": list(LONG_DRIVES), "seed": LONG_SEED, "frames": args.frames, "piece_m": PIECE_M}
    write_json_atomic(args.out, {"drives": drives, "settings": settings, "seconds": time.time() - started})


if __name__ == "__main__":
    main()
