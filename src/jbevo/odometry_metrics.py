"""Scores of BEVO outputs against a batch of sequences' ground truth, shared by
``python -m jbevo.train`` and ``python -m jbevo.evaluate``.

The planar trajectories are lifted to SE(3) with ``z = 0`` and scored with the KITTI devkit's
segment errors (pooled over all segments of all sequences, as the devkit pools a benchmark),
ATE (no alignment: both start at the true first pose) and the per-frame motion error. The
devkit's segment lengths (100-800 m) need long drives; the built-in sequences are ~100 m, so
the training command scores them on 10-50 m segments and says so in its output.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jbevo import metrics
from jbevo.datasets.sequence import Sequence
from jbevo.geometry import wrap_angle
from jbevo.odometry import BevoOutput, relative_motion

SHORT_SEGMENTS = (10.0, 20.0, 30.0, 40.0, 50.0)


def segment_lengths(dataset: str, frames: int) -> tuple[float, ...]:
    """The devkit's 100-800 m, or 10-50 m where the drives are too short for them (the built-in
    synthetic drives, or a cap of under 1,000 frames)."""
    short = dataset == "synthetic" or (frames and frames < 1000)
    return SHORT_SEGMENTS if short else metrics.SEGMENT_LENGTHS


def segment_errors(poses: Float[Array, "T 3"], planar: Float[Array, "T 3"], lengths: tuple[float, ...]) -> metrics.SegmentErrors:
    """Devkit segment errors of one planar estimate against its planar truth (both lifted to
    z = 0), starting every frame for short segments and every 10 frames (the devkit's step) for
    the devkit's lengths."""
    step = 1 if lengths[0] < 100 else 10
    return metrics.kitti_segment_errors(metrics.planar_to_se3(planar), metrics.planar_to_se3(poses), lengths=lengths, step=step)


def score(output: BevoOutput, seq: Sequence, lengths: tuple[float, ...] = metrics.SEGMENT_LENGTHS) -> dict:
    """Pooled ``t_err_pct``, ``r_err_deg_per_100m`` (over segments of ``lengths`` metres),
    ``ate_m`` (RMS over all frames of all sequences), per-frame ``motion_rmse_m`` and
    ``yaw_rmse_deg``, and per-sequence ``t_err_pct`` / ``ate_m`` lists. Batched inputs
    (leading axis) or one sequence."""
    if seq.frame_times.ndim == 1:
        output = jax.tree_util.tree_map(lambda x: x[None], output)
        seq = jax.tree_util.tree_map(lambda x: x[None], seq)
    segments = jax.vmap(lambda e, g: segment_errors(e, g, lengths))(output.poses, seq.planar)
    pooled = metrics.kitti_errors(metrics.SegmentErrors(*(x.reshape(-1, x.shape[-1]) for x in segments)))
    per_seq = [metrics.kitti_errors(jax.tree_util.tree_map(lambda x, i=i: x[i], segments)) for i in range(seq.planar.shape[0])]
    position_error = jnp.sum((output.poses[..., :2] - seq.planar[..., :2]) ** 2, -1)
    truth = jax.vmap(relative_motion)(seq)
    err = (output.increments - truth)[:, 1:]
    return {
        "t_err_pct": float(pooled.t_err_pct),
        "r_err_deg_per_100m": float(pooled.r_err_deg_per_100m),
        "segments": int(pooled.segments),
        "segment_lengths_m": list(lengths),
        "ate_m": float(jnp.sqrt(jnp.mean(position_error))),
        "motion_rmse_m": float(jnp.sqrt(jnp.mean(err[..., 0] ** 2 + err[..., 1] ** 2))),
        "yaw_rmse_deg": float(jnp.degrees(jnp.sqrt(jnp.mean(wrap_angle(err[..., 2]) ** 2)))),
        "per_sequence": {
            "t_err_pct": [float(k.t_err_pct) for k in per_seq],
            "r_err_deg_per_100m": [float(k.r_err_deg_per_100m) for k in per_seq],
            "ate_m": [float(v) for v in np.sqrt(np.mean(np.asarray(position_error), axis=-1))],
        },
    }
