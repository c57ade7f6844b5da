"""Shared by the benchmark scripts (run as ``python benchmarks/<name>.py``, so this folder is on
``sys.path``)."""

from __future__ import annotations

import time

import jax


def best_seconds(fn, repeats: int) -> float:
    """Best wall time of ``fn()`` over ``repeats`` runs, after one warm-up call (compilation);
    waits for JAX results."""
    return best_seconds_interleaved({"fn": fn}, repeats)["fn"]


def best_seconds_interleaved(fns: dict, repeats: int) -> dict:
    """Best wall time of each ``fns[name]()`` over ``repeats`` rounds that run every function once
    in turn (after one warm-up call each), so that a slow spell of a shared machine falls on all
    of them rather than on whichever was being timed; waits for JAX results."""
    for fn in fns.values():
        jax.block_until_ready(fn())
    best = dict.fromkeys(fns, float("inf"))
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            jax.block_until_ready(fn())
            best[name] = min(best[name], time.perf_counter() - t0)
    return best
