"""Imaging conditions for the localization experiments: day, night, fog, rain, and dynamic
obstacles drawn over the rendered ground.

A :class:`Condition` changes the renderer's haze and wet sheen and then the exposure (gain,
gamma, contrast) and sensor noise; ``obstacles`` moving vehicles and pedestrians are boxes in the
world (their own texture), projected into each frame and drawn on top of the ground (they
occlude it; the ground never occludes them). Images leave as 8-bit, as a camera gives them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from jbevo.data.synthetic.render import HAZE_DISTANCE, SKY_HORIZON
from jbevo.geometry.camera import Camera


@dataclass(frozen=True)
class Condition:
    """Appearance of one recording: ``gain`` and ``gamma`` (``I' = gain * I^gamma``), contrast about
    mid-grey, sensor ``noise`` (std, in [0, 1] units), ``haze_distance`` and ``sheen`` of the
    renderer, and the number of moving ``obstacles``."""

    name: str = "day"
    gain: float = 1.0
    gamma: float = 1.0
    contrast: float = 1.0
    noise: float = 0.004
    haze_distance: float = HAZE_DISTANCE
    sheen: float = 0.0
    obstacles: int = 0


CONDITIONS = {
    "day": Condition(),
    "night": Condition("night", gain=0.25, gamma=1.5, noise=0.015),
    "fog": Condition("fog", contrast=0.8, haze_distance=30.0),
    "rain": Condition("rain", contrast=0.6, noise=0.008, haze_distance=120.0, sheen=0.35),
    "dynamic": Condition("dynamic", obstacles=12),
}


class Obstacles(NamedTuple):
    """``K`` boxes moving at constant velocity: centre ``(x, y)`` at time 0, velocity, heading,
    size ``(length, width, height)`` and brightness."""

    centre: Float[Array, "K 2"]
    velocity: Float[Array, "K 2"]
    size: Float[Array, "K 3"]
    brightness: Float[Array, " K"]


def place_obstacles(poses: np.ndarray, count: int, seed: int) -> Obstacles:
    """``count`` cars and pedestrians near a trajectory (``T_world_body`` poses): each starts 8-30 m
    ahead of a random frame's pose, 2-6 m to a side, and moves at up to 8 m/s (cars) or 1.5 m/s
    (pedestrians) along a random heading."""
    rng = np.random.default_rng(seed)
    frames = rng.integers(0, len(poses), count)
    ahead, side = rng.uniform(8, 30, count), rng.choice([-1, 1], count) * rng.uniform(2, 6, count)
    r = poses[frames, :2, :2]
    centre = poses[frames, :2, 3] + r[:, :, 0] * ahead[:, None] + r[:, :, 1] * side[:, None]
    car = rng.random(count) < 0.6
    heading = rng.uniform(-np.pi, np.pi, count)
    speed = np.where(car, rng.uniform(0, 8, count), rng.uniform(0, 1.5, count))
    velocity = speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], -1)
    size = np.where(car[:, None], [4.2, 1.8, 1.5], [0.5, 0.5, 1.7])
    return Obstacles(*(jnp.asarray(a, jnp.float32) for a in (centre, velocity, size, rng.uniform(0.05, 0.95, count))))


def draw_obstacles(
    image: Float[Array, "H W"], camera: Camera, pose: Float[Array, "4 4"], obstacles: Obstacles, time: Float[Array, ""]
) -> Float[Array, "H W"]:
    """Draw each obstacle's image-space bounding box (of its 8 corners, axis-aligned in the world)
    with a striped texture of its brightness; obstacles with a corner behind the camera are
    skipped."""
    height, width = camera.image_shape
    centre = obstacles.centre + time * obstacles.velocity
    signs = jnp.array([[sx, sy, sz] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5) for sz in (0.0, 1.0)], image.dtype)
    corners = jnp.concatenate([centre, jnp.zeros_like(centre[:, :1])], -1)[:, None, :] + signs[None] * obstacles.size[:, None, :]
    r_cw = camera.rotation_body_to_camera @ pose[:3, :3].T
    p = (corners - pose[:3, 3]) @ r_cw.T @ camera.intrinsics.T  # (K, 8, 3)
    visible = jnp.all(p[..., 2] > 0.5, axis=-1)
    z = jnp.where(p[..., 2] > 0.5, p[..., 2], 1.0)
    u, v = p[..., 0] / z, p[..., 1] / z
    u0, u1, v0, v1 = u.min(-1), u.max(-1), v.min(-1), v.max(-1)
    cols = jnp.arange(width, dtype=image.dtype)
    rows = jnp.arange(height, dtype=image.dtype)
    inside_u = (cols[None] >= u0[:, None]) & (cols[None] <= u1[:, None])
    inside_v = (rows[None] >= v0[:, None]) & (rows[None] <= v1[:, None])
    stripes = 0.08 * jnp.sin(2 * jnp.pi * (rows[None] - v0[:, None]) / jnp.maximum(v1 - v0, 1.0)[:, None] * 3)
    # Nearest obstacle in front: draw far to near.
    order = jnp.argsort(-jnp.min(z, axis=-1))

    def paint(img, k):
        mask = visible[k] & inside_v[k][:, None] & inside_u[k][None, :]
        return jnp.where(mask, obstacles.brightness[k] + stripes[k][:, None], img), None

    image, _ = jax.lax.scan(paint, image, order)
    return image


def expose(image: Float[Array, "H W"], condition: Condition, key: PRNGKeyArray) -> Array:
    """Exposure, contrast and sensor noise; returns 8-bit."""
    image = jnp.clip(image, 0.0, 1.0)
    if condition.gamma != 1.0:  # static: a pow per pixel only where it does something
        image = image**condition.gamma
    image = condition.gain * image
    if condition.contrast != 1.0:
        mid = condition.gain * SKY_HORIZON**condition.gamma * 0.5
        image = mid + condition.contrast * (image - mid)
    # Uniform noise of the same std: sampling it costs a third of a Gaussian (erfinv) per pixel.
    image = image + condition.noise * 3.4641016 * (jax.random.uniform(key, image.shape, image.dtype) - 0.5)
    return jnp.round(jnp.clip(image, 0.0, 1.0) * 255.0).astype(jnp.uint8)


__all__ = ["CONDITIONS", "Condition", "Obstacles", "draw_obstacles", "expose", "place_obstacles"]
