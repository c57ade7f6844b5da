"""Shared by the benchmark scripts (run as ``python benchmarks/<name>.py``, so this folder is on
``sys.path``)."""

from __future__ import annotations

import time

import jax


def best_seconds(fn, repeats: int) -> float:
    """Best wall time of ``fn()`` over ``repeats`` runs, after one warm-up call (compilation);
    waits for JAX results."""
    jax.block_until_ready(fn())
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best
