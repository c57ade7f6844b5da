"""Jit-compiled runs of the models, defined once so that repeated calls with models and inputs of
the same structure reuse one compilation (a fresh ``filter_jit`` wrapper per call would trace
and compile the whole recursion again).

Example::

    >>> from jbevo.models.bevo import Bevo
    >>> out = run_bevo(Bevo.create(), seq)                      # doctest: +SKIP
    >>> outs = run_bevo_batch(Bevo.create(), batch)             # vmapped over a stacked batch  # doctest: +SKIP
"""

from __future__ import annotations

import equinox as eqx
import jax

from jbevo.data.map import Map
from jbevo.data.sequence import Sequence
from jbevo.models.bevo import Bevo, BevoOutput
from jbevo.models.bevo_plus import BevoPlus, LocalizationOutput


@eqx.filter_jit
def run_bevo(model: Bevo, seq: Sequence, warm_start: bool = False) -> BevoOutput:
    """``model(seq, warm_start=warm_start)`` for one unbatched sequence, jitted."""
    return model(seq, warm_start=warm_start)


@eqx.filter_jit
def run_bevo_batch(model: Bevo, batch: Sequence, warm_start: bool = False) -> BevoOutput:
    """``model`` over a batched sequence (leading axis on every array), vmapped and jitted."""
    return jax.vmap(lambda seq: model(seq, warm_start=warm_start))(batch)


@eqx.filter_jit
def run_bevo_plus(model: BevoPlus, seq: Sequence, map_: Map, warm_start: bool = False) -> LocalizationOutput:
    """``model(seq, map_, warm_start=warm_start)`` for one unbatched sequence, jitted."""
    return model(seq, map_, warm_start=warm_start)


@eqx.filter_jit
def run_bevo_plus_batch(model: BevoPlus, batch: Sequence, map_: Map, warm_start: bool = False) -> LocalizationOutput:
    """``model`` over a batched sequence that shares one map, vmapped and jitted."""
    return jax.vmap(lambda seq: model(seq, map_, warm_start=warm_start))(batch)


__all__ = ["run_bevo", "run_bevo_batch", "run_bevo_plus", "run_bevo_plus_batch"]
