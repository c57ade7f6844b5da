"""The bird's-eye view (BEV): a raster of the ground plane in the level frame, the projection of a
camera image onto it, its feathered edge, and the body-frame motion a registration of two BEVs
means.

BEV image: ``rows`` run backwards along level x (forward is up when displayed), ``cols``
backwards along level y (left is left). Pixel ``(row, col)`` is the ground point
``x = (origin_row - row) * resolution``, ``y = (origin_col - col) * resolution``. So a positive yaw
(turning left) is a counter-clockwise turn as displayed, the sense
:func:`jbevo.vision.registration.register` calls positive.

One 3x3 matrix maps BEV pixels to image pixels (:func:`bev_to_image_homography`), so the
projection is a homography followed by a bilinear gather; it is differentiable with respect to
pitch, roll, the camera parameters and the image, and works under ``jit`` and ``vmap``.

Example::

    >>> import jax.numpy as jnp
    >>> from jbevo.geometry.camera import Camera
    >>> camera, grid = Camera.kitti(), BevGrid(0.1, (256, 256), near=4.0)
    >>> bev, valid = bev_project(jnp.ones((376, 1241)), jnp.float32(0), jnp.float32(0), camera, grid)
    >>> bev.shape, bool(valid[-1, 128])
    ((256, 256), True)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.scipy.ndimage import map_coordinates
from jaxtyping import Array, ArrayLike, Bool, Float

from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import Camera, apply_homography, ground_to_image_homography


def bev_to_image_homography(camera: Camera, grid: BevGrid, pitch, roll) -> Float[Array, "3 3"]:
    """``H`` with ``(u, v, 1) ~ H (col, row, 1)`` from BEV pixels to image pixels."""
    return ground_to_image_homography(camera, pitch, roll) @ grid.pixel_to_ground()


def bev_project(
    image: Float[Array, "H W"], pitch: Float[ArrayLike, ""], roll: Float[ArrayLike, ""], camera: Camera, grid: BevGrid
) -> tuple[Float[Array, "h w"], Bool[Array, "h w"]]:
    """The gravity-aligned BEV of a grayscale ``image`` taken at ``pitch`` and ``roll``.

    Returns ``(bev, valid)``: ``bev`` is bilinearly sampled (0 where invalid), ``valid`` marks the
    BEV pixels whose ground point is in front of the camera and projects inside
    ``[0, W - 1] x [0, H - 1]`` (so both bilinear taps lie in the image). Differentiable in ``pitch``, ``roll``,
    ``image`` and the camera's arrays; batch with ``jax.vmap``.
    """
    if image.ndim != 2 or tuple(image.shape) != camera.image_shape:
        raise ValueError(f"image must have the camera's shape {camera.image_shape}, got {image.shape}")
    h = bev_to_image_homography(camera, grid, pitch, roll).astype(image.dtype)
    rows = jnp.arange(grid.shape[0], dtype=image.dtype)[:, None]
    cols = jnp.arange(grid.shape[1], dtype=image.dtype)[None, :]
    u, v, in_front = apply_homography(h, cols, rows)
    height, width = camera.image_shape
    valid = in_front & (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    u = jnp.where(valid, u, 0.0)
    v = jnp.where(valid, v, 0.0)
    bev = map_coordinates(image, [v, u], order=1, mode="nearest")
    return jnp.where(valid, bev, 0.0), valid


def bev_increment(grid: BevGrid, rotation: Float[ArrayLike, ""], translation: Float[Array, " 2"]) -> Float[Array, " 3"]:
    """The body-frame motion ``(dx, dy, dyaw)`` from the pose a BEV ``a`` was taken at to the pose
    of BEV ``b``, given the :func:`jbevo.vision.registration.register` result ``(rotation, translation)``
    that carries ``a`` onto ``b`` (same ``grid``).

    With ``R = R(dyaw)`` (standard, counter-clockwise), BEV origin ``o`` and image centre ``c``
    (both ``(col, row)``), and ``S`` the swap of the two axes: ``dyaw = -rotation`` and
    ``(dx, dy) = resolution * R S (t - (R - I)(c - o))``. A ground point fixed in the world moves
    in the BEV opposite to the vehicle, and DPC measures turns about the image centre, not about
    the camera's ground point ``o``; the ``(R - I)(c - o)`` term moves the turn's centre there.
    """
    dyaw = -jnp.asarray(rotation)
    c, s = jnp.cos(dyaw), jnp.sin(dyaw)
    r = jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])
    rows, cols = grid.shape
    centre = jnp.array([(cols - 1) / 2, (rows - 1) / 2], translation.dtype)
    origin = jnp.array([grid.origin[1], grid.origin[0]], translation.dtype)
    t = translation - (r - jnp.eye(2, dtype=translation.dtype)) @ (centre - origin)
    d = grid.resolution * r @ t[::-1]  # S swaps (x, y) = (col, row)
    return jnp.stack([d[0], d[1], wrap_angle(dyaw)])


def feathered_bev(image: Array, pitch: Array, roll: Array, camera: Camera, grid: BevGrid, feather: int) -> Float[Array, "h w"]:
    """The BEV of an 8-bit ``image`` (intensities in [0, 1]) with the pixels outside the camera's
    view at the mean of the valid ones and the view's edge feathered over ``feather`` pixels."""
    bev, valid = bev_project(image.astype(pitch.dtype) * (1.0 / 255.0), pitch, roll, camera, grid)
    return feather_to_mean(bev, valid, feather)


def feather_to_mean(image: Float[Array, "h w"], valid: Array, feather: int) -> Float[Array, "h w"]:
    """``mean + w (image - mean)``, the mean over ``valid`` pixels and ``w`` the feathered
    ``valid`` mask: invalid pixels fade to the mean."""
    valid = valid.astype(image.dtype)
    weight = _feathered(valid, feather)
    mean = jnp.sum(image * valid) / jnp.maximum(jnp.sum(valid), 1.0)
    return mean + weight * (image - mean)


def _feathered(valid: Float[Array, "H W"], width: int) -> Float[Array, "H W"]:
    """The valid mask eroded and smoothed by a ``width``-pixel box filter applied twice (a
    triangle ramp from 0 at the view's edge to 1 ``width`` pixels inside)."""
    if width <= 0:
        return valid
    k = jnp.ones(2 * width + 1, valid.dtype) / (2 * width + 1)
    eroded = 1.0 - jnp.clip(_box(1.0 - valid, k) * (2 * width + 1), 0.0, 1.0)
    return _box(eroded, k)


def _box(image, k):
    image = jax.vmap(lambda r: jnp.convolve(r, k, mode="same"))(image)
    return jax.vmap(lambda c: jnp.convolve(c, k, mode="same"), in_axes=1, out_axes=1)(image)


__all__ = ["BevGrid", "bev_increment", "bev_project", "bev_to_image_homography", "feather_to_mean", "feathered_bev"]
