"""Scores of model outputs against ground truth: BEVO's odometry (KITTI devkit segment errors,
ATE, per-frame motion) and BEVO+'s localization (position and yaw errors).

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
from jaxtyping import ArrayLike, Float

from jbevo.data.sequence import Sequence
from jbevo.eval import devkit
from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.se3 import planar_to_se3
from jbevo.models.bevo import BevoOutput
from jbevo.models.losses import relative_motion

SHORT_SEGMENTS = (10.0, 20.0, 30.0, 40.0, 50.0)


def segment_lengths(dataset: str, frames: int) -> tuple[float, ...]:
    """The devkit's 100-800 m, or 10-50 m where the drives are too short for them (the built-in
    synthetic drives, or a cap of under 1,000 frames)."""
    short = dataset == "synthetic" or (frames and frames < 1000)
    return SHORT_SEGMENTS if short else devkit.SEGMENT_LENGTHS


def segment_errors(
    poses: Float[ArrayLike, "T 3"], planar: Float[ArrayLike, "T 3"], lengths: tuple[float, ...]
) -> devkit.SegmentErrors:
    """Devkit segment errors of one planar estimate against its planar truth (both lifted to
    z = 0), starting every frame for short segments and every 10 frames (the devkit's step) for
    the devkit's lengths."""
    step = 1 if lengths[0] < 100 else 10
    return devkit.kitti_segment_errors(
        planar_to_se3(jnp.asarray(planar)), planar_to_se3(jnp.asarray(poses)), lengths=lengths, step=step
    )


def _unbatch(outputs, seqs) -> tuple[list, list]:
    """Lists of unbatched outputs and sequences from lists, or from batched pytrees."""
    if isinstance(seqs, Sequence):
        if seqs.frame_times.ndim == 1:
            return [outputs], [seqs]
        count = seqs.frame_times.shape[0]
        take = lambda tree, i: jax.tree_util.tree_map(lambda x: x[i], tree)
        return [take(outputs, i) for i in range(count)], [take(seqs, i) for i in range(count)]
    return list(outputs), list(seqs)


def _optional(value, segments) -> float | None:
    return float(value) if int(segments) else None


def score(
    outputs: BevoOutput | list[BevoOutput], seqs: Sequence | list[Sequence], lengths: tuple[float, ...] = devkit.SEGMENT_LENGTHS
) -> dict:
    """BEVO's odometry scores over one or many sequences (lists, of any lengths, or a batch with a
    leading axis): ``t_err_pct`` and ``r_err_deg_per_100m`` pooled over all segments of
    ``lengths`` metres of all sequences (as the devkit pools a benchmark; ``None`` where no
    sequence is long enough for a segment), ``segments``, ``ate_m`` (position RMS over all
    frames), per-frame ``motion_rmse_m`` and ``yaw_rmse_deg``, and per-sequence lists."""
    outputs, seqs = _unbatch(outputs, seqs)
    if not seqs or len(outputs) != len(seqs):
        raise ValueError(f"score needs as many outputs as sequences (at least one), got {len(outputs)} and {len(seqs)}")
    segments = [segment_errors(o.poses, s.planar, lengths) for o, s in zip(outputs, seqs)]
    pooled = devkit.kitti_errors(segments)
    per_seq = [devkit.kitti_errors(seg) for seg in segments]
    position = [np.sum((np.asarray(o.poses)[:, :2] - np.asarray(s.planar)[:, :2]) ** 2, -1) for o, s in zip(outputs, seqs)]
    motion = [np.asarray(o.increments - relative_motion(s))[1:] for o, s in zip(outputs, seqs)]
    err = np.concatenate(motion)
    return {
        "t_err_pct": _optional(pooled.t_err_pct, pooled.segments),
        "r_err_deg_per_100m": _optional(pooled.r_err_deg_per_100m, pooled.segments),
        "segments": int(pooled.segments),
        "segment_lengths_m": list(lengths),
        "ate_m": float(np.sqrt(np.mean(np.concatenate(position)))),
        "motion_rmse_m": float(np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2))),
        "yaw_rmse_deg": float(np.degrees(np.sqrt(np.mean(np.asarray(wrap_angle(jnp.asarray(err[:, 2]))) ** 2)))),
        "per_sequence": {
            "t_err_pct": [_optional(k.t_err_pct, k.segments) for k in per_seq],
            "r_err_deg_per_100m": [_optional(k.r_err_deg_per_100m, k.segments) for k in per_seq],
            "ate_m": [float(np.sqrt(np.mean(p))) for p in position],
            "segments": [int(k.segments) for k in per_seq],
        },
    }


def criterion(scores: dict) -> float:
    """The number a checkpoint is selected by (lower is better): ``t_err_pct`` where the drives
    hold segments, else ``ate_m``."""
    return scores["t_err_pct"] if scores["segments"] else scores["ate_m"]


def format_scores(scores: dict) -> str:
    """One line of BEVO's odometry scores."""
    if scores["segments"]:
        kitti = f"t_err {scores['t_err_pct']:.3f} %  r_err {scores['r_err_deg_per_100m']:.3f} deg/100m"
    else:
        kitti = f"no segment of {scores['segment_lengths_m'][0]:g} m or more"
    return (
        f"{kitti}  ATE {scores['ate_m']:.3f} m  per-frame motion {100 * scores['motion_rmse_m']:.2f} cm, "
        f"yaw {scores['yaw_rmse_deg']:.3f} deg"
    )


def pose_errors(poses, truth) -> dict:
    """Mean, max and final position error (m), mean yaw error (deg) and the distance driven."""
    poses, truth = np.asarray(poses, float), np.asarray(truth, float)
    pos = np.hypot(*(poses[:, :2] - truth[:, :2]).T)
    yaw = np.abs(np.degrees(np.angle(np.exp(1j * (poses[:, 2] - truth[:, 2])))))
    return {
        "mean_position_error_m": float(pos.mean()),
        "max_position_error_m": float(pos.max()),
        "final_position_error_m": float(pos[-1]),
        "mean_yaw_error_deg": float(yaw.mean()),
        "distance_m": float(np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T))),
    }


__all__ = ["SHORT_SEGMENTS", "criterion", "format_scores", "pose_errors", "score", "segment_errors", "segment_lengths"]
