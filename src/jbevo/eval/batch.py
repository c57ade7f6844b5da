"""Evaluation of many sequences at once: equal-length sequences stacked and run in one jitted,
vmapped call, the batch sharded over the local devices (``jax.sharding``)."""

from __future__ import annotations

import time

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jbevo.data import sequence as sq
from jbevo.models.bevo import Bevo, BevoOutput
from jbevo.models.runners import run_bevo_batch
from jbevo.progress import progress


def shard_batch(batch, devices=None):
    """Place a batched pytree with its leading axis split over ``devices`` (all local ones)."""
    devices = jax.local_devices() if devices is None else devices
    mesh = Mesh(np.array(devices), ("batch",))
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    return jax.device_put(batch, sharding)


def run_many(
    model: Bevo, seqs: list[sq.Sequence], warm_start: bool = False, devices: list | None = None
) -> tuple[list[BevoOutput], float]:
    """Outputs for every sequence (vmapped per group of equal length, sharded over ``devices``,
    default all local ones, padded to a multiple of their count; numpy arrays) and the
    steady-state frames per second of the sequences given, the padding not counted (each group is
    run twice: the first call compiles)."""
    devices = jax.local_devices() if devices is None else list(devices)
    n_dev = len(devices)
    outputs: list[BevoOutput | None] = [None] * len(seqs)
    frames, seconds = 0, 0.0
    groups: dict[tuple, list[int]] = {}
    for i, s in enumerate(seqs):
        groups.setdefault((s.num_frames, s.camera.image_shape, s.imu_times.shape[-1]), []).append(i)
    for idx in progress(list(groups.values()), "evaluating"):
        padded = idx + [idx[-1]] * (-len(idx) % n_dev)
        batch = shard_batch(sq.stack([seqs[i] for i in padded]), devices)
        jax.block_until_ready(run_bevo_batch(model, batch, warm_start))  # compile
        t0 = time.perf_counter()
        out = jax.block_until_ready(run_bevo_batch(model, batch, warm_start))
        seconds += time.perf_counter() - t0
        frames += len(idx) * seqs[idx[0]].num_frames
        for j, i in enumerate(idx):
            outputs[i] = jax.tree_util.tree_map(lambda x, j=j: np.asarray(x[j]), out)
    return outputs, frames / seconds  # type: ignore[return-value]


__all__ = ["run_many", "shard_batch"]
