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

Command line: ``python -m jbevo.metrics --gt GT.txt --est EST.txt [--align sim3] [--json out.json]
[--plot out.png]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

SEGMENT_LENGTHS = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
SEGMENT_STEP = 10
ALIGNMENTS = ("none", "se3", "sim3", "4dof")


# ----------------------------------------------------------------------------- SE(3) helpers


def general_inverse(pose: Float[Array, "... 4 4"]) -> Float[Array, "... 4 4"]:
    """``inv`` of any 4x4 (what the devkit uses: estimates need not be exactly orthonormal)."""
    return jnp.linalg.inv(pose)


def rotation_angle(pose: Float[Array, "... 4 4"]) -> Float[Array, "..."]:
    """The devkit's rotation error: ``acos(clip((trace(R) - 1) / 2, -1, 1))`` in radians."""
    d = 0.5 * (pose[..., 0, 0] + pose[..., 1, 1] + pose[..., 2, 2] - 1.0)
    return jnp.arccos(jnp.clip(d, -1.0, 1.0))


def translation_norm(pose: Float[Array, "... 4 4"]) -> Float[Array, "..."]:
    return jnp.linalg.norm(pose[..., :3, 3], axis=-1)


def relative_to_first(poses: Float[Array, "N 4 4"], first: int | Array) -> Float[Array, "N 4 4"]:
    """``inv(P[first]) P``: the trajectory expressed in the frame of its pose ``first``."""
    return general_inverse(poses[first]) @ poses


def planar_to_se3(xy_yaw: Float[Array, "N 3"]) -> Float[Array, "N 4 4"]:
    """Lift ``(x, y, yaw)`` rows (world z up) to 4x4 poses with ``z = 0``."""
    x, y, yaw = xy_yaw[..., 0], xy_yaw[..., 1], xy_yaw[..., 2]
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    zero, one = jnp.zeros_like(x), jnp.ones_like(x)
    rows = [
        [c, -s, zero, x],
        [s, c, zero, y],
        [zero, zero, one, zero],
        [zero, zero, zero, one],
    ]
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def se3_to_planar(poses: Float[Array, "N 4 4"]) -> Float[Array, "N 3"]:
    """``(x, y, yaw)`` of poses in a z-up world (yaw of the x axis about z)."""
    return jnp.stack([poses[..., 0, 3], poses[..., 1, 3], jnp.arctan2(poses[..., 1, 0], poses[..., 0, 0])], -1)


# ----------------------------------------------------------------------------- alignment


class Alignment(NamedTuple):
    """``x -> scale * rotation @ x + translation`` maps estimate positions onto ground truth."""

    rotation: Float[Array, "3 3"]
    translation: Float[Array, " 3"]
    scale: Float[Array, ""]


def umeyama(
    est: Float[Array, "N D"], gt: Float[Array, "N D"], with_scale: bool, weights: Float[Array, " N"] | None = None
) -> tuple[Array, Array, Array]:
    """Least-squares similarity (Umeyama 1991) taking ``est`` points onto ``gt`` points.

    Returns ``(R, t, s)`` with ``gt ~ s R est + t``; ``weights`` (0/1 masks included) select points.
    """
    n = est.shape[0]
    w = jnp.ones(n, est.dtype) if weights is None else weights.astype(est.dtype)
    w = w / jnp.sum(w)
    mu_e = w @ est
    mu_g = w @ gt
    de, dg = est - mu_e, gt - mu_g
    cov = (dg * w[:, None]).T @ de
    u, d, vt = jnp.linalg.svd(cov)
    sign = jnp.sign(jnp.linalg.det(u) * jnp.linalg.det(vt))
    sign = jnp.where(sign == 0, 1.0, sign)
    fix = jnp.ones(est.shape[1], est.dtype).at[-1].set(sign)
    r = (u * fix) @ vt
    var_e = jnp.sum(w * jnp.sum(de**2, axis=1))
    s = jnp.sum(d * fix) / var_e if with_scale else jnp.asarray(1.0, est.dtype)
    t = mu_g - s * r @ mu_e
    return r, t, s


def align(
    est_xyz: Float[Array, "N 3"],
    gt_xyz: Float[Array, "N 3"],
    kind: str,
    valid: Bool[Array, " N"] | None = None,
    up_axis: int = 1,
) -> Alignment:
    """Alignment of estimated onto ground-truth positions.

    ``kind``: ``none``; ``se3`` (rotation, translation); ``sim3`` (plus scale); ``4dof`` (rotation
    about ``up_axis`` only, plus translation; ``up_axis=1`` is KITTI camera 0's y axis, which points
    down along gravity, ``2`` a z-up world).
    """
    dtype = est_xyz.dtype
    if kind not in ALIGNMENTS:
        raise ValueError(f"alignment must be one of {ALIGNMENTS}, got {kind!r}")
    if kind == "none":
        return Alignment(jnp.eye(3, dtype=dtype), jnp.zeros(3, dtype), jnp.asarray(1.0, dtype))
    w = None if valid is None else valid.astype(dtype)
    if kind in ("se3", "sim3"):
        r, t, s = umeyama(est_xyz, gt_xyz, kind == "sim3", w)
        return Alignment(r, t, s)
    plane = [i for i in range(3) if i != up_axis]
    r2, _, _ = umeyama(est_xyz[:, plane], gt_xyz[:, plane], False, w)
    r = jnp.eye(3, dtype=dtype)
    r = r.at[plane[0], plane[0]].set(r2[0, 0]).at[plane[0], plane[1]].set(r2[0, 1])
    r = r.at[plane[1], plane[0]].set(r2[1, 0]).at[plane[1], plane[1]].set(r2[1, 1])
    ww = jnp.ones(est_xyz.shape[0], dtype) if w is None else w
    ww = ww / jnp.sum(ww)
    t = ww @ gt_xyz - r @ (ww @ est_xyz)
    return Alignment(r, t, jnp.asarray(1.0, dtype))


