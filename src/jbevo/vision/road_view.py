"""The camera against the road, and which part of the BEV is road: a few interpretable, learnable
numbers that make the ground-plane BEV hold on real streets.

Real frames break two assumptions of the plain BEV:

* **Calibration.** The BEV needs the camera's attitude and height against the road plane. The IMU
  gives the body's attitude against gravity; the camera may sit a fraction of a degree off the
  body's axes, its height is known to a few centimetres, and a street's grade and banking tilt the
  road against gravity. A pitch error ``e`` scales the BEV's apparent motion by about
  ``1 - 2 e x / h`` (25 % per degree at ``x`` = 12 m, ``h`` = 1.65 m), a height error scales it by
  ``h_true / h``. :class:`RoadView` adds a pitch and roll offset to the projection's attitude and
  scales the camera's height.
* **Off-ground content.** Everything above the road (parked cars, facades, trees) projects onto the
  ground plane stretched away from the camera and moves faster in the BEV than the ground does,
  biasing the motion high (on a narrow street lined with parked cars, by 30-40 %). The road
  corridor keeps the BEV's columns within ``corridor`` metres of the camera's line and fades the
  rest to the BEV's mean over ``corridor_edge`` metres (a logistic ramp), so what stands beside
  the lane stops voting.

Hand-set (:meth:`RoadView.create`): no offsets, the nominal height, and a corridor of 1.75 m on
either side: half a standard 3.5 m lane, a physical prior rather than a value tuned on any frames.
Every number is learnable end to end (:mod:`jbevo.training`); the gradient through the projection
is tested against finite differences.

Example::

    >>> import jax.numpy as jnp
    >>> from jbevo.geometry.camera import Camera
    >>> view = RoadView.create(pitch=0.01)
    >>> view.attitude(jnp.zeros(2)).tolist()
    [0.009999999776482582, 0.0]
    >>> float(view.camera(Camera.kitti()).height)
    1.649999976158142
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import Camera


class RoadView(eqx.Module):
    """The camera's attitude and height against the road, and the BEV's road corridor.

    Attributes:
        pitch: radians added to the projection's pitch (positive: nose down, as ZYX Euler).
        roll: radians added to the projection's roll.
        log_height_scale: log of the factor on the camera's nominal height.
        log_corridor: log of the corridor's half width (metres, across the BEV's columns).
        corridor_edge: the logistic ramp's scale in metres: the weight is 0.73 this far inside the
            corridor's edge and 0.27 this far outside (static).
    """

    pitch: Float[Array, ""]
    roll: Float[Array, ""]
    log_height_scale: Float[Array, ""]
    log_corridor: Float[Array, ""]
    corridor_edge: float = eqx.field(static=True, default=0.2)

    @classmethod
    def create(
        cls, pitch: float = 0.0, roll: float = 0.0, height_scale: float = 1.0, corridor: float = 1.75, corridor_edge: float = 0.2
    ) -> RoadView:
        """A road view from its physical values (radians, a factor, metres)."""
        if not (height_scale > 0 and corridor > 0 and corridor_edge > 0):
            raise ValueError(
                f"height_scale, corridor and corridor_edge must be positive, got {height_scale}, {corridor}, {corridor_edge}"
            )
        f = jnp.float32
        return cls(f(pitch), f(roll), jnp.log(f(height_scale)), jnp.log(f(corridor)), float(corridor_edge))

    def attitude(self, pitch_roll: Float[Array, " 2"]) -> Float[Array, " 2"]:
        """The camera's ``(pitch, roll)`` against the road, from the body's against gravity."""
        offset = jnp.stack([self.pitch, self.roll]).astype(pitch_roll.dtype)
        return pitch_roll + offset

    def height(self, camera: Camera) -> Float[Array, ""]:
        """The camera's height above the road (metres)."""
        return camera.height * jnp.exp(self.log_height_scale)

    def camera(self, camera: Camera) -> Camera:
        """``camera`` at :meth:`height`."""
        return eqx.tree_at(lambda c: c.height, camera, self.height(camera))

    def corridor_weight(self, grid: BevGrid) -> Float[Array, " w"]:
        """Each BEV column's weight: 1 inside the corridor, falling to 0 outside it."""
        y = grid.ground_points()[0, :, 1]
        return jax.nn.sigmoid((jnp.exp(self.log_corridor) - jnp.abs(y)) / self.corridor_edge)

    def keep_road(self, bev: Float[Array, "h w"], grid: BevGrid) -> Float[Array, "h w"]:
        """``bev`` with the columns outside the corridor faded to its mean."""
        weight = self.corridor_weight(grid).astype(bev.dtype)
        mean = jnp.mean(bev)
        return mean + weight[None, :] * (bev - mean)


__all__ = ["RoadView"]
