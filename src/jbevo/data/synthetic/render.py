"""Camera images of the planar :class:`~jbevo.data.synthetic.world.World` for a 6-DoF pose.

Frames: world z up, the ground is ``z = 0``; body x forward, y left, z up; the
camera's centre is the body origin (so the body pose's ``z`` is the camera height) and
``camera.rotation_body_to_camera`` mounts it (KITTI camera 0 looks along body x).

Every pixel's ray is intersected with the ground; the texture is sampled there with the pixel's
ground footprint (the length of the longer side of the pixel's ground parallelogram, from the
ray's analytic derivatives), so the far field is smoothed rather than aliased. Pixels whose ray
misses the ground show a sky gradient; the ground fades into a horizon haze with distance.
:func:`render` is pure and jit/vmap friendly; :func:`render_batch` renders many poses. It maps
over them two at a time (``lax.map``) rather than vmapping all: on a CPU the texture gathers of
a whole batch thrash the cache, and two at a time renders faster than a batch of 16 vmapped.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo.data.synthetic.structures import Boxes, cast_boxes
from jbevo.data.synthetic.world import World
from jbevo.geometry.camera import Camera

SKY_TOP, SKY_HORIZON, HAZE_DISTANCE = 0.85, 0.65, 400.0


def camera_rays(camera: Camera, rotation_world_body: Float[Array, "3 3"]) -> tuple[Float[Array, "3 H W"], Float[Array, "3 3"]]:
    """World-frame ray direction of every pixel (unnormalised: camera z component 1) and the
    camera-to-world rotation."""
    height, width = camera.image_shape
    dtype = camera.intrinsics.dtype
    u = jnp.arange(width, dtype=dtype)[None, :]
    v = jnp.arange(height, dtype=dtype)[:, None]
    k = camera.intrinsics
    xc = (u - k[0, 2]) / k[0, 0]
    yc = (v - k[1, 2]) / k[1, 1]
    r_wc = rotation_world_body @ camera.rotation_body_to_camera.T
    return (r_wc[:, 0, None, None] * xc[None] + r_wc[:, 1, None, None] * yc[None] + r_wc[:, 2, None, None]), r_wc


def render(
    world: World,
    camera: Camera,
    pose: Float[Array, "4 4"],
    haze_distance: float = HAZE_DISTANCE,
    sheen: float = 0.0,
    boxes: Boxes | None = None,
    ground_contrast: float = 1.0,
) -> Float[Array, "H W"]:
    """Grayscale image in [0, 1] seen by ``camera`` at body pose ``T_world_body`` (``pose``).

    ``haze_distance`` (metres) sets how fast the ground fades into the horizon's grey (fog: tens
    of metres); ``sheen`` adds a wet road's reflection of the sky, strongest at grazing angles.
    ``boxes`` (:mod:`jbevo.data.synthetic.structures`: facades, parked cars, poles) stand on the
    ground and hide what is behind them; ``ground_contrast`` scales the ground texture's
    contrast about mid-grey (worn, smooth asphalt: below 1).
    """
    pose = jnp.asarray(pose, camera.intrinsics.dtype)
    d, r_wc = camera_rays(camera, pose[:3, :3])
    centre = pose[:3, 3]
    k = camera.intrinsics
    dz = d[2]
    ground = dz < -1e-6
    dz_safe = jnp.where(ground, dz, -1.0)
    s = -centre[2] / dz_safe  # ray parameter to the ground
    x = centre[0] + s * d[0]
    y = centre[1] + s * d[1]
    # d/du and d/dv of the ground point: the ray moves by r_wc[:, 0] / fx per column (and
    # r_wc[:, 1] / fy per row); P = c - c_z d / d_z, so dP = -c_z (d' d_z - d d_z') / d_z^2.
    lengths = []
    for col, f in ((0, k[0, 0]), (1, k[1, 1])):
        dd = r_wc[:, col] / f
        gx = -centre[2] * (dd[0] * dz_safe - d[0] * dd[2]) / dz_safe**2
        gy = -centre[2] * (dd[1] * dz_safe - d[1] * dd[2]) / dz_safe**2
        lengths.append(jnp.sqrt(gx**2 + gy**2))
    footprint = jnp.maximum(lengths[0], lengths[1])
    x, y = jnp.where(ground, x, 0.0), jnp.where(ground, y, 0.0)
    texture = world.sample(x, y, jnp.where(ground, footprint, 1e3))
    if ground_contrast != 1.0:  # static
        texture = 0.45 + ground_contrast * (texture - 0.45)
    distance = s * jnp.sqrt(d[0] ** 2 + d[1] ** 2 + dz**2)
    haze = jnp.exp(-jnp.where(ground, distance, 0.0) / haze_distance)
    elevation = dz / jnp.sqrt(d[0] ** 2 + d[1] ** 2 + dz**2)
    texture = texture + sheen * (1.0 - texture) * (1.0 + elevation) ** 8  # Schlick-like grazing reflection
    sky = SKY_HORIZON + (SKY_TOP - SKY_HORIZON) * jnp.clip(elevation * 4.0, 0.0, 1.0)
    image = jnp.where(ground, haze * texture + (1 - haze) * SKY_HORIZON, sky)
    if boxes is not None:
        t_box, surface = cast_boxes(world, boxes, centre, d, 1.0 / k[0, 0])
        in_front = t_box < jnp.where(ground, s, jnp.inf)
        box_haze = jnp.exp(-jnp.where(in_front, t_box, 0.0) * jnp.sqrt(d[0] ** 2 + d[1] ** 2 + dz**2) / haze_distance)
        image = jnp.where(in_front, box_haze * surface + (1 - box_haze) * SKY_HORIZON, image)
    return image.astype(camera.intrinsics.dtype)


def render_batch(
    world: World, camera: Camera, poses: Float[Array, "N 4 4"], batch_size: int = 2, **kwargs
) -> Float[Array, "N H W"]:
    """:func:`render` for each pose, ``batch_size`` at a time (``kwargs`` go to :func:`render`)."""
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (N, 4, 4), got {poses.shape}")
    return jax.lax.map(lambda pose: render(world, camera, pose, **kwargs), poses, batch_size=batch_size)


__all__ = ["camera_rays", "render", "render_batch"]
