"""BEV band geometry: what the near and the far half of two registered BEVs say about the
attitude the BEVs were projected with, and the motion free of its errors.

A BEV projected with a pitch ``e`` radians off (its pitch minus the true one) puts a ground point
``x`` metres ahead at ``x - e (x^2 + h^2) / h`` (camera ``h`` metres above the ground; measured
sign). Between two BEVs of a car that moved ``D`` metres forward, a point's apparent forward
shift is therefore not ``D`` but

    s(x) = D - [e (2 x D + D^2) + d ((x + D)^2 + h^2)] / h,

with ``e`` the current BEV's pitch error and ``d`` the previous one's minus the current one's.
When the previous BEV was projected again with the updated attitude (as :class:`jbevo.models.bevo.Bevo`
does with ``bands``), ``d`` is only what the gyro's pitch-rate bias error ``b_hat - b`` integrates
over the frame, ``(b_hat - b) T``. The scale error ``2 e x / h`` is 25 % per degree at 12 m: the
reason BEVO needs its pitch to hundredths of a degree. After the full-BEV registration, the
previous BEV is turned by DPC's rotation and both are registered again, translation only, on
their far and near halves (:func:`register_bands`). Then:

* **Pitch and pitch-rate bias.** The slope of the forward shift over distance,
  ``m = (s_far - s_near) / (x_far - x_near)``, is a linear measurement of the attitude state:
  ``m = [2 D (p - p_hat) + c T (b_y - b_hat_y)] / h`` with ``c = (E[x^2]_far - E[x^2]_near) /
  (x_far - x_near) + 2 D`` (``E`` over the band's DPC window). At speed it measures the pitch
  (0.1 deg per frame at 10 m/s on KITTI-size BEVs); at a standstill it still measures the bias.
* **Forward motion.** After the update's estimate of ``d`` is removed, ``s(x)`` is linear in ``x``
  and equals ``D`` at ``x = -D / 2``: the near band's shift extrapolated there is free of the
  pitch error, and of the camera's bounce (a height change scales the BEV: also linear in ``x``).
* **Yaw.** A roll error ``r`` makes the forward shift grow across the BEV, ``D r y / h``, which
  DPC's rotation partly takes for a turn (~0.03 deg per frame for 0.1 deg of roll at 1 m per
  frame: 3 deg / 100 m). A true residual turn ``w`` moves the lateral shift along the distance,
  ``w x``, which no attitude error does to first order: the difference of the two bands'
  lateral shifts over their distance corrects DPC's rotation. The soft-argmax sees the far band
  nearer than its window's centre (foreshortening blurs it along the rows), so the correction
  carries a gain (hand-set 1.3, measured on KITTI 08; learnable).

The bands need detail in the far half: on KITTI-size images (376 x 1241) with a 256 x 256 BEV at
0.1 m/px they bring BEVO near the true attitude's accuracy (``experiments/bands.py``); on
128 x 416 images with a 128 x 128 BEV the far band is too blurred and the pitch measurement
biased (it lowers accuracy there), so :class:`jbevo.models.bevo.Bevo` leaves them off unless asked.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from jbevo.geometry.bev_grid import BevGrid
from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.phase_correlation import disk_window, rotate_image
from jbevo.vision.registration import Registration, register_translation


@functools.cache
def band_moments(grid: BevGrid, taper: float, power: int) -> tuple[float, float]:
    """``E[x^power]`` over the far (top) and the near (bottom) half of ``grid`` under DPC's disk
    window, ``x`` the ground distance ahead of a row (numpy, at trace time)."""
    rows, cols = grid.shape
    half = rows // 2
    with jax.ensure_compile_time_eval():
        window = np.asarray(disk_window((half, cols), taper))
    x = (grid.origin[0] - np.arange(rows)) * grid.resolution
    weights = window.sum(1)
    moment = lambda xs: float(np.sum(weights * xs**power) / np.sum(weights))
    return moment(x[:half]), moment(x[half : 2 * half])


def register_bands(
    a: Float[Array, "h w"], b: Float[Array, "h w"], params: DPCParams
) -> tuple[Float[Array, "2 2"], Float[Array, " 2"]]:
    """Translation-only DPC of the far (top) and the near (bottom) halves of ``a`` onto those of
    ``b``: shifts ``((far x, far y), (near x, near y))`` in pixels and the two confidences."""
    half = a.shape[0] // 2
    return register_translation(jnp.stack([a[:half], a[half : 2 * half]]), jnp.stack([b[:half], b[half : 2 * half]]), params)


class BandShifts(NamedTuple):
    """The far and near band shifts of a registered BEV pair, in metres."""

    forward: Float[Array, " 2"]  #: (far, near), positive: the scene moved toward the camera
    lateral: Float[Array, " 2"]  #: (far, near), along the BEV's columns
    confidence: Float[Array, " 2"]


class SlopeMeasurement(NamedTuple):
    """The bands' forward-shift slope as a scalar measurement linear in the attitude state."""

    value: Float[Array, ""]  #: the measured slope (per metre of distance ahead)
    pitch: Float[Array, ""]  #: its coefficient on the pitch error (per radian)
    pitch_rate_bias: Float[Array, ""]  #: its coefficient on the pitch-rate bias error (per rad/s)
    variance: Float[Array, ""]
    valid: Bool[Array, ""]  #: False where the shifts are not finite (then the other fields are 0)


