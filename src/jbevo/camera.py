"""Pinhole camera, bird's-eye-view (BEV) grid, ground homography and ``bev_project``.

Frames (DESIGN.md): body x forward, y left, z up; camera x right, y down, z forward (KITTI
camera 0). Euler angles are ZYX; a positive pitch turns the nose down, a positive roll lowers
the right side. The *level* frame has the body's yaw but no pitch or roll; its origin is on the
ground plane right below the camera, so the camera centre is at ``(0, 0, height)`` in it.

BEV image: ``rows`` run backwards along level x (forward is up when displayed), ``cols``
backwards along level y (left is left). Pixel ``(row, col)`` is the ground point
``x = (origin_row - row) * resolution``, ``y = (origin_col - col) * resolution``. So a positive yaw
(turning left) is a counter-clockwise turn as displayed, the sense :func:`jbevo.registration.register`
calls positive.

One 3x3 matrix maps BEV pixels to image pixels (:func:`bev_to_image_homography`), so the
projection is a homography followed by a bilinear gather; it is differentiable with respect to
pitch, roll, the camera parameters and the image, and works under ``jit`` and ``vmap``.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jax.scipy.ndimage import map_coordinates
from jaxtyping import Array, Bool, Float

from jbevo.geometry import wrap_angle

# Body -> camera for a camera looking straight ahead: camera x = -body y, y = -body z, z = body x.
FORWARD = ((0.0, -1.0, 0.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))


class Camera(eqx.Module):
    """Pinhole camera: intrinsics, image size, height of the centre above the ground, and the
    body-to-camera rotation (the mounting; pitch and roll of the vehicle come on top of it).

    ``Camera.kitti()`` is KITTI odometry camera 0 (sequences 00-02 calibration) at 1.65 m.
    """

    intrinsics: Float[Array, "3 3"]
    height: Float[Array, ""]
    rotation_body_to_camera: Float[Array, "3 3"]
    image_shape: tuple[int, int] = eqx.field(static=True)

    def __init__(self, fx, fy, cx, cy, image_shape, height, rotation_body_to_camera=FORWARD):
        self.intrinsics = jnp.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], jnp.float32)
        self.height = jnp.asarray(height, jnp.float32)
        self.rotation_body_to_camera = jnp.asarray(rotation_body_to_camera, jnp.float32)
        if len(image_shape) != 2 or min(image_shape) < 1:
            raise ValueError(f"image_shape must be (H, W), got {image_shape}")
        if not height > 0:
            raise ValueError(f"height must be positive, got {height}")
        self.image_shape = (int(image_shape[0]), int(image_shape[1]))

    @classmethod
    def kitti(cls, height: float = 1.65) -> Camera:
        return cls(718.856, 718.856, 607.1928, 185.2157, (376, 1241), height)


class BevGrid(eqx.Module):
    """A BEV raster: ``shape`` pixels of ``resolution`` metres; ``origin`` is the (row, col) where
    the camera's ground point sits (may lie outside the raster). All static."""

    resolution: float = eqx.field(static=True)
    shape: tuple[int, int] = eqx.field(static=True)
    origin: tuple[float, float] = eqx.field(static=True)

    def __init__(self, resolution: float = 0.1, shape=(256, 256), origin=None, near: float = 4.0):
        """``origin`` defaults to the column centre and a row ``near`` metres below the bottom edge,
        so the raster covers ``near`` to ``near + rows * resolution`` metres ahead."""
        if not resolution > 0:
            raise ValueError(f"resolution must be positive, got {resolution}")
        if len(shape) != 2 or min(shape) < 1:
            raise ValueError(f"shape must be (rows, cols), got {shape}")
        self.resolution = float(resolution)
        self.shape = (int(shape[0]), int(shape[1]))
        if origin is None:
            origin = (shape[0] - 1 + near / resolution, (shape[1] - 1) / 2)
        self.origin = (float(origin[0]), float(origin[1]))

    def ground_points(self) -> Float[Array, "H W 2"]:
        """Level-frame ground coordinates ``(x, y)`` of every pixel centre."""
        rows = jnp.arange(self.shape[0], dtype=jnp.float32)
        cols = jnp.arange(self.shape[1], dtype=jnp.float32)
        x = (self.origin[0] - rows)[:, None] * self.resolution
        y = (self.origin[1] - cols)[None, :] * self.resolution
        return jnp.stack(jnp.broadcast_arrays(x, y), axis=-1)

    def pixel_to_ground(self) -> Float[Array, "3 3"]:
        """Affine map from homogeneous ``(col, row, 1)`` to ``(x, y, 1)`` on the ground."""
        r, (o_row, o_col) = self.resolution, self.origin
        return jnp.array([[0.0, -r, o_row * r], [-r, 0.0, o_col * r], [0.0, 0.0, 1.0]], jnp.float32)


