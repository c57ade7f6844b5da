"""The optimisation loop that ``python -m jbevo.train`` and ``python -m jbevo.localize train``
share: a jitted Adam step over vmapped windows, and one shuffled epoch with a progress bar."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import numpy as np
import optax
from tqdm import tqdm


def make_step(static: Any, optimizer: optax.GradientTransformation, loss: Callable[[Any, Any], jax.Array]):
    """A jitted ``step(params, opt_state, batch) -> (params, opt_state, loss)`` for
    ``loss(model, batch)``, the model being ``eqx.combine(params, static)``."""

    @eqx.filter_jit
    def step(params, opt_state, batch):
        value, grads = jax.value_and_grad(lambda p: loss(eqx.combine(p, static), batch))(params)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, value

    return step


def run_epoch(step, params, opt_state, windows: Any, batch: int, rng: np.random.Generator, label: str):
    """One pass over the ``windows`` (a batched pytree) in shuffled batches of ``batch``:
    ``(params, opt_state, mean loss, steps)``. A non-finite loss stops with a message."""
    n = jax.tree_util.tree_leaves(windows)[0].shape[0]
    order = rng.permutation(n)
    steps = max(1, n // batch)
    bar = tqdm(range(steps), desc=label, file=sys.stdout, leave=False)
    losses = []
    for i in bar:
        idx = order[i * batch : (i + 1) * batch]
        chunk = jax.tree_util.tree_map(lambda x, idx=idx: x[idx], windows)
        params, opt_state, loss = step(params, opt_state, chunk)
        if not np.isfinite(float(loss)):
            raise SystemExit(f"the loss became {float(loss)} at {label}, step {i}; lower --lr")
        losses.append(float(loss))
        bar.set_postfix(loss=f"{np.mean(losses[-10:]):.5f}")
    return params, opt_state, float(np.mean(losses)), steps