class BandGeometry(eqx.Module):
    """The band model's learnable parameters: the log standard deviation of the forward-shift
    slope measurement (hand-set 0.003: the slope's scatter on KITTI-size BEVs, 0.1 deg of pitch
    at 1 m per frame) and the log gain of the yaw correction (hand-set 1.3; module docstring).

    ``robust`` (static): the slope's variance grows by its squared innovation (Cauchy-like, as the
    attitude filter's other updates), so a slope that off-ground content or a near-standstill
    frame bends far from the prediction loses its weight instead of tilting the filter. Without
    it, a slow start on a real street (KITTI 07: 0.1-0.3 m per frame between parked cars) drove
    the pitch 25 degrees off within 40 frames.

    ``min_travel`` (static, metres per frame; 0: always on): below it (the full registration's
    forward motion) :class:`jbevo.models.bevo.Bevo` neither updates the attitude with the slope
    nor takes the bands' motion, but the full registration's. The slope's pitch coefficient
    ``2 D / h`` vanishes with the travel ``D`` while its noise does not.

    ``keyframes`` (static; needs ``min_travel`` > 0): below ``min_travel`` per frame the bands
    compare the current BEV with the last one at which they engaged (the keyframe) instead of
    the previous one, and engage once the travel since the keyframe reaches ``min_travel``: a
    slow car measures the slope over a baseline of at least ``min_travel`` metres, spread over
    several frames, instead of never. The motion of a frame whose keyframe is not the previous
    frame stays the full registration's between consecutive BEVs."""

    log_slope_std: Float[Array, ""]
    log_yaw_gain: Float[Array, ""]
    robust: bool = eqx.field(static=True, default=False)
    min_travel: float = eqx.field(static=True, default=0.0)
    keyframes: bool = eqx.field(static=True, default=False)

    @classmethod
    def create(
        cls,
        slope_std: float = 0.003,
        yaw_gain: float = 1.3,
        robust: bool = False,
        min_travel: float = 0.0,
        keyframes: bool = False,
    ) -> BandGeometry:
        if not (slope_std > 0 and yaw_gain > 0):
            raise ValueError(f"slope_std and yaw_gain must be positive, got {slope_std}, {yaw_gain}")
        if not min_travel >= 0:
            raise ValueError(f"min_travel must be non-negative, got {min_travel}")
        if keyframes and not min_travel > 0:
            raise ValueError("keyframes need a positive min_travel (the baseline a keyframe is kept for)")
        return cls(
            jnp.log(jnp.float32(slope_std)), jnp.log(jnp.float32(yaw_gain)), bool(robust), float(min_travel), bool(keyframes)
        )

    def shifts(
        self, prev: Float[Array, "h w"], bev: Float[Array, "h w"], reg: Registration, grid: BevGrid, params: DPCParams
    ) -> BandShifts:
        """``prev`` turned by the full registration's rotation, then :func:`register_bands`. (Moving
        it by the translation too, bilinearly or by whole pixels, measured worse on KITTI-style
        drives.)"""
        turned = rotate_image(prev, reg.rotation, jnp.mean(prev))
        shift, confidence = register_bands(turned, bev, params)
        shift = grid.resolution * shift
        # Rows run backwards along x: a positive row shift is a forward motion of the car.
        return BandShifts(shift[:, 1], shift[:, 0], confidence)

    def _slope(self, forward: Float[Array, " 2"], grid: BevGrid, params: DPCParams) -> Array:
        x_far, x_near = band_moments(grid, params.window_taper, 1)
        return (forward[0] - forward[1]) / (x_far - x_near)

    def _extrapolate(self, forward: Float[Array, " 2"], grid: BevGrid, params: DPCParams) -> Array:
        """``D`` with ``s(-D / 2) = D`` on the line through the two bands."""
        _, x_near = band_moments(grid, params.window_taper, 1)
        slope = self._slope(forward, grid, params)
        return (forward[1] - x_near * slope) / (1.0 + 0.5 * slope)

    def slope_measurement(
        self, shifts: BandShifts, grid: BevGrid, params: DPCParams, height: Float[Array, ""], frame_dt: float | Float[Array, ""]
    ) -> SlopeMeasurement:
        """The forward-shift slope of the band pair as a scalar measurement of the attitude the
        current BEV was projected with (module docstring): ``m = [2 D (p - p_hat) + c T (b_y -
        b_hat_y)] / h``, whose prediction at that attitude is zero. ``frame_dt`` is the time
        between the two BEVs (several frames from a keyframe)."""
        (x_far, x_near), (m2_far, m2_near) = (
            band_moments(grid, params.window_taper, 1),
            band_moments(grid, params.window_taper, 2),
        )
        travel = self._extrapolate(shifts.forward, grid, params)
        c = (m2_far - m2_near) / (x_far - x_near) + 2.0 * travel
        slope = self._slope(shifts.forward, grid, params)
        valid = jnp.isfinite(slope) & jnp.isfinite(travel)
        zero = jnp.zeros_like(slope)
        value = jnp.where(valid, slope, zero)
        variance = jnp.exp(2.0 * self.log_slope_std).astype(slope.dtype)
        return SlopeMeasurement(
            value=value,
            pitch=jnp.where(valid, 2.0 * travel / height, zero),
            pitch_rate_bias=jnp.where(valid, c * frame_dt / height, zero),
            variance=variance + value**2 if self.robust else variance,
            valid=valid,
        )

    def remove_drift(self, shifts: BandShifts, grid: BevGrid, params: DPCParams, height: Array, drift: Array) -> BandShifts:
        """The band shifts without what a pitch ``drift`` of the earlier BEV relative to the later
        one (radians, the ``d`` of the module docstring) adds to them: ``d ((x + D)^2 + h^2) / h``
        averaged over each band, at the travel ``D`` the shifts give."""
        (x_far, x_near), (m2_far, m2_near) = (
            band_moments(grid, params.window_taper, 1),
            band_moments(grid, params.window_taper, 2),
        )
        travel = self._extrapolate(shifts.forward, grid, params)
        h2 = height**2
        forward = shifts.forward + drift / height * jnp.stack(
            [
                m2_far + 2.0 * travel * x_far + travel**2 + h2,
                m2_near + 2.0 * travel * x_near + travel**2 + h2,
            ]
        )
        return shifts._replace(forward=forward)

    def motion(
        self, shifts: BandShifts, reg: Registration, grid: BevGrid, params: DPCParams, height: Array, drift: Array
    ) -> tuple[Array, Float[Array, " 2"]]:
        """DPC's ``(rotation, translation)`` (pixels, for :func:`jbevo.vision.bev.bev_increment`) with
        the forward translation extrapolated to the pitch-free distance after removing the
        previous BEV's pitch ``drift`` relative to the current one (radians, the estimated
        ``(b_hat - b) T``), the rotation corrected by the bands' lateral shifts, and the lateral
        translation taken at the BEV's centre row."""
        x_far, x_near = band_moments(grid, params.window_taper, 1)
        travel = self._extrapolate(self.remove_drift(shifts, grid, params, height, drift).forward, grid, params)
        lat_far, lat_near = shifts.lateral[0], shifts.lateral[1]
        turn = (lat_far - lat_near) / (x_far - x_near)
        lateral = lat_near + (grid.centre_distance - x_near) * turn
        rotation = reg.rotation - jnp.exp(self.log_yaw_gain) * turn
        return rotation, jnp.stack([lateral, travel]) / grid.resolution


__all__ = ["BandGeometry", "BandShifts", "SlopeMeasurement", "band_moments", "register_bands"]
