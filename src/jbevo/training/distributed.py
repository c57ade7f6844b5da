"""One job as several processes (one per host or per accelerator) through JAX's distributed
runtime: :func:`initialize` joins the job, after which ``jax.devices()`` lists every process's
devices and a :class:`jbevo.training.data_parallel.DataParallel` spans them all.

The coordinator's address, the process count and this process's id come from the arguments,
else from JAX's environment variables (``JAX_COORDINATOR_ADDRESS``) and its cluster detection
(SLURM, Open MPI, Kubernetes; see ``jax.distributed.initialize``). On CPUs the processes reduce
over gloo."""

from __future__ import annotations

import pickle
from typing import Any

import jax
import numpy as np
from jax.experimental import multihost_utils


def initialize(coordinator: str | None = None, num_processes: int | None = None, process_id: int | None = None) -> None:
    """Join the job (before any other JAX call of this process). ``ValueError`` for a process id
    outside ``[0, num_processes)``."""
    if num_processes is not None and process_id is not None and not 0 <= process_id < num_processes:
        raise ValueError(f"process id {process_id} is outside [0, {num_processes})")
    # CPU devices of different processes reduce over gloo (the default CPU backend has no
    # cross-process collectives); accelerators use their own.
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(coordinator_address=coordinator, num_processes=num_processes, process_id=process_id)


def is_main() -> bool:
    """Whether this is the process that writes files and prints (process 0)."""
    return jax.process_index() == 0


def share(items: list) -> list:
    """This process's share of ``items``: every ``process_count``-th from its index (all of them
    in a single process)."""
    return items[jax.process_index() :: jax.process_count()]


def gather_objects(obj: Any) -> list[Any]:
    """``obj`` (any picklable value) of every process, in process order, on every process."""
    if jax.process_count() == 1:
        return [obj]
    data = np.frombuffer(pickle.dumps(obj), np.uint8)
    sizes = np.asarray(multihost_utils.process_allgather(np.array([data.size], np.int64))).reshape(-1)
    padded = np.zeros(int(sizes.max()), np.uint8)
    padded[: data.size] = data
    gathered = np.asarray(multihost_utils.process_allgather(padded)).reshape(len(sizes), -1)
    return [pickle.loads(row[:n].tobytes()) for row, n in zip(gathered, sizes)]


__all__ = ["gather_objects", "initialize", "is_main", "share"]
