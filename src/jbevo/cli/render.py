"""``python -m jbevo.render``: render a synthetic sequence (a procedural drive, or a KITTI
trajectory in the synthetic world) and write it to one ``.npz`` file.

    python -m jbevo.render --out seq.npz --frames 200 --town town01 --condition day
    python -m jbevo.render --out seq09.npz --kitti-poses $JBEVO_REFERENCE_DATA/kitti_odom/gt_poses/09.txt
"""

from __future__ import annotations

import argparse
from pathlib import Path

from jbevo.cli import common
from jbevo.data.pose_files import read_kitti
from jbevo.data.sequence_file import save
from jbevo.data.synthetic.conditions import CONDITIONS
from jbevo.data.synthetic.imu import IMU_PRESETS, NOISELESS
from jbevo.data.synthetic.sequences import kitti_sequence, procedural_sequence, small_camera
from jbevo.data.synthetic.street import WORLDS, street_named
from jbevo.data.synthetic.world import TOWNS
from jbevo.geometry.camera import Camera


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser."""
    p = common.parser("python -m jbevo.render", __doc__, [common.seed_option()])
    p.add_argument("--out", type=Path, required=True, help="output .npz file (written atomically)")
    p.add_argument("--frames", type=common.positive_int, default=200, help="number of frames (10 Hz)")
    p.add_argument("--town", choices=sorted(TOWNS), default="town01")
    p.add_argument("--condition", choices=sorted(CONDITIONS), default="day")
    p.add_argument(
        "--world", choices=sorted(WORLDS), default="flat", help="flat, or street (structures, slopes, mounting, exposure)"
    )
    p.add_argument("--kitti-poses", type=Path, help="drive along this KITTI pose file instead of a procedural drive")
    p.add_argument("--start", type=common.non_negative_int, default=0, help="first frame of --kitti-poses")
    p.add_argument(
        "--camera",
        choices=("small", "kitti"),
        default=None,
        help="128x416 or 376x1241 (default: small for procedural, kitti for --kitti-poses)",
    )
    p.add_argument("--noiseless-imu", action="store_true", help="the same as --imu-noise noiseless")
    p.add_argument("--imu-noise", choices=sorted(IMU_PRESETS), default="adis16448", help="the simulated IMU's noise preset")
    return p


def render(args: argparse.Namespace) -> int:
    """Render the sequence and write it."""
    camera_kind = args.camera or ("kitti" if args.kitti_poses else "small")
    camera = Camera.kitti() if camera_kind == "kitti" else small_camera()
    noise = NOISELESS if args.noiseless_imu else IMU_PRESETS[args.imu_noise]
    if args.kitti_poses:
        with common.reading(f"{args.kitti_poses}"):
            poses = read_kitti(args.kitti_poses).poses
            seq = kitti_sequence(
                poses,
                args.start,
                args.frames,
                args.town,
                camera,
                args.condition,
                noise,
                args.seed,
                street=street_named(args.world),
            )
    else:
        seq = procedural_sequence(
            args.seed, args.frames, args.town, camera, args.condition, noise, street=street_named(args.world)
        )
    with common.reading(f"{args.out}"):
        save(seq, args.out)
    print(
        f"wrote {args.out}: {seq.num_frames} frames of {seq.camera.image_shape}, {seq.imu_times.shape[-1]} IMU samples per frame"
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command with ``argv`` (default: the process's arguments); returns the exit code."""
    return common.run(build_parser(), render, argv)


__all__ = ["build_parser", "main", "render"]
