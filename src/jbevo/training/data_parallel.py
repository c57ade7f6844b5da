"""Data-parallel training: a batch of windows split along its leading axis over every device of
every process, the parameters and the optimizer's state replicated.

The loss and its gradient are computed per shard inside :func:`jax.shard_map` and averaged over
the data axis (``lax.pmean``: one all-reduce), so every device applies the same update. Each
shard holds ``batch / devices`` windows and the loss is a mean over windows, so the mean of the
shards' means is the batch's mean: the result equals one device's to round-off (the reduction
order differs). Each process materialises only the rows of a batch its own devices hold
(:meth:`DataParallel.local_rows`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

#: The mesh axis the batch is split over.
DATA_AXIS = "data"


@dataclass(frozen=True)
class DataParallel:
    """A one-axis mesh (:data:`DATA_AXIS`) over ``devices`` (default: all devices of all processes)."""

    mesh: Mesh

    @classmethod
    def create(cls, devices: list | None = None) -> DataParallel:
        devices = jax.devices() if devices is None else list(devices)
        if not devices:
            raise ValueError("data parallelism needs at least one device")
        return cls(Mesh(np.array(devices), (DATA_AXIS,)))

    @property
    def size(self) -> int:
        """The number of devices the batch is split over."""
        return int(self.mesh.devices.size)

    @property
    def batch_sharding(self) -> NamedSharding:
        return NamedSharding(self.mesh, PartitionSpec(DATA_AXIS))

    @property
    def replicated(self) -> NamedSharding:
        return NamedSharding(self.mesh, PartitionSpec())

    def check_batch(self, batch: int) -> None:
        """``ValueError`` unless ``batch`` windows split evenly over the devices."""
        if batch < 1 or batch % self.size:
            raise ValueError(
                f"a batch of {batch} windows does not split evenly over {self.size} devices; use a multiple of {self.size}"
            )

    def local_rows(self, batch: int) -> np.ndarray:
        """The rows of a global batch of ``batch`` that this process's devices hold, in order."""
        self.check_batch(batch)
        index_map = self.batch_sharding.addressable_devices_indices_map((batch,))
        rows = {r for index in index_map.values() if index for r in range(*index[0].indices(batch))}
        return np.array(sorted(rows), int)

    def put_batch(self, local: Any, batch: int) -> Any:
        """A global batch (leading axis ``batch``, split over the devices) from this process's rows
        of it (:meth:`local_rows`, numpy leaves)."""
        return jax.tree_util.tree_map(
            lambda x: jax.make_array_from_process_local_data(self.batch_sharding, np.asarray(x), (batch, *np.shape(x)[1:])),
            local,
        )

    def replicate(self, tree: Any) -> Any:
        """``tree``'s arrays copied to every device (the same value on every process)."""
        return jax.tree_util.tree_map(
            lambda x: jax.make_array_from_process_local_data(self.replicated, np.asarray(x)) if _is_array(x) else x, tree
        )

    def mean_over_batch(self, f: Callable[[Any, Any], Any]) -> Callable[[Any, Any], Any]:
        """``f(replicated, batch)`` (a mean over the batch's windows, any pytree of results) run
        per shard of the batch and averaged over the devices."""

        def per_shard(replicated, batch):
            return jax.lax.pmean(f(replicated, batch), DATA_AXIS)

        spec = PartitionSpec(DATA_AXIS)
        return jax.shard_map(
            per_shard, mesh=self.mesh, in_specs=(PartitionSpec(), spec), out_specs=PartitionSpec(), check_vma=False
        )


def local_copy(tree: Any) -> Any:
    """``tree`` with every array replaced by this process's copy of it (on one local device), for arrays
    replicated over devices of other processes too (which numpy cannot read whole)."""
    return jax.tree_util.tree_map(lambda x: x.addressable_data(0) if isinstance(x, jax.Array) else x, tree)


def _is_array(x: Any) -> bool:
    return isinstance(x, (jax.Array, np.ndarray, np.generic))


__all__ = ["DATA_AXIS", "DataParallel", "local_copy"]
