"""BEVO throughput and memory at KITTI image size (376x1241, KITTI camera 0) with a 256x256 BEV
(0.1 m/px, 4-29.6 m ahead): inference frames per second (sequences vmapped, one jitted call),
training frames per second (value and gradient of the motion loss over windows of 64 frames,
``jax.checkpoint`` per frame) and the compiled training step's peak memory (XLA's memory
analysis: arguments + temporaries + outputs), for one window of 64 frames; for BEVO with the band
geometry (``jbevo.vision.bands``, the top-level keys) and without (``without_bands``).

    python benchmarks/bevo.py [--sequences 4] [--frames 64] [--repeats 3]

The frames are rendered from a procedural drive (the synthetic world). Writes
``benchmarks/results/bevo.json``.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

from jbevo import data
from jbevo.data.synthetic import World, procedural_sequence
from jbevo.files import write_json_atomic
from jbevo.geometry import BevGrid, Camera
from jbevo.models import Bevo, motion_loss
from timing import best_seconds


def measure(model: Bevo, batch, window, repeats: int) -> dict:
    """Inference frames/s over the vmapped ``batch``, training frames/s and the compiled training
    step's memory over one ``window``."""
    sequences, frames = batch.images.shape[:2]
    infer = eqx.filter_jit(jax.vmap(lambda m, s: m(s), in_axes=(None, 0)))
    seconds = best_seconds(lambda: infer(model, batch), repeats)
    inference_fps = sequences * frames / seconds
    print(f"  inference: {inference_fps:.1f} frames/s ({1e3 * seconds / (sequences * frames):.2f} ms/frame)")
    params, static = eqx.partition(model, eqx.is_inexact_array)

    def loss(p, s):
        return motion_loss(eqx.combine(p, static)(s, warm_start=True), s)

    grad_fn = jax.jit(jax.value_and_grad(loss))
    memory = grad_fn.lower(params, window).compile().memory_analysis()
    peak_bytes = None
    if memory is not None:
        peak_bytes = memory.argument_size_in_bytes + memory.temp_size_in_bytes + memory.output_size_in_bytes
    train_fps = window.images.shape[0] / best_seconds(lambda: grad_fn(params, window), repeats)
    print(f"  training: {train_fps:.1f} frames/s; step memory {peak_bytes / 2**30:.3f} GB (XLA)")
    return {
        "inference_frames_per_s": inference_fps,
        "train_frames_per_s": train_fps,
        "peak_memory_gb_window64": peak_bytes / 2**30 if peak_bytes is not None else None,
        "learnable_parameters": model.num_learnable(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sequences", type=int, default=4)
    parser.add_argument("--frames", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "bevo.json")
    args = parser.parse_args()

    world = World.create("town01")
    camera = Camera.kitti()
    seqs = [procedural_sequence(s, args.frames, camera=camera, world=world) for s in range(args.sequences)]
    batch = data.stack(seqs)
    grid = BevGrid(0.1, (256, 256), near=4.0)
    results = {}
    for label, bands in (("with_bands", True), ("without_bands", False)):
        model = Bevo.create(grid, bands=bands)
        print(
            f"{label}: {model.num_learnable()} learnable parameters; {args.sequences} sequences x {args.frames} frames of {camera.image_shape}"
        )
        results[label] = measure(model, batch, seqs[0], args.repeats)
    rss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(f"process peak RSS {rss_gb:.2f} GB")
    main_result = results["with_bands"]

    write_json_atomic(
        args.out,
        {
            **main_result,
            "without_bands": results["without_bands"],
            "process_peak_rss_gb": rss_gb,
            "window_frames": args.frames,
            "sequences": args.sequences,
            "image_shape": list(camera.image_shape),
            "bev_shape": list(grid.shape),
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
