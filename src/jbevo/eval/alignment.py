"""Aligning an estimated trajectory to its ground truth: Umeyama's least-squares similarity, and
the ``none``, ``se3``, ``sim3`` and ``4dof`` (rotation about gravity plus translation, for VIO)
alignments."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

ALIGNMENTS = ("none", "se3", "sim3", "4dof")


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


__all__ = ["ALIGNMENTS", "Alignment", "align", "apply_alignment", "umeyama"]
