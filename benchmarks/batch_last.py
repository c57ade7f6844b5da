"""Batches with the batch as the last axis (``jbevo.filtering.batch_last.vmap_last``) against
``jax.vmap``, and against dynamax 1.0.3's UKF vmapped, same data, same process.

The localization model and data of ``benchmarks/ukf.py`` (T = 5,000 steps, 64 sequences,
float64): jbevo's UKF vmapped (each loop one XLA:CPU kernel), the same filter under
``vmap_last`` (inputs and outputs batch-last), dynamax's UKF vmapped; and the gradient of the
summed log-likelihood with respect to the initial means, vmapped and batch-last. Timed in
interleaved rounds (best of ``--repeats``), the whole measurement repeated ``--runs`` times
(the JSON keeps every run; its top-level figures are the medians). Writes
``benchmarks/results/batch_last.json``.

    python benchmarks/batch_last.py [--steps 5000] [--batch 64] [--repeats 7] [--runs 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jbevo.data.synthetic.planar import simulate_planar_sequence  # noqa: E402
from jbevo.files import write_json_atomic  # noqa: E402
from jbevo.filtering.batch_last import vmap_last  # noqa: E402
from timing import best_seconds_interleaved  # noqa: E402
from ukf import dynamax_start, make_dynamax_runner, make_jbevo, make_log_likelihood  # noqa: E402


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "batch_last.json")
    args = parser.parse_args(argv)
    steps, batch = args.steps, args.batch

    keys = jax.random.split(jax.random.PRNGKey(0), batch)
    seqs = jax.vmap(lambda k: simulate_planar_sequence(k, steps, yaw_rate_std=0.1))(keys)
    x0 = seqs.poses[:, 0] + jnp.array([0.5, -0.5, 0.05])
    leading = (x0, seqs.increments, seqs.fixes)
    trailing = tuple(jnp.moveaxis(a, 0, -1) for a in leading)

    jb_vmap = jax.jit(jax.vmap(make_jbevo(check_inputs=False)))
    jb_last = jax.jit(vmap_last(make_jbevo(check_inputs=False, one_kernel=False)))
    grad_vmap = jax.jit(jax.grad(lambda *a: jnp.sum(jax.vmap(make_log_likelihood(check_inputs=False))(*a))))
    grad_last = jax.jit(jax.grad(lambda *a: jnp.sum(vmap_last(make_log_likelihood(one_kernel=False, check_inputs=False))(*a))))

    pred0, fixes_unwrapped = dynamax_start(x0, seqs.increments, seqs.fixes)
    dyn = make_dynamax_runner()
    dyn_vmap = jax.jit(jax.vmap(lambda m, P, u, z: dyn(m, P, u, z)))

    timings = {
        "jbevo_vmap64": lambda: jb_vmap(*leading),
        "jbevo_batch_last64": lambda: jb_last(*trailing),
        "dynamax_vmap64": lambda: dyn_vmap(pred0.mean, pred0.cov, seqs.increments, fixes_unwrapped),
        "jbevo_grad_vmap64": lambda: grad_vmap(*leading),
        "jbevo_grad_batch_last64": lambda: grad_last(*trailing),
    }
    runs = []
    for _ in range(args.runs):
        run = {name: batch * steps / t for name, t in best_seconds_interleaved(timings, args.repeats).items()}
        run["batch_last_speedup_vs_vmap"] = run["jbevo_batch_last64"] / run["jbevo_vmap64"]
        run["batch_last_speedup_vs_dynamax"] = run["jbevo_batch_last64"] / run["dynamax_vmap64"]
        run["vmap_speedup_vs_dynamax"] = run["jbevo_vmap64"] / run["dynamax_vmap64"]
        run["grad_batch_last_speedup_vs_vmap"] = run["jbevo_grad_batch_last64"] / run["jbevo_grad_vmap64"]
        runs.append(run)

    results: dict = {"T": steps, "batch": batch, "dtype": "float64", "repeats": args.repeats, "runs": runs}
    results.update({name: float(np.median([r[name] for r in runs])) for name in runs[0]})
    ours, theirs = jb_last(*trailing), jb_vmap(*leading)
    results["max_abs_diff_batch_last_vs_vmap"] = float(
        max(np.abs(np.asarray(jnp.moveaxis(a, -1, 0)) - np.asarray(b)).max() for a, b in zip(ours, theirs, strict=True))
    )
    g_last, g_vmap = grad_last(*trailing), grad_vmap(*leading)
    results["max_rel_diff_grad_batch_last_vs_vmap"] = float(
        np.abs(np.asarray(jnp.moveaxis(g_last, -1, 0)) - np.asarray(g_vmap)).max() / np.abs(np.asarray(g_vmap)).max()
    )
    results["machine"] = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}"
    print(
        f"steps/s over {batch} sequences: vmap {results['jbevo_vmap64']:,.0f}, batch-last {results['jbevo_batch_last64']:,.0f} "
        f"({results['batch_last_speedup_vs_vmap']:.2f}x; {results['batch_last_speedup_vs_dynamax']:.2f}x dynamax "
        f"{results['dynamax_vmap64']:,.0f}); gradient {results['grad_batch_last_speedup_vs_vmap']:.2f}x vmap's; "
        f"max |batch-last - vmap| {results['max_abs_diff_batch_last_vs_vmap']:.1e}"
    )
    write_json_atomic(args.out, results)
    return results


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
