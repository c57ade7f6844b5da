"""Simulator speed: frames per second of the ground renderer at KITTI size (376x1241, the KITTI
camera 0 intrinsics) over a procedural drive, alone and as a sequence's frames are made (with
the day condition's exposure, sensor noise and 8-bit output: ``frames_per_s_kitti_size``), and
the time for a whole procedural sequence (trajectory, IMU and images) with the small camera; the
same for the street world (:mod:`jbevo.data.synthetic.street`: the 32 nearest structures ray-cast
per frame, the mounted camera, exposure gain and vignetting), timed in interleaved rounds with
the flat world (``street_slowdown_kitti_size`` = flat frames/s over street frames/s). The
200-frame drives are timed after one of the same length has compiled.

    python benchmarks/simulator.py [--frames 64] [--repeats 5]

Writes ``benchmarks/results/simulator.json``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jbevo.data.synthetic.conditions import CONDITIONS
from jbevo.data.synthetic.render import render_batch
from jbevo.data.synthetic.sequences import _frames, _half_fov, procedural_sequence
from jbevo.data.synthetic.street import STREET, exposure_gains, mounted_camera, vignette
from jbevo.data.synthetic.structures import nearest_boxes, place_structures
from jbevo.data.synthetic.trajectories import procedural_drive
from jbevo.data.synthetic.world import World
from jbevo.files import write_json_atomic
from jbevo.geometry.camera import Camera
from timing import best_seconds, best_seconds_interleaved


def drive_seconds(world: World, street, frames: int = 200) -> float:
    """Seconds for a whole procedural sequence of ``frames`` frames (small camera), after one of
    the same length has compiled everything."""
    procedural_sequence(0, frames, world=world, street=street)
    t0 = time.perf_counter()
    jax.block_until_ready(procedural_sequence(1, frames, world=world, street=street).images)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "simulator.json")
    args = parser.parse_args()

    t0 = time.perf_counter()
    world = World.create("town01")
    world_seconds = time.perf_counter() - t0
    camera = Camera.kitti()
    _, poses = procedural_drive(0, args.frames)
    poses = jnp.asarray(poses, jnp.float32)
    times = jnp.arange(args.frames, dtype=jnp.float32) * 0.1
    keys = jax.random.split(jax.random.PRNGKey(0), args.frames)
    day = CONDITIONS["day"]
    render_only = jax.jit(render_batch)
    seconds_render = best_seconds(lambda: render_only(world, camera, poses), args.repeats)
    view = np.asarray(poses, float)
    boxes = jax.tree_util.tree_map(jnp.asarray, nearest_boxes(place_structures(view, STREET, 0), view, _half_fov(camera)))
    gains = jnp.asarray(exposure_gains(args.frames, STREET, 0))
    street_args = (boxes, gains, vignette(camera, STREET.vignetting), STREET.ground_contrast)
    mounted = mounted_camera(camera, STREET)
    both = best_seconds_interleaved(
        {
            "flat": lambda: _frames(world, camera, poses, times, None, keys, day),
            "street": lambda: _frames(world, mounted, poses, times, None, keys, day, *street_args),
        },
        args.repeats,
    )
    seconds, seconds_street = both["flat"], both["street"]
    kitti_fps, street_fps = args.frames / seconds, args.frames / seconds_street
    print(
        f"render KITTI size: {args.frames / seconds_render:.1f} frames/s; with exposure, sensor noise and 8-bit "
        f"output: {kitti_fps:.1f} frames/s ({1e3 * seconds / args.frames:.2f} ms/frame)"
    )

    seq_seconds = drive_seconds(world, None)
    print(f"procedural sequence of 200 frames (small camera, IMU, trajectory): {seq_seconds:.2f} s")
    print(f"street world, KITTI size: {street_fps:.1f} frames/s ({kitti_fps / street_fps:.2f}x slower than the flat world)")
    street_seq_seconds = drive_seconds(world, STREET)
    print(f"street procedural sequence of 200 frames (small camera): {street_seq_seconds:.2f} s")

    write_json_atomic(
        args.out,
        {
            "frames_per_s_kitti_size": kitti_fps,
            "ms_per_frame_kitti_size": 1e3 * seconds / args.frames,
            "render_only_frames_per_s_kitti_size": args.frames / seconds_render,
            "world_build_s": world_seconds,
            "procedural_sequence_200_frames_small_camera_s": seq_seconds,
            "street_frames_per_s_kitti_size": street_fps,
            "street_ms_per_frame_kitti_size": 1e3 * seconds_street / args.frames,
            "street_slowdown_kitti_size": kitti_fps / street_fps,
            "street_procedural_sequence_200_frames_small_camera_s": street_seq_seconds,
            "street_structures_per_frame": int(boxes.valid.shape[-1]),
            "frames": args.frames,
            "image_shape": list(camera.image_shape),
            "machine": {
                "cpu_count": os.cpu_count(),
                "platform": platform.platform(),
                "jax": jax.__version__,
                "numpy": np.__version__,
            },
        },
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
