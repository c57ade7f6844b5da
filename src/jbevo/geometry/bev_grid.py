"""The BEV raster: ``shape`` pixels of ``resolution`` metres on the ground plane of the level
frame, and where the camera's ground point sits on it.

Pixel ``(row, col)`` is the ground point ``x = (origin_row - row) * resolution``,
``y = (origin_col - col) * resolution``: rows run backwards along x (forward is up when
displayed), columns backwards along y (left is left).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float


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

    @property
    def centre_distance(self) -> float:
        """The ground distance ``x`` of the raster's centre row (metres)."""
        return (self.origin[0] - (self.shape[0] - 1) / 2) * self.resolution

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


__all__ = ["BevGrid"]