def apply_alignment(poses: Float[Array, "N 4 4"], alignment: Alignment) -> Float[Array, "N 4 4"]:
    """Scale the positions, then rotate and translate the poses (as the KITTI evaluation tools
    do for 7-DoF alignment): ``A @ [R, s t]``."""
    scaled = poses.at[:, :3, 3].multiply(alignment.scale)
    a = jnp.eye(4, dtype=poses.dtype).at[:3, :3].set(alignment.rotation).at[:3, 3].set(alignment.translation)
    return a @ scaled


# ----------------------------------------------------------------------------- KITTI devkit


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
    t_err_pct: Array  # mean translation error, %
    r_err_deg_per_100m: Array  # mean rotation error, deg / 100 m
    t_err_pct_by_length: Array  # (L,) per segment length
    r_err_deg_per_100m_by_length: Array  # (L,)
    segments: Array  # number of segments averaged


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
    )


# ----------------------------------------------------------------------------- ATE and RPE


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


# ----------------------------------------------------------------------------- one call


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
    """The headline numbers as plain floats (the keys of ``--json``)."""
    return {
        "t_err_pct": float(ev.kitti.t_err_pct),
        "r_err_deg_per_100m": float(ev.kitti.r_err_deg_per_100m),
        "ate_m": float(ev.ate_m),
        "rpe_trans_m": float(ev.rpe.trans_m),
        "rpe_rot_deg": float(ev.rpe.rot_deg),
        "segments": int(ev.kitti.segments),
        "t_err_pct_by_length": {f"{int(l)}": float(v) for l, v in zip(SEGMENT_LENGTHS, ev.kitti.t_err_pct_by_length)},
        "r_err_deg_per_100m_by_length": {
            f"{int(l)}": float(v) for l, v in zip(SEGMENT_LENGTHS, ev.kitti.r_err_deg_per_100m_by_length)
        },
    }


# ----------------------------------------------------------------------------- command line


def main(argv: list[str] | None = None) -> int:
    jax.config.update("jax_enable_x64", True)
    from jbevo import trajectory_io
    from jbevo.files import write_json_atomic

    parser = argparse.ArgumentParser(
        prog="python -m jbevo.metrics",
        description="KITTI devkit t_err/r_err, ATE and RPE of an estimated trajectory (KITTI or TUM pose files).",
    )
    parser.add_argument("--gt", type=Path, required=True, help="ground-truth poses (KITTI 12/13 columns or TUM)")
    parser.add_argument("--est", type=Path, required=True, help="estimated poses (same formats)")
    parser.add_argument("--align", choices=["sim3", "se3", "4dof", "se2", "none"], default="none",
                        help="alignment of the estimate before the metrics (se2 = 4dof about the gravity axis)")
    parser.add_argument("--up-axis", type=int, default=1, help="gravity axis for 4dof/se2: 1 = KITTI camera y (default), 2 = z-up")
    parser.add_argument("--rpe-delta", type=float, default=1.0)
    parser.add_argument("--rpe-unit", choices=["frames", "m"], default="frames")
    parser.add_argument("--json", type=Path, help="write the numbers to this JSON file")
    parser.add_argument("--plot", type=Path, help="write a top-view PNG of both trajectories")
    args = parser.parse_args(argv)

    try:
        gt_traj = trajectory_io.read_poses(args.gt)
        est_traj = trajectory_io.read_poses(args.est)
        gt, est, valid = trajectory_io.match_frames(gt_traj, est_traj)
    except (OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    kind = "4dof" if args.align == "se2" else args.align
    ev = evaluate(jnp.asarray(gt), jnp.asarray(est), jnp.asarray(valid), kind, args.up_axis, args.rpe_delta, args.rpe_unit)
    numbers = summary(ev)
    numbers["alignment"] = args.align
    print(f"t_err  {numbers['t_err_pct']:.6f} %   ({numbers['segments']} segments)")
    print(f"r_err  {numbers['r_err_deg_per_100m']:.6f} deg/100m")
    print(f"ATE    {numbers['ate_m']:.6f} m   (alignment: {args.align})")
    print(f"RPE    {numbers['rpe_trans_m']:.6f} m, {numbers['rpe_rot_deg']:.6f} deg   "
          f"(delta {args.rpe_delta:g} {args.rpe_unit})")
    if args.json:
        write_json_atomic(args.json, numbers)
    if args.plot:
        from jbevo import plots

        v = valid.astype(bool)
        plots.trajectory_top_view(
            args.plot, ev.gt[v], {args.est.stem: ev.aligned[v]}, plane=(0, 2) if args.up_axis == 1 else (0, 1)
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
