"""Parallel-in-time smoothing against sequential, on this machine, over sequence lengths.

The BEVO+ localization model (state (x, y, yaw), odometry increments, pose fixes; float64) over
T = 1e3, 1e4 and 1e5 steps. In one process on the same data, timed in interleaved rounds (best
of ``--repeats``), each jitted:

* ``ukf_uks``: jbevo's unscented Kalman filter and unscented RTS smoother (sequential, one pass);
* ``ipls_sequential`` / ``ipls_parallel``: one iteration of the iterated posterior-linearisation
  smoother (sigma-point linearisation, then the affine filter and smoother by ``lax.scan`` or by
  ``associative_scan``), from the same linearisation points;
* ``affine_sequential`` / ``affine_parallel``: the affine Kalman filter and RTS smoother alone;
  ``affine_sequential_plain_loop``: the sequential ones with XLA's plain loops instead of one
  kernel per loop (``one_kernel=False``), the per-step overhead that the parallel form avoids.

Also recorded: the largest difference between the parallel and sequential results, the number
of iterations to convergence from the unscented smoother's points, and the distance of the
converged smoother from the unscented one. Writes ``benchmarks/results/parallel_in_time.json``.

    python benchmarks/parallel_in_time.py [--steps 1000 10000 100000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import math
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
from jbevo.filtering import parallel, smoother, ukf  # noqa: E402
from jbevo.filtering import posterior_linearisation as pl  # noqa: E402
from jbevo.filtering.planar import planar_pose_model  # noqa: E402
from jbevo.geometry import wrap_angle  # noqa: E402
from timing import best_seconds_interleaved  # noqa: E402

Q = jnp.diag(jnp.array([0.02, 0.01, 0.005]) ** 2)
R = jnp.diag(jnp.array([0.5, 0.5, 0.05]) ** 2)
P0 = jnp.diag(jnp.array([1.0, 1.0, 0.1]) ** 2)
CONVERGED = 1e-9  #: largest change of a smoothed mean in an iteration, at convergence


def state_difference(a, b) -> float:
    d = np.array(a) - np.array(b)
    d[..., 2] = np.asarray(wrap_angle(jnp.asarray(d[..., 2])))
    return float(np.abs(d).max())


def measure(steps: int, repeats: int) -> dict:
    model = planar_pose_model()
    seq = simulate_planar_sequence(jax.random.PRNGKey(0), steps, yaw_rate_std=0.2, fix_std=(0.5, 0.5, 0.3))
    initial = ukf.GaussianState(seq.poses[0] + jnp.array([0.3, -0.2, 0.05]), P0)
    controls, fixes = seq.increments, seq.fixes
    q_seq = jnp.broadcast_to(Q, (steps, 3, 3))
    r_seq = jnp.broadcast_to(R, (steps, 3, 3))

    @jax.jit
    def ukf_uks(controls, fixes):
        result = ukf.filter(model, initial, controls, fixes, Q, R, check_inputs=False)
        return smoother.smooth(model, result, controls, Q).smoothed_mean

    points = jax.jit(lambda c, z: pl.unscented_linearisation(model, initial, c, z, q_seq, r_seq))(controls, fixes)

    def ipls(parallel_in_time: bool, iterations: int = 1):
        return jax.jit(
            lambda c, z, p: pl.smooth(
                model,
                initial,
                c,
                z,
                Q,
                R,
                iterations=iterations,
                parallel_in_time=parallel_in_time,
                linearisation=p,
                check_inputs=False,
            )
        )

    ipls_seq, ipls_par = ipls(False), ipls(True)
    affine = jax.jit(lambda c, z, p: pl.linearised_model(model, p, c, z, q_seq, r_seq))(controls, fixes, points)
    prior = ukf.GaussianState(initial.mean, initial.cov)

    def affine_sequential(m, one_kernel=True):
        filtered = parallel.sequential_filter(m, prior, one_kernel=one_kernel)
        return parallel.sequential_smoother(m, filtered, one_kernel=one_kernel).mean

    affine_seq = jax.jit(affine_sequential)
    affine_seq_plain = jax.jit(lambda m: affine_sequential(m, one_kernel=False))
    affine_par = jax.jit(lambda m: parallel.smooth(m, parallel.filter(m, prior)).mean)

    seconds = best_seconds_interleaved(
        {
            "ukf_uks": lambda: ukf_uks(controls, fixes),
            "ipls_sequential": lambda: ipls_seq(controls, fixes, points).smoothed_mean,
            "ipls_parallel": lambda: ipls_par(controls, fixes, points).smoothed_mean,
            "affine_sequential": lambda: affine_seq(affine),
            "affine_sequential_plain_loop": lambda: affine_seq_plain(affine),
            "affine_parallel": lambda: affine_par(affine),
        },
        repeats,
    )
    a, b = ipls_seq(controls, fixes, points), ipls_par(controls, fixes, points)
    converged = ipls(True, iterations=10)(controls, fixes, points)
    changes = np.asarray(converged.mean_change)
    below = np.nonzero(changes < CONVERGED)[0]
    return {
        "seconds": seconds,
        "parallel_over_sequential": {
            "ipls_iteration": seconds["ipls_parallel"] / seconds["ipls_sequential"],
            "affine_filter_smoother": seconds["affine_parallel"] / seconds["affine_sequential"],
            "affine_filter_smoother_plain_loop": seconds["affine_parallel"] / seconds["affine_sequential_plain_loop"],
        },
        "max_abs_diff_parallel_vs_sequential": {
            "smoothed_mean": state_difference(a.smoothed_mean, b.smoothed_mean),
            "smoothed_cov": float(np.abs(np.asarray(a.smoothed_cov - b.smoothed_cov)).max()),
        },
        "mean_change_per_iteration": changes.tolist(),
        "iterations_to_converge": int(below[0]) + 1 if below.size else None,
        "max_abs_diff_converged_vs_ukf_uks": state_difference(converged.smoothed_mean, ukf_uks(controls, fixes)),
        "span_ratio_sequential_over_parallel": steps / (2 * math.ceil(math.log2(steps))),
    }


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, nargs="+", default=[1000, 10000, 100000])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "parallel_in_time.json")
    args = p.parse_args(argv)
    results = {
        "config": {
            "steps": args.steps,
            "repeats": args.repeats,
            "dtype": "float64",
            "state_dim": 3,
            "converged_below": CONVERGED,
        },
        "by_steps": {},
    }
    for steps in args.steps:
        r = measure(steps, args.repeats)
        results["by_steps"][str(steps)] = r
        s = r["seconds"]
        print(
            f"T={steps:>6}: UKF+URTS {s['ukf_uks'] * 1e3:8.1f} ms | IPLS iteration seq {s['ipls_sequential'] * 1e3:8.1f} ms, "
            f"par {s['ipls_parallel'] * 1e3:8.1f} ms ({r['parallel_over_sequential']['ipls_iteration']:.2f}x) | affine seq "
            f"{s['affine_sequential'] * 1e3:8.1f} ms, par {s['affine_parallel'] * 1e3:8.1f} ms "
            f"({r['parallel_over_sequential']['affine_filter_smoother']:.2f}x) | converged in {r['iterations_to_converge']}",
            flush=True,
        )
    results["machine"] = (
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, {jax.devices()[0].platform}"
    )
    write_json_atomic(args.out, results)
    return results


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
