"""Counting a model's learnable parameters."""

from __future__ import annotations

import equinox as eqx
import jax


def num_learnable(module: eqx.Module) -> int:
    """Number of learnable scalars (inexact array leaves) of a model."""
    return sum(int(x.size) for x in jax.tree_util.tree_leaves(eqx.filter(module, eqx.is_inexact_array)))


__all__ = ["num_learnable"]
