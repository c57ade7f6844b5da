"""The KITTI odometry devkit's errors (``evaluate_odometry.cpp``), in JAX.

Segment lengths 100, 200, ..., 800 m; a segment starts every 10 frames; distances are accumulated
on the ground truth; the segment's last frame is the first whose distance exceeds
``start + length``; the error of a segment is ``inv(inv(E[f]) E[l]) (inv(G[f]) G[l])``, its
rotation angle from the trace (clamped) and the norm of its translation, each divided by the
length. ``t_err`` is the mean over all segments (of all sequences) in %, ``r_err`` in deg per
100 m. A segment counts only where both its frames are valid (estimates may start late, as in
KITTI evaluation tools that key poses by frame index). Jit-able and vmappable for fixed shapes
(masks instead of ragged selections); use float64 (``jax_enable_x64``) to reproduce published
numbers to 1e-6.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from jbevo.geometry.se3 import general_inverse, rotation_angle, translation_norm

SEGMENT_LENGTHS = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)


SEGMENT_STEP = 10


def trajectory_distances(poses: Float[Array, "N 4 4"]) -> Float[Array, " N"]:
    """Distance travelled along the trajectory up to each frame (0 at frame 0)."""
    steps = jnp.linalg.norm(poses[1:, :3, 3] - poses[:-1, :3, 3], axis=-1)
    return jnp.concatenate([jnp.zeros(1, poses.dtype), jnp.cumsum(steps)])


class SegmentErrors(NamedTuple):
    """Per-segment KITTI errors; ``valid`` marks the segments that exist."""

    first: Array  # (S, L) first frame of each segment
    length: Array  # (S, L) segment length in metres
    t_err: Array  # (S, L) translation error / length (fraction)
    r_err: Array  # (S, L) rotation error / length (rad per metre)
    valid: Array  # (S, L) bool


def kitti_segment_errors(
    gt: Float[Array, "N 4 4"],
    est: Float[Array, "N 4 4"],
    valid: Bool[Array, " N"] | None = None,
    lengths: tuple[float, ...] = SEGMENT_LENGTHS,
    step: int = SEGMENT_STEP,
) -> SegmentErrors:
    """Errors of every (start frame, length) segment of one sequence, as the devkit computes them."""
    n = gt.shape[0]
    if est.shape != gt.shape:
        raise ValueError(f"gt and est must have the same shape (N, 4, 4), got {gt.shape} and {est.shape}")
    valid = jnp.ones(n, bool) if valid is None else jnp.asarray(valid, bool)
    dist = trajectory_distances(gt)
    first = jnp.arange(0, n, step)
    length = jnp.asarray(lengths, gt.dtype)
    # The first frame whose distance exceeds dist[first] + length (dist is non-decreasing).
    last = jnp.searchsorted(dist, dist[first][:, None] + length[None, :], side="right")
    exists = (last < n) & valid[first][:, None] & valid[jnp.minimum(last, n - 1)]
    last = jnp.minimum(last, n - 1)
    f = first[:, None]
    delta_gt = general_inverse(gt[f]) @ gt[last]
    delta_est = general_inverse(est[f]) @ est[last]
    error = general_inverse(delta_est) @ delta_gt
    return SegmentErrors(
        first=jnp.broadcast_to(f, last.shape),
        length=jnp.broadcast_to(length, last.shape),
        t_err=translation_norm(error) / length,
        r_err=rotation_angle(error) / length,
        valid=exists,
    )


class KittiErrors(NamedTuple):
    """The devkit's errors averaged over segments (zero where there is no segment: check
    ``segments``)."""

    t_err_pct: Array  # mean translation error, %
    r_err_deg_per_100m: Array  # mean rotation error, deg / 100 m
    t_err_pct_by_length: Array  # (L,) per segment length
    r_err_deg_per_100m_by_length: Array  # (L,)
    segments: Array  # number of segments averaged
    segments_by_length: Array  # (L,) number of segments of each length


def kitti_errors(segments: list[SegmentErrors] | SegmentErrors) -> KittiErrors:
    """Average segment errors over all segments of all sequences, overall and per length."""
    if isinstance(segments, SegmentErrors):
        segments = [segments]
    cat = SegmentErrors(*[jnp.concatenate([getattr(s, k) for s in segments]) for k in SegmentErrors._fields])
    w = cat.valid.astype(cat.t_err.dtype)
    count = jnp.sum(w)
    safe = jnp.maximum(count, 1.0)
    per_len = jnp.maximum(jnp.sum(w, axis=0), 1.0)
    deg100 = 180.0 / jnp.pi * 100.0
    return KittiErrors(
        t_err_pct=100.0 * jnp.sum(w * cat.t_err) / safe,
        r_err_deg_per_100m=deg100 * jnp.sum(w * cat.r_err) / safe,
        t_err_pct_by_length=100.0 * jnp.sum(w * cat.t_err, axis=0) / per_len,
        r_err_deg_per_100m_by_length=deg100 * jnp.sum(w * cat.r_err, axis=0) / per_len,
        segments=count,
        segments_by_length=jnp.sum(w, axis=0),
    )


__all__ = [
    "SEGMENT_LENGTHS",
    "SEGMENT_STEP",
    "KittiErrors",
    "SegmentErrors",
    "kitti_errors",
    "kitti_segment_errors",
    "trajectory_distances",
]
