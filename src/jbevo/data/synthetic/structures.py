"""Vertical structure beside the road: facades, parked cars, poles and trees, and kerbs, as boxes
standing on the ground, placed along a drive and ray-cast by the renderer.

Every structure is an oriented box: centre ``(x, y)``, heading, half length and half width,
bottom and top height. :func:`place_structures` lines a drive's path with them on both sides
(seeded, from a :class:`~jbevo.data.synthetic.street.Street`'s settings) and drops any box that
comes within ``clearance`` of the path, so the vehicle never drives through one (a loop's second
pass included). :func:`nearest_boxes` keeps, for each frame, the ``k`` boxes nearest the camera
that are not wholly behind it and lie within ``reach``: the renderer casts every pixel's ray
against those (:func:`cast_boxes`). Surfaces: facades carry rows of windows and the ground
tile's noise as plaster; the rest carry the tile's noise in their own shade. A box face's
texture is sampled with the same footprint-filtered lookup as the ground.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float
from scipy.spatial import KDTree

from jbevo.data.synthetic.street import Street
from jbevo.data.synthetic.world import World

#: numpy where boxes are placed and chosen, JAX where they are rendered.
BoxArray = np.ndarray | Array


class Boxes(NamedTuple):
    """``K`` oriented boxes (leading axes may precede ``K``): ``centre`` ``(K, 2)``, ``heading``
    ``(K,)``, ``half`` sizes ``(K, 2)`` (along and across the heading), height range ``z``
    ``(K, 2)`` (bottom, top), ``shade`` (brightness), ``facade`` (1: windows), ``texture_offset``
    ``(K, 2)`` (metres) and ``valid`` (0: an empty slot)."""

    centre: BoxArray
    heading: BoxArray
    half: BoxArray
    z: BoxArray
    shade: BoxArray
    facade: BoxArray
    texture_offset: BoxArray
    valid: BoxArray


def _path(poses: np.ndarray, spacing: float, extend: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arc length, position and heading every ``spacing`` metres along the poses' path, carried
    straight on for ``extend`` metres before its start and after its end (arc length from the
    extension's start)."""
    xy = poses[:, :2, 3]
    yaw = np.unwrap(np.arctan2(poses[:, 1, 0], poses[:, 0, 0]))
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]
    keep = np.r_[True, np.diff(s) > 1e-6]
    s, xy, yaw = s[keep], xy[keep], yaw[keep]
    grid = np.arange(-extend, s[-1] + extend + 1e-9, spacing)
    inside = np.clip(grid, 0.0, s[-1])
    heading = np.interp(inside, s, yaw)
    pos = np.stack([np.interp(inside, s, xy[:, 0]), np.interp(inside, s, xy[:, 1])], -1)
    beyond = grid - inside  # negative before the start, positive after the end
    pos = pos + beyond[:, None] * np.stack([np.cos(heading), np.sin(heading)], -1)
    return grid + extend, pos, heading


