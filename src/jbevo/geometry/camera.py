"""Pinhole camera on a vehicle and the homography of the ground plane into its image.

Frames: body x forward, y left, z up; camera x right, y down, z forward (KITTI camera 0). Euler
angles are ZYX; a positive pitch turns the nose down, a positive roll lowers the right side.
The *level* frame has the body's yaw but no pitch or roll; its origin is on the ground plane
right below the camera, so the camera centre is at ``(0, 0, height)`` in it.

Example::

    >>> import jax.numpy as jnp
    >>> camera = Camera.kitti()
    >>> uv, in_front = project_ground_points(camera, jnp.float32(0), jnp.float32(0), jnp.array([[10.0, 0.0]]))
    >>> bool(in_front[0]), round(float(uv[0, 0]), 1)
    (True, 607.2)
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

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


def level_to_body(pitch: Float[ArrayLike, ""], roll: Float[ArrayLike, ""]) -> Float[Array, "3 3"]:
    """``R_level_body = Ry(pitch) Rx(roll)``: body axes expressed in the level frame (ZYX Euler
    without the yaw)."""
    pitch, roll = jnp.asarray(pitch), jnp.asarray(roll)
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


def apply_homography(h: Float[Array, "3 3"], x: Array, y: Array) -> tuple[Array, Array, Array]:
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
    u, v, in_front = apply_homography(h, xy[..., 0], xy[..., 1])
    return jnp.stack([u, v], axis=-1), in_front


__all__ = [
    "FORWARD",
    "Camera",
    "apply_homography",
    "ground_to_image_homography",
    "level_to_body",
    "level_to_camera",
    "project_ground_points",
]