def level_to_body(pitch: Float[Array, ""], roll: Float[Array, ""]) -> Float[Array, "3 3"]:
    """``R_level_body = Ry(pitch) Rx(roll)``: body axes expressed in the level frame (ZYX Euler
    without the yaw)."""
    cp, sp, cr, sr = jnp.cos(pitch), jnp.sin(pitch), jnp.cos(roll), jnp.sin(roll)
    zero, one = jnp.zeros_like(cp), jnp.ones_like(cp)
    ry = jnp.stack([jnp.stack([cp, zero, sp]), jnp.stack([zero, one, zero]), jnp.stack([-sp, zero, cp])])
    rx = jnp.stack([jnp.stack([one, zero, zero]), jnp.stack([zero, cr, -sr]), jnp.stack([zero, sr, cr])])
    return ry @ rx


def level_to_camera(camera: Camera, pitch, roll) -> Float[Array, "3 3"]:
    """``R_camera_level``: maps level-frame vectors into the camera frame."""
    return camera.rotation_body_to_camera @ level_to_body(pitch, roll).T


def ground_to_image_homography(camera: Camera, pitch, roll) -> Float[Array, "3 3"]:
    """``H`` with ``(u, v, 1) ~ H (x, y, 1)`` for ground points ``(x, y, 0)`` of the level frame."""
    r = level_to_camera(camera, pitch, roll)
    # p_cam = R (x, y, -height) = x R[:, 0] + y R[:, 1] - height R[:, 2]
    m = jnp.stack([r[:, 0], r[:, 1], -camera.height * r[:, 2]], axis=1)
    return camera.intrinsics @ m


def bev_to_image_homography(camera: Camera, grid: BevGrid, pitch, roll) -> Float[Array, "3 3"]:
    """``H`` with ``(u, v, 1) ~ H (col, row, 1)`` from BEV pixels to image pixels."""
    return ground_to_image_homography(camera, pitch, roll) @ grid.pixel_to_ground()


def _apply_homography(h: Float[Array, "3 3"], x: Array, y: Array) -> tuple[Array, Array, Array]:
    """``(u, v)`` of ``h (x, y, 1)`` and whether its third component is positive (in front);
    finite also where it is not (the division is guarded)."""
    w = h[2, 0] * x + h[2, 1] * y + h[2, 2]
    in_front = w > 1e-6
    w = jnp.where(in_front, w, 1.0)
    return (h[0, 0] * x + h[0, 1] * y + h[0, 2]) / w, (h[1, 0] * x + h[1, 1] * y + h[1, 2]) / w, in_front


def project_ground_points(camera: Camera, pitch, roll, xy: Float[Array, "... 2"]):
    """Image pixels ``(u, v)`` of level-frame ground points and whether they are in front of the
    camera (``z > 0``)."""
    h = ground_to_image_homography(camera, pitch, roll)
    u, v, in_front = _apply_homography(h, xy[..., 0], xy[..., 1])
    return jnp.stack([u, v], axis=-1), in_front


def bev_project(
    image: Float[Array, "H W"], pitch: Float[Array, ""], roll: Float[Array, ""], camera: Camera, grid: BevGrid
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
    u, v, in_front = _apply_homography(h, cols, rows)
    height, width = camera.image_shape
    valid = in_front & (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    u = jnp.where(valid, u, 0.0)
    v = jnp.where(valid, v, 0.0)
    bev = map_coordinates(image, [v, u], order=1, mode="nearest")
    return jnp.where(valid, bev, 0.0), valid


def bev_increment(grid: BevGrid, rotation: Float[Array, ""], translation: Float[Array, " 2"]) -> Float[Array, " 3"]:
    """The body-frame motion ``(dx, dy, dyaw)`` from the pose a BEV ``a`` was taken at to the pose
    of BEV ``b``, given the :func:`jbevo.registration.register` result ``(rotation, translation)``
    that carries ``a`` onto ``b`` (same ``grid``).

    With ``R = R(dyaw)`` (standard, counter-clockwise), BEV origin ``o`` and image centre ``c``
    (both ``(col, row)``), and ``S`` the swap of the two axes: ``dyaw = -rotation`` and
    ``(dx, dy) = resolution * R S (t - (R - I)(c - o))``. A ground point fixed in the world moves
    in the BEV opposite to the vehicle, and DPC measures turns about the image centre, not about
    the camera's ground point ``o``; the ``(R - I)(c - o)`` term moves the turn's centre there.
    """
    dyaw = -rotation
    c, s = jnp.cos(dyaw), jnp.sin(dyaw)
    r = jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])
    rows, cols = grid.shape
    centre = jnp.array([(cols - 1) / 2, (rows - 1) / 2], translation.dtype)
    origin = jnp.array([grid.origin[1], grid.origin[0]], translation.dtype)
    t = translation - (r - jnp.eye(2, dtype=translation.dtype)) @ (centre - origin)
    d = grid.resolution * r @ t[::-1]  # S swaps (x, y) = (col, row)
    return jnp.stack([d[0], d[1], wrap_angle(dyaw)])