def place_structures(poses: np.ndarray, street: Street, seed: int, clearance: float = 1.2) -> Boxes:
    """Boxes along the path of ``poses`` (``T_world_body``, numpy) on both sides (numpy arrays)."""
    rng = np.random.default_rng([seed, 5])
    s, pos, heading = _path(np.asarray(poses, float), 0.5, 50.0)
    length = s[-1]
    rows: list[tuple] = []  # (cx, cy, heading, half_l, half_w, z0, z1, shade, facade)

    def at(distance: float, side: int, offset: float):
        i = min(int(round(distance / 0.5)), len(s) - 1)
        h = heading[i]
        normal = np.array([-np.sin(h), np.cos(h)]) * side
        return pos[i] + offset * normal, h

    for side in (1, -1):
        if street.facades:
            d = 0.0
            while d < length:
                seg = rng.uniform(8.0, 18.0)
                if rng.random() >= street.facade_gap:
                    depth = 4.0
                    c, h = at(d + seg / 2, side, rng.uniform(*street.facade_offset) + depth / 2)
                    rows.append(
                        (*c, h, seg / 2, depth / 2, 0.0, rng.uniform(*street.facade_height), rng.uniform(0.35, 0.75), 1.0)
                    )
                d += seg
        d = rng.uniform(0, 6.5)
        while d < length:
            if rng.random() < street.parked_car_probability:
                c, h = at(d, side, rng.uniform(*street.parked_car_offset))
                h = h + np.radians(rng.normal(0, 3))
                rows.append((*c, h, rng.uniform(2.0, 2.3), 0.9, 0.15, rng.uniform(1.35, 1.55), rng.uniform(0.08, 0.9), 0.0))
            d += 6.5
        d = rng.exponential(1 / street.poles_per_metre) if street.poles_per_metre > 0 else np.inf
        while d < length:
            c, h = at(d, side, rng.uniform(*street.pole_offset))
            if rng.random() < 0.5:  # a pole
                rows.append((*c, h, 0.12, 0.12, 0.0, rng.uniform(4.0, 8.0), rng.uniform(0.2, 0.6), 0.0))
            else:  # a tree: trunk and crown
                rows.append((*c, h, 0.2, 0.2, 0.0, 3.0, rng.uniform(0.15, 0.35), 0.0))
                rows.append((*c, h, 1.6, 1.6, 2.8, rng.uniform(5.0, 7.0), rng.uniform(0.15, 0.4), 0.0))
            d += rng.exponential(1 / street.poles_per_metre)
        if street.kerb_height > 0:
            for d in np.arange(4.0, length, 8.0):
                c, h = at(d, side, street.kerb_offset)
                rows.append((*c, h, 4.05, 0.1, 0.0, street.kerb_height, 0.62, 0.0))
    if not rows:
        return _empty(0)
    a = np.array(rows, float)
    # Drop any box within ``clearance`` of the path (curves, loops, the other side of a turn).
    tree = KDTree(pos)
    keep = np.ones(len(a), bool)
    for i, (cx, cy, h, hl, hw) in enumerate(a[:, :5]):
        near = tree.query_ball_point((cx, cy), np.hypot(hl, hw) + clearance)
        if near:
            rel = pos[near] - (cx, cy)
            u = rel[:, 0] * np.cos(h) + rel[:, 1] * np.sin(h)
            v = -rel[:, 0] * np.sin(h) + rel[:, 1] * np.cos(h)
            keep[i] = not np.any((np.abs(u) < hl + clearance) & (np.abs(v) < hw + clearance))
    a = a[keep]
    n = len(a)
    return Boxes(
        centre=a[:, :2],
        heading=a[:, 2],
        half=a[:, 3:5],
        z=a[:, 5:7],
        shade=a[:, 7],
        facade=a[:, 8],
        texture_offset=rng.uniform(0, 80, (n, 2)),
        valid=np.ones(n),
    )


def _empty(k: int) -> Boxes:
    z = np.zeros
    return Boxes(z((k, 2)), z(k), z((k, 2)), z((k, 2)), z(k), z(k), z((k, 2)), z(k))


def nearest_boxes(boxes: Boxes, poses: np.ndarray, half_fov: float = np.pi / 2, k: int = 32, reach: float = 40.0) -> Boxes:
    """For each pose (``T``), the ``k`` boxes nearest the camera within ``reach`` metres that some
    ray within ``half_fov`` radians of the heading may meet (a box whose corners all lie behind
    the camera, or all beyond one edge of that wedge, is culled), padded with invalid boxes: a :class:`Boxes` with arrays
    ``(T, k, ...)`` (float32)."""
    poses = np.asarray(poses, float)
    t = len(poses)
    if len(boxes.heading) == 0:
        return Boxes(*(np.broadcast_to(x, (t, k, *x.shape[1:])).astype(np.float32) for x in _empty(1)))
    cam = poses[:, None, :2, 3]
    yaw = np.arctan2(poses[:, 1, 0], poses[:, 0, 0])[:, None]
    rel = cam - boxes.centre[None]
    c, s = np.cos(boxes.heading)[None], np.sin(boxes.heading)[None]
    u = np.abs(rel[..., 0] * c + rel[..., 1] * s) - boxes.half[None, :, 0]
    v = np.abs(-rel[..., 0] * s + rel[..., 1] * c) - boxes.half[None, :, 1]
    distance = np.hypot(np.maximum(u, 0), np.maximum(v, 0))
    # Each corner's bearing from the camera against the heading, and whether it is behind.
    bearings, behind = [], []
    forward = np.stack([np.cos(yaw), np.sin(yaw)], -1)  # (T, 1, 2)
    for su, sv in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
        corner = boxes.centre + np.stack(
            [
                su * boxes.half[:, 0] * np.cos(boxes.heading) - sv * boxes.half[:, 1] * np.sin(boxes.heading),
                su * boxes.half[:, 0] * np.sin(boxes.heading) + sv * boxes.half[:, 1] * np.cos(boxes.heading),
            ],
            -1,
        )
        offset = corner[None] - cam
        bearings.append(np.angle(np.exp(1j * (np.arctan2(offset[..., 1], offset[..., 0]) - yaw))))
        behind.append(np.sum(offset * forward, -1) <= 0)
    bearing = np.stack(bearings)
    outside = np.all(behind, 0) | np.all(bearing > half_fov, 0) | np.all(bearing < -half_fov, 0)
    distance = np.where(~outside & (distance < reach), distance, np.inf)
    order = np.argsort(distance, axis=1)[:, :k]
    chosen = np.take_along_axis(distance, order, 1)
    out = [np.asarray(x)[order] for x in boxes]
    valid = np.isfinite(chosen).astype(float)
    if order.shape[1] < k:  # fewer boxes than slots
        pad = k - order.shape[1]
        out = [np.concatenate([x, np.zeros((t, pad, *x.shape[2:]))], 1) for x in out]
        valid = np.concatenate([valid, np.zeros((t, pad))], 1)
    chosen_boxes = Boxes(*out)._replace(valid=valid)
    return Boxes(*(x.astype(np.float32) for x in chosen_boxes))


