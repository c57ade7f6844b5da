"""Learn a localization UKF's noise covariances from pose supervision (a filtering demo).

    python -m jbevo.demo [--steps 300] [--train 16] [--val 16] [--iterations 150] [--out DIR]

Simulated planar drives (:mod:`jbevo.data.synthetic.planar`) give noisy odometry increments and noisy
pose fixes, some missing. The (x, y, yaw) UKF of :mod:`jbevo.filtering.planar` starts from badly
chosen motion and measurement noise (Q too small, R too large: it trusts the drifting odometry);
``jax.grad`` through the whole filter recursion, vmapped over the training drives, and optax's
Adam learn the six log standard deviations from the true poses
(:func:`jbevo.filtering.learning.fit_noise`, supervised). The demo prints the validation
errors before and after, and writes ``metrics.json`` to ``--out`` if given.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import optax

from jbevo.cli import common
from jbevo.data.synthetic.planar import PlanarSequence, simulate_planar_sequence
from jbevo.files import write_json_atomic
from jbevo.filtering import ukf
from jbevo.filtering.learning import Noise, fit_noise
from jbevo.filtering.noise import DiagonalCovariance
from jbevo.filtering.planar import planar_pose_model
from jbevo.geometry.angles import wrap_angle

ODOMETRY_STD = (0.02, 0.01, 0.005)  # m, m, rad per step
FIX_STD = (0.5, 0.5, 0.05)  # m, m, rad
YAW_WEIGHT = 10.0  # m per rad in the training loss


PRIOR_COV = (0.1, 0.1, 0.01)


def run_filter(noise: Noise, seq: PlanarSequence) -> ukf.FilterResult:
    """The planar pose UKF with ``noise`` over one simulated drive."""
    prior = ukf.GaussianState(seq.poses[0], jnp.diag(jnp.array(PRIOR_COV)))
    return ukf.filter(planar_pose_model(), prior, seq.increments, seq.fixes, noise.motion(), noise.measurement())


def errors(noise: Noise, seq: PlanarSequence) -> tuple[jax.Array, jax.Array]:
    """Per-step position error (m) and absolute yaw error (rad) of the filtered poses."""
    est = run_filter(noise, seq).filtered_mean
    pos = jnp.linalg.norm(est[:, :2] - seq.poses[1:, :2], axis=-1)
    return pos, jnp.abs(wrap_angle(est[:, 2] - seq.poses[1:, 2]))


def summary(noise: Noise, seqs: PlanarSequence) -> dict:
    """Validation position RMSE and maximum (m) and mean yaw error (deg) over the drives."""
    pos, yaw = jax.jit(jax.vmap(errors, in_axes=(None, 0)))(noise, seqs)
    return {
        "position_rmse_m": float(jnp.sqrt(jnp.mean(pos**2))),
        "position_max_m": float(jnp.max(pos)),
        "yaw_mean_deg": float(jnp.degrees(jnp.mean(yaw))),
    }


def simulate(key, count: int, steps: int) -> PlanarSequence:
    keys = jax.random.split(key, count)
    return jax.vmap(lambda k: simulate_planar_sequence(k, steps, odometry_std=ODOMETRY_STD, fix_std=FIX_STD, fix_dropout=0.2))(
        keys
    )


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser."""
    p = common.parser("python -m jbevo.demo", __doc__, [common.seed_option()])
    p.add_argument("--steps", type=common.positive_int, default=300, help="steps per drive (default 300)")
    p.add_argument("--train", type=common.positive_int, default=16, help="training drives (default 16)")
    p.add_argument("--val", type=common.positive_int, default=16, help="validation drives (default 16)")
    p.add_argument("--iterations", type=common.positive_int, default=150, help="Adam iterations (default 150)")
    p.add_argument("--lr", type=common.positive_float, default=0.05, help="Adam learning rate (default 0.05)")
    p.add_argument("--out", type=Path, default=None, help="folder for metrics.json")
    return p


def demo(args: argparse.Namespace) -> dict:
    """Run the demo; returns the metrics (and writes them to ``args.out/metrics.json``)."""
    k_train, k_val = jax.random.split(jax.random.PRNGKey(args.seed))
    train, val = simulate(k_train, args.train, args.steps), simulate(k_val, args.val, args.steps)
    noise = Noise(  # deliberately wrong: Q 10x too small, R 5x too large
        DiagonalCovariance.from_std(jnp.array(ODOMETRY_STD) / 10),
        DiagonalCovariance.from_std(jnp.array(FIX_STD) * 5),
    )
    before = summary(noise, val)
    print(
        f"validation before: position RMSE {before['position_rmse_m']:.3f} m, "
        f"max {before['position_max_m']:.3f} m, mean yaw error {before['yaw_mean_deg']:.3f} deg"
    )
    start = time.perf_counter()
    # The loss: mean squared position error plus (10 m/rad x yaw error)^2 over the training drives.
    prior = ukf.GaussianState(train.poses[:, 0], jnp.broadcast_to(jnp.diag(jnp.array(PRIOR_COV)), (args.train, 3, 3)))
    fit = fit_noise(
        planar_pose_model(),
        prior,
        train.increments,
        train.fixes,
        noise,
        objective="supervised",
        targets=train.poses[:, 1:],
        state_weights=jnp.array([1.0, 1.0, YAW_WEIGHT**2]),
        optimizer=optax.adam(args.lr),
        iterations=args.iterations,
    )
    noise = fit.noise
    for it in range(args.iterations):
        if it % max(1, args.iterations // 5) == 0 or it == args.iterations - 1:
            print(f"  iteration {it:4d}  training loss {float(fit.losses[it]):.5f}")
    seconds = time.perf_counter() - start
    after = summary(noise, val)
    print(
        f"validation after:  position RMSE {after['position_rmse_m']:.3f} m, "
        f"max {after['position_max_m']:.3f} m, mean yaw error {after['yaw_mean_deg']:.3f} deg"
    )
    assert isinstance(noise.motion, DiagonalCovariance) and isinstance(noise.measurement, DiagonalCovariance)
    learned = {
        "motion_std": [float(v) for v in jnp.exp(noise.motion.log_std)],
        "measurement_std": [float(v) for v in jnp.exp(noise.measurement.log_std)],
    }
    print(f"learned odometry std {learned['motion_std']} (true {list(ODOMETRY_STD)})")
    print(f"learned fix std      {learned['measurement_std']} (true {list(FIX_STD)})")
    metrics = {
        "before": before,
        "after": after,
        "learned": learned,
        "true": {"motion_std": list(ODOMETRY_STD), "measurement_std": list(FIX_STD)},
        "train_seconds": seconds,
        "args": common.json_args(args),
    }
    if args.out is not None:
        write_json_atomic(args.out / "metrics.json", metrics)
        print(f"wrote {args.out / 'metrics.json'}")
    return metrics


def main(argv: list[str] | None = None) -> int:
    """Run the command with ``argv`` (default: the process's arguments); returns the exit code."""
    return common.run(build_parser(), demo, argv)


__all__ = ["build_parser", "demo", "errors", "main", "run_filter", "summary"]
