"""A georeferenced top-down map (drone or satellite imagery), the second input of map
localization."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Float, UInt8


class Map(NamedTuple):
    """An 8-bit map and its georeference: pixel ``(0, 0)`` is world ``(x_max, y_max)``."""

    image: UInt8[Array, "R C"]
    x_max: float
    y_max: float
    resolution: float

    def world_to_pixel(self, xy: Float[Array, "... 2"]) -> Float[Array, "... 2"]:
        """``(row, col)`` of world points."""
        return jnp.stack([(self.x_max - xy[..., 0]), (self.y_max - xy[..., 1])], -1) / self.resolution


__all__ = ["Map"]
