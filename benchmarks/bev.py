"""BEV projection speed: jbevo ``bev_project`` vs the same homography sampled with dm-pix and
with OpenCV's ``warpPerspective`` (not differentiable; a speed reference), same process.

A 256x256 BEV (0.1 m/px, 4-29.6 m ahead) from 376x1241 float32 grayscale images (KITTI size,
KITTI camera 0 intrinsics at 1.65 m), random pitch/roll within +-3 deg, batches of ``--batch``
frames, best of ``--repeats`` after compilation. Writes ``benchmarks/results/bev.json``.

    python benchmarks/bev.py [--batch 32] [--repeats 7]
"""

from __future__ import annotations

import argparse
import os
import platform
from pathlib import Path

import cv2
import dm_pix
import jax
import jax.numpy as jnp
import numpy as np

from jbevo.files import write_json_atomic
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import Camera
from jbevo.vision.bev import bev_project, bev_to_image_homography
from timing import best_seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "bev.json")
    args = parser.parse_args()

    camera = Camera.kitti()
    grid = BevGrid(0.1, (256, 256), near=4.0)
    rng = np.random.default_rng(0)
    images = jnp.asarray(rng.random((args.batch, *camera.image_shape)), jnp.float32)
    pitch = jnp.asarray(np.radians(rng.uniform(-3, 3, args.batch)), jnp.float32)
    roll = jnp.asarray(np.radians(rng.uniform(-3, 3, args.batch)), jnp.float32)

    ours = jax.jit(jax.vmap(lambda im, p, r: bev_project(im, p, r, camera, grid)))

    def dmpix_one(image, p, r):
        h = bev_to_image_homography(camera, grid, p, r)
        rows, cols = jnp.meshgrid(jnp.arange(256.0), jnp.arange(256.0), indexing="ij")
        q = jnp.einsum("ij,jhw->ihw", h, jnp.stack([cols, rows, jnp.ones_like(rows)]))
        coords = jnp.stack([q[1] / q[2], q[0] / q[2]], -1)  # (row, col)
        return dm_pix.flat_nd_linear_interpolate(image, coords.reshape(-1, 2).T).reshape(256, 256)

    dmpix = jax.jit(jax.vmap(dmpix_one))

    homographies = [np.asarray(bev_to_image_homography(camera, grid, p, r)) for p, r in zip(pitch, roll)]
    images_np = np.asarray(images)

    def opencv():
        for im, h in zip(images_np, homographies):
            cv2.warpPerspective(im, h, (256, 256), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)

    results = {}
    for name, fn in (("jbevo", lambda: ours(images, pitch, roll)), ("dm_pix", lambda: dmpix(images, pitch, roll))):
        results[f"{name}_bev_per_s"] = args.batch / best_seconds(fn, args.repeats)
    results["opencv_bev_per_s"] = args.batch / best_seconds(opencv, args.repeats)
    single = jax.jit(lambda im, p, r: bev_project(im, p, r, camera, grid))
    results["jbevo_single_ms"] = 1e3 * best_seconds(lambda: single(images[0], pitch[0], roll[0]), args.repeats)
    results["bev_per_s"] = results["jbevo_bev_per_s"]
    results["speedup_vs_dm_pix"] = results["jbevo_bev_per_s"] / results["dm_pix_bev_per_s"]
    results["speedup_vs_opencv"] = results["jbevo_bev_per_s"] / results["opencv_bev_per_s"]
    bev_ours, valid = ours(images, pitch, roll)
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    bev_cv = cv2.warpPerspective(images_np[0], homographies[0], (256, 256), flags=flags)
    inside = np.asarray(valid[0])
    results["max_abs_diff_vs_opencv_inside"] = float(np.abs(np.asarray(bev_ours[0]) - bev_cv)[inside].max())
    results["config"] = {
        "batch": args.batch,
        "bev": "256x256 at 0.1 m/px",
        "image": "376x1241 float32",
        "jax": jax.__version__,
        "opencv": cv2.__version__,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.python_version()}",
    }
    write_json_atomic(args.out, results)
    for k, v in results.items():
        if k != "config":
            print(f"{k:32s} {v:,.3f}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
