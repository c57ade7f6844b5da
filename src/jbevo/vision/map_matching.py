"""Matching a BEV against a top-down map: the map resampled as a BEV at a pose would see it, and a
DPC registration of the two into a pose fix and a measurement of the BEV's pitch error.

The map's pixel ``(row, col)`` is world ``x = x_max - row * resolution``,
``y = y_max - col * resolution`` (:class:`jbevo.data.map.Map`): its axes are those of a BEV at
yaw 0.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from jbevo.data.map import Map
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.se2 import se2_compose
from jbevo.vision.bands import band_moments, register_bands
from jbevo.vision.bev import bev_increment, feather_to_mean
from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.registration import register


def map_crop(map_: Map, pose: Float[Array, " 3"], grid: BevGrid) -> tuple[Float[Array, "h w"], Bool[Array, "h w"]]:
    """The map resampled on ``grid`` as a BEV taken at ``pose`` ``(x, y, yaw)`` would see it:
    ``(crop, inside)``, intensities in [0, 1] (bilinear; 0 off the map) and the mask of pixels
    whose ground point lies inside the map. Differentiable in ``pose``; the map's 8-bit image is
    only gathered at the four neighbours of each pixel (never converted whole)."""
    dtype = pose.dtype
    ground = grid.ground_points().astype(dtype)  # level frame: x forward, y left
    c, s = jnp.cos(pose[2]), jnp.sin(pose[2])
    wx = pose[0] + c * ground[..., 0] - s * ground[..., 1]
    wy = pose[1] + s * ground[..., 0] + c * ground[..., 1]
    resolution = jnp.asarray(map_.resolution, dtype)
    row = (jnp.asarray(map_.x_max, dtype) - wx) / resolution
    col = (jnp.asarray(map_.y_max, dtype) - wy) / resolution
    rows, cols = map_.image.shape
    inside = (row >= 0) & (row <= rows - 1) & (col >= 0) & (col <= cols - 1)
    row, col = jnp.clip(row, 0, rows - 1), jnp.clip(col, 0, cols - 1)
    r0 = jnp.clip(jnp.floor(jax.lax.stop_gradient(row)), 0, rows - 2).astype(jnp.int32)
    c0 = jnp.clip(jnp.floor(jax.lax.stop_gradient(col)), 0, cols - 2).astype(jnp.int32)
    fr, fc = row - r0, col - c0
    tap = lambda dr, dc: map_.image[r0 + dr, c0 + dc].astype(dtype)
    top = tap(0, 0) + fc * (tap(0, 1) - tap(0, 0))
    bottom = tap(1, 0) + fc * (tap(1, 1) - tap(1, 0))
    crop = (top + fr * (bottom - top)) * (1.0 / 255.0)
    return jnp.where(inside, crop, 0.0), inside


class MapMatch(NamedTuple):
    """One map-matching measurement."""

    fix: Float[Array, " 3"]  #: the pose (x, y, yaw) the match says the BEV was taken at
    confidence: Float[Array, ""]  #: DPC confidence times the fraction of the crop on the map
    pitch_error: Float[Array, ""]  #: the BEV's pitch minus the true pitch (radians)


def match_to_map(
    bev: Float[Array, "h w"],
    valid: Bool[Array, "h w"],
    map_: Map,
    pose: Float[Array, " 3"],
    grid: BevGrid,
    params: DPCParams,
    height: Float[Array, ""],
    pitch_gain: Float[Array, ""] | float = 1.0,
    feather: int = 2,
) -> MapMatch:
    """Match a BEV (on ``grid``, ``valid`` its camera-view mask, camera ``height`` metres above
    the ground) against the map at ``pose``.

    1. The crop at ``pose`` and the BEV, both limited to the pixels valid in both (the rest fade
       to the mean over ``feather`` pixels, so the common edge does not pull DPC toward zero
       shift), are registered by DPC: the first fix ``pose (+) bev_increment(...)``.
    2. A BEV projected with a pitch error ``d`` (its pitch minus the true one) puts a ground
       point ``x`` metres ahead ``d (x^2 + h^2) / h`` too far: the first fix's forward position
       is biased by ~1 m per degree. The crop at the first fix is registered again, translation
       only, on the far and the near half of the grid; the difference of their forward shifts
       measures ``d`` (80 m per radian on the default grid; times ``pitch_gain``, which
       calibrates the model: the soft-argmax sees the band's spread of scales, and measures
       about 0.75 of it), and extrapolating the near half's shift to the camera removes the bias
       from the fix.
    """
    crop, inside = map_crop(map_, pose, grid)
    both = valid & inside
    bev_w = feather_to_mean(bev, both, feather)
    reg = register(feather_to_mean(crop, both, feather), bev_w, params)
    first = se2_compose(pose, bev_increment(grid, reg.rotation, reg.translation))
    covered = jnp.sum(both) / jnp.maximum(jnp.sum(valid), 1)

    crop2, inside2 = map_crop(map_, first, grid)
    both2 = valid & inside2
    crop_w = feather_to_mean(crop2, both2, feather)
    bev_w = feather_to_mean(bev, both2, feather)
    shift, band_conf = register_bands(crop_w, bev_w, params)
    forward = grid.resolution * shift[:, 1]  # rows run backwards along x: +1 row shift = +resolution forward
    lateral = grid.resolution * shift[:, 0]
    far_m2, near_m2 = band_moments(grid, params.window_taper, 2)
    h = jnp.asarray(height, forward.dtype)
    pitch_error = pitch_gain * (forward[0] - forward[1]) * h / (far_m2 - near_m2)
    residual = jnp.stack([forward[1] - pitch_error * (near_m2 + h**2) / h, 0.5 * (lateral[0] + lateral[1]), 0.0 * h])
    confidence = reg.confidence * covered * jnp.sqrt(band_conf[0] * band_conf[1] + 1e-12)
    return MapMatch(se2_compose(first, residual), confidence, pitch_error)


__all__ = ["MapMatch", "map_crop", "match_to_map"]
