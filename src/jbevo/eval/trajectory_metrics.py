"""Trajectory metrics: the KITTI odometry devkit errors, ATE, RPE and Umeyama alignment.

Poses are ``(N, 4, 4)`` homogeneous transforms (``T_world_frame``); planar trajectories
``(N, 3)`` rows of ``(x, y, yaw)`` are lifted with :func:`planar_to_se3`. Every function is
JAX (jit-able and vmappable for fixed shapes; masks instead of ragged selections); use float64
(``jax_enable_x64``) to reproduce published numbers to 1e-6.

**KITTI devkit** (``evaluate_odometry.cpp``): segment lengths 100, 200, ..., 800 m; a segment
starts every 10 frames; distances are accumulated on the ground truth; the segment's last frame is
the first whose distance exceeds ``start + length``; the error of a segment is
``inv(inv(E[f]) E[l]) (inv(G[f]) G[l])``, its rotation angle from the trace (clamped) and the norm
of its translation, each divided by the length. ``t_err`` is the mean over all segments (of all
sequences) in %, ``r_err`` in deg per 100 m. A segment counts only where both its frames are
valid (estimates may start late, as in KITTI evaluation tools that key poses by frame index).

**ATE**: RMSE of positions after an alignment (``none``, ``se3``, ``sim3`` by Umeyama, or
``4dof``: rotation about the gravity axis plus translation, for VIO).

**RPE**: relative pose error between frame pairs chosen on the ground truth, by a frame delta
(``i -> i + delta``) or a distance delta (``i -> first j`` whose ground-truth distance from
``i`` exceeds ``delta`` metres): mean translation norm (m) and rotation angle (deg) of
``inv(G[i]^-1 G[j]) (E[i]^-1 E[j])``.

Command line: ``python -m jbevo.metrics`` (:mod:`jbevo.cli.metrics`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from jbevo.eval.alignment import align, apply_alignment
from jbevo.eval.devkit import (
    SEGMENT_LENGTHS,
    KittiErrors,
    SegmentErrors,
    kitti_errors,
    kitti_segment_errors,
    trajectory_distances,
)
from jbevo.geometry.se3 import general_inverse, relative_to_first, rotation_angle, translation_norm


def ate(gt: Float[Array, "N 4 4"], est: Float[Array, "N 4 4"], valid: Bool[Array, " N"] | None = None) -> Array:
    """Position RMSE over the valid frames (align first with :func:`align`)."""
    err = jnp.sum((gt[:, :3, 3] - est[:, :3, 3]) ** 2, axis=-1)
    w = jnp.ones(err.shape, err.dtype) if valid is None else jnp.asarray(valid, err.dtype)
    return jnp.sqrt(jnp.sum(w * err) / jnp.maximum(jnp.sum(w), 1.0))


class RelativePoseError(NamedTuple):
    trans_m: Array  # mean translation error of the pairs, metres
    rot_deg: Array  # mean rotation error of the pairs, degrees
    trans_rmse_m: Array
    pairs: Array  # number of pairs


def rpe(
    gt: Float[Array, "N 4 4"],
    est: Float[Array, "N 4 4"],
    delta: float = 1,
    unit: str = "frames",
    valid: Bool[Array, " N"] | None = None,
) -> RelativePoseError:
    """Relative pose error over pairs ``(i, j)`` chosen on the ground truth.

    ``unit="frames"``: ``j = i + delta``. ``unit="m"``: ``j`` is the first frame whose
    ground-truth distance from ``i`` exceeds ``delta`` metres. Pairs need both frames valid.
    """
    n = gt.shape[0]
    valid = jnp.ones(n, bool) if valid is None else jnp.asarray(valid, bool)
    i = jnp.arange(n)
    if unit == "frames":
        if int(delta) != delta or delta < 1:
            raise ValueError(f"a frame delta must be a positive integer, got {delta}")
        j = i + int(delta)
    elif unit == "m":
        dist = trajectory_distances(gt)
        j = jnp.searchsorted(dist, dist + delta, side="right")
    else:
        raise ValueError(f"unit must be 'frames' or 'm', got {unit!r}")
    ok = (j < n) & valid & valid[jnp.minimum(j, n - 1)]
    j = jnp.minimum(j, n - 1)
    rel_gt = general_inverse(gt) @ gt[j]
    rel_est = general_inverse(est) @ est[j]
    err = general_inverse(rel_gt) @ rel_est
    w = ok.astype(gt.dtype)
    count = jnp.maximum(jnp.sum(w), 1.0)
    t = translation_norm(err)
    return RelativePoseError(
        trans_m=jnp.sum(w * t) / count,
        rot_deg=jnp.degrees(jnp.sum(w * rotation_angle(err)) / count),
        trans_rmse_m=jnp.sqrt(jnp.sum(w * t**2) / count),
        pairs=jnp.sum(w),
    )


class Evaluation(NamedTuple):
    segments: SegmentErrors  # per segment, before pooling (what evaluate_batch pools)
    kitti: KittiErrors
    ate_m: Array
    rpe: RelativePoseError
    aligned: Array  # (N, 4, 4) the estimate after expressing relative to the first valid frame and aligning
    gt: Array  # (N, 4, 4) the ground truth relative to the first valid frame


def evaluate(
    gt: Float[Array, "N 4 4"],
    est: Float[Array, "N 4 4"],
    valid: Bool[Array, " N"] | None = None,
    alignment: str = "none",
    up_axis: int = 1,
    rpe_delta: float = 1,
    rpe_unit: str = "frames",
) -> Evaluation:
    """Express both trajectories relative to their first common (valid) frame, align the
    estimate (``none``, ``se3``, ``sim3``, ``4dof``), then the KITTI errors, ATE and RPE.

    Reproduces the KITTI evaluation tools that key poses by frame index (an estimate that starts at
    frame 2 is compared from frame 2 on). Jit it with ``alignment``, ``rpe_unit`` static.
    """
    n = gt.shape[0]
    valid = jnp.ones(n, bool) if valid is None else jnp.asarray(valid, bool)
    first = jnp.argmax(valid)
    gt_rel = relative_to_first(gt, first)
    est_rel = relative_to_first(est, first)
    a = align(est_rel[:, :3, 3], gt_rel[:, :3, 3], alignment, valid, up_axis)
    est_aligned = apply_alignment(est_rel, a)
    seg = kitti_segment_errors(gt_rel, est_aligned, valid)
    return Evaluation(
        segments=seg,
        kitti=kitti_errors(seg),
        ate_m=ate(gt_rel, est_aligned, valid),
        rpe=rpe(gt_rel, est_aligned, rpe_delta, rpe_unit, valid),
        aligned=est_aligned,
        gt=gt_rel,
    )


def evaluate_batch(
    gt: Float[Array, "B N 4 4"],
    est: Float[Array, "B N 4 4"],
    valid: Bool[Array, "B N"] | None = None,
    alignment: str = "none",
    up_axis: int = 1,
) -> tuple[KittiErrors, Array]:
    """Many equal-length sequences at once (vmapped): the KITTI errors pooled over all segments of
    all sequences, as the devkit reports a set of sequences, and the ATE of each sequence."""
    if valid is None:
        valid = jnp.ones(gt.shape[:2], bool)

    def one(g, e, v):
        ev = evaluate(g, e, v, alignment, up_axis)
        return ev.segments, ev.ate_m

    seg, ates = jax.vmap(one)(gt, est, valid)
    flat = SegmentErrors(*[x.reshape((-1,) + x.shape[2:]) for x in seg])
    return kitti_errors(flat), ates


def summary(ev: Evaluation) -> dict:
    """The headline numbers as plain floats (the keys of ``python -m jbevo.metrics --json``);
    ``None`` for the devkit errors where the drive holds no segment (of any, or of that length)."""

    def value(v, count):
        return float(v) if int(count) else None

    kitti = ev.kitti
    return {
        "t_err_pct": value(kitti.t_err_pct, kitti.segments),
        "r_err_deg_per_100m": value(kitti.r_err_deg_per_100m, kitti.segments),
        "ate_m": float(ev.ate_m),
        "rpe_trans_m": float(ev.rpe.trans_m),
        "rpe_rot_deg": float(ev.rpe.rot_deg),
        "segments": int(kitti.segments),
        "t_err_pct_by_length": {
            f"{int(length)}": value(v, n)
            for length, v, n in zip(SEGMENT_LENGTHS, kitti.t_err_pct_by_length, kitti.segments_by_length)
        },
        "r_err_deg_per_100m_by_length": {
            f"{int(length)}": value(v, n)
            for length, v, n in zip(SEGMENT_LENGTHS, kitti.r_err_deg_per_100m_by_length, kitti.segments_by_length)
        },
    }


__all__ = ["Evaluation", "RelativePoseError", "ate", "evaluate", "evaluate_batch", "rpe", "summary"]