def _slab(o, inv_d, lo, hi):
    """Entry and exit ray parameters of the slab ``lo <= o + t d <= hi`` (``inv_d`` = 1 / d)."""
    t1, t2 = (lo - o) * inv_d, (hi - o) * inv_d
    return jnp.minimum(t1, t2), jnp.maximum(t1, t2)


def _reciprocal(x):
    return 1.0 / jnp.where(jnp.abs(x) < 1e-9, 1e-9, x)


def cast_boxes(
    world: World, boxes: Boxes, origin: Float[Array, " 3"], d: Float[Array, "3 H W"], pixel_angle: Float[Array, ""] | float
) -> tuple[Float[Array, "H W"], Float[Array, "H W"]]:
    """The ray parameter of the nearest box each pixel's ray ``origin + t d`` meets (``inf`` where
    none) and the surface brightness there (texture filtered for a pixel of ``pixel_angle``
    radians)."""
    dtype = d.dtype
    inv_dz = _reciprocal(d[2])  # the same for every box

    def one(carry, box):
        best, index, axis, i = carry
        centre, heading, half, z, valid = box
        c, s = jnp.cos(heading), jnp.sin(heading)
        ox, oy = origin[0] - centre[0], origin[1] - centre[1]
        lu, lv = c * ox + s * oy, -s * ox + c * oy
        a0, b0 = _slab(lu, _reciprocal(c * d[0] + s * d[1]), -half[0], half[0])
        a1, b1 = _slab(lv, _reciprocal(c * d[1] - s * d[0]), -half[1], half[1])
        a2, b2 = _slab(origin[2], inv_dz, z[0], z[1])
        enter = jnp.maximum(jnp.maximum(a0, a1), a2)
        leave = jnp.minimum(jnp.minimum(b0, b1), b2)
        hit = (enter <= leave) & (enter > 0) & (valid > 0) & (enter < best)
        face = jnp.where(a2 >= jnp.maximum(a0, a1), 2, jnp.where(a1 >= a0, 1, 0))
        return (jnp.where(hit, enter, best), jnp.where(hit, i, index), jnp.where(hit, face, axis), i + 1), None

    shape = d.shape[1:]
    init = (jnp.full(shape, jnp.inf, dtype), jnp.zeros(shape, jnp.int32), jnp.zeros(shape, jnp.int32), jnp.int32(0))
    (best, index, face, _), _ = jax.lax.scan(one, init, (boxes.centre, boxes.heading, boxes.half, boxes.z, boxes.valid))
    hit = jnp.isfinite(best)
    t = jnp.where(hit, best, 0.0)
    take = lambda x: x[index]
    centre, heading = take(boxes.centre), take(boxes.heading)
    c, s = jnp.cos(heading), jnp.sin(heading)
    px, py, pz = origin[0] + t * d[0] - centre[..., 0], origin[1] + t * d[1] - centre[..., 1], origin[2] + t * d[2]
    lu, lv = c * px + s * py, -s * px + c * py
    # Face coordinates: along the face and up it (the roof: both horizontal axes).
    across = jnp.where(face == 0, lv, lu)
    up = jnp.where(face == 2, lv, pz)
    distance = t * jnp.sqrt(jnp.sum(d**2, axis=0))
    footprint = jnp.maximum(distance * pixel_angle, 1e-3)
    offset = take(boxes.texture_offset)
    plaster = world.sample(across + offset[..., 0], up + offset[..., 1], footprint)
    shade = take(boxes.shade)
    value = shade * (0.55 + 0.9 * plaster)
    # Windows: 1.4 m x 1.6 m every 3 m along and up, from 1 m; edges as wide as a pixel's footprint.
    edge = jnp.maximum(footprint, 0.05)
    wu = jnp.abs(jnp.mod(across, 3.0) - 1.5)
    wz = jnp.abs(jnp.mod(pz - 1.0, 3.0) - 1.5)
    window = jnp.clip((0.7 - wu) / edge + 0.5, 0, 1) * jnp.clip((0.8 - wz) / edge + 0.5, 0, 1) * (pz > 1.0)
    value = jnp.where(take(boxes.facade) > 0, value * (1 - 0.55 * window) + 0.1 * window * plaster, value)
    value = value * jnp.where(face == 0, 0.8, jnp.where(face == 2, 1.15, 1.0))
    return best, jnp.clip(value, 0.0, 1.0).astype(dtype)


__all__ = ["Boxes", "cast_boxes", "nearest_boxes", "place_structures"]
