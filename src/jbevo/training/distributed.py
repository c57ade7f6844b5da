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
from jax.sharding import Mesh, NamedSharding, PartitionSpec

#: Seconds a process that has finished waits at exit for the others.
SHUTDOWN_WAIT_S = 6 * 3600


def initialize(coordinator: str | None = None, num_processes: int | None = None, process_id: int | None = None) -> None:
    """Join the job (before any other JAX call of this process). ``ValueError`` for a process id
    outside ``[0, num_processes)``."""
    if num_processes is not None and process_id is not None and not 0 <= process_id < num_processes:
        raise ValueError(f"process id {process_id} is outside [0, {num_processes})")
    # CPU devices of different processes reduce over gloo (the default CPU backend has no
    # cross-process collectives); accelerators use their own.
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    # A process that finishes first (process 0 still writing its files) waits at exit for the
    # others up to SHUTDOWN_WAIT_S; a process that dies is noticed by its heartbeat.
    jax.distributed.initialize(
        coordinator_address=coordinator,
        num_processes=num_processes,
        process_id=process_id,
        shutdown_timeout_seconds=SHUTDOWN_WAIT_S,
    )


def is_main() -> bool:
    """Whether this is the process that writes files and prints (process 0)."""
    return jax.process_index() == 0


def share(items: list) -> list:
    """This process's share of ``items``: every ``process_count``-th from its index (all of them
    in a single process)."""
    return items[jax.process_index() :: jax.process_count()]


def gather_objects(obj: Any) -> list[Any]:
    """``obj`` (any picklable value) of every process, in process order, on every process (a
    collective: every process must call it). Processes may hold different numbers of devices."""
    if jax.process_count() == 1:
        return [obj]
    data = np.frombuffer(pickle.dumps(obj), np.uint8)
    sizes = _allgather_rows(np.array([data.size], np.int64)).reshape(-1)
    padded = np.zeros(int(sizes.max()), np.uint8)
    padded[: data.size] = data
    gathered = _allgather_rows(padded)
    return [pickle.loads(row[:n].tobytes()) for row, n in zip(gathered, sizes)]


def agree(error: str | None) -> None:
    """Raise ``RuntimeError`` on every process if ``error`` (this process's failure, or None) is
    set on any: so that a failure on one host (a missing file, a bad checkpoint) stops all of
    them at once, instead of leaving the others waiting in a collective."""
    failed = [(i, e) for i, e in enumerate(gather_objects(error)) if e is not None]
    if failed:
        i, e = failed[0]
        raise RuntimeError(e if i == jax.process_index() or jax.process_count() == 1 else f"process {i}: {e}")


def _allgather_rows(row: np.ndarray) -> np.ndarray:
    """``row`` (one 1-D array, the same size on every process) of every process, stacked in
    process order: one device of each process in a mesh, whatever each holds."""
    devices = [min((d for d in jax.devices() if d.process_index == p), key=lambda d: d.id) for p in range(jax.process_count())]
    mesh = Mesh(np.array(devices), ("process",))
    local = jax.make_array_from_process_local_data(NamedSharding(mesh, PartitionSpec("process")), row[None])
    full = jax.jit(lambda x: x, out_shardings=NamedSharding(mesh, PartitionSpec()))(local)
    return np.asarray(full.addressable_data(0))


__all__ = ["SHUTDOWN_WAIT_S", "agree", "gather_objects", "initialize", "is_main", "share"]
