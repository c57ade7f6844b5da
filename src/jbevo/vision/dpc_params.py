"""The learnable parameters and static settings of differentiable phase correlation
(:mod:`jbevo.vision.registration`)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float


class DPCParams(eqx.Module):
    """The learnable parameters of DPC (array leaves) and its static settings.

    The defaults were chosen on the tuning photos of ``benchmarks/registration.py`` (no training).
    Widths and temperatures are stored as logs so that gradient steps keep them positive.

    Attributes:
        log_angle_temperature: soft-argmax temperature of the angle peak.
        log_shift_temperature: soft-argmax temperature of the translation peak.
        log_angle_peak_width: std of the Gaussian angle peak, in angle bins.
        log_shift_peak_width: std of the Gaussian translation peak, in pixels.
        highpass: exponent ``h`` of the radial emphasis ``(r / max_radius) ** h``.
        log_radial_width: std of a Gaussian radial weight, in cycles per pixel.
        n_angles: polar samples over 180 degrees (static).
        n_radii: polar radii between ``min_radius`` and ``max_radius`` (static).
        min_radius, max_radius: polar band in cycles per pixel (static).
        window_taper: fraction of the disk radius over which the window falls to zero (static).
        peak_half_width: half size of the soft-argmax window, in samples (static).
        pad: zero-padding factor of the rotation spectrum (static; 2 halves its bin spacing,
            which makes bilinear polar resampling far more accurate).
    """

    log_angle_temperature: Float[Array, ""]
    log_shift_temperature: Float[Array, ""]
    log_angle_peak_width: Float[Array, ""]
    log_shift_peak_width: Float[Array, ""]
    highpass: Float[Array, ""]
    log_radial_width: Float[Array, ""]
    n_angles: int = eqx.field(static=True)
    n_radii: int = eqx.field(static=True)
    min_radius: float = eqx.field(static=True)
    max_radius: float = eqx.field(static=True)
    window_taper: float = eqx.field(static=True)
    peak_half_width: int = eqx.field(static=True)
    pad: int = eqx.field(static=True)

    def __init__(
        self,
        angle_temperature: float = 0.5,
        shift_temperature: float = 0.5,
        angle_peak_width: float = 1.0,
        shift_peak_width: float = 1.0,
        highpass: float = 0.5,
        radial_width: float = 0.15,
        *,
        n_angles: int = 512,
        n_radii: int = 64,
        min_radius: float = 0.02,
        max_radius: float = 0.35,
        window_taper: float = 0.5,
        peak_half_width: int = 4,
        pad: int = 2,
    ):
        f = jnp.float32
        self.log_angle_temperature = jnp.log(f(angle_temperature))
        self.log_shift_temperature = jnp.log(f(shift_temperature))
        self.log_angle_peak_width = jnp.log(f(angle_peak_width))
        self.log_shift_peak_width = jnp.log(f(shift_peak_width))
        self.highpass = jnp.asarray(highpass, f)
        self.log_radial_width = jnp.log(f(radial_width))
        if not 0.0 < min_radius < max_radius <= 0.5:
            raise ValueError(f"need 0 < min_radius < max_radius <= 0.5, got {min_radius}, {max_radius}")
        if n_angles < 8 or n_radii < 1 or peak_half_width < 1 or pad < 1:
            raise ValueError("n_angles >= 8, n_radii >= 1, peak_half_width >= 1 and pad >= 1 required")
        if not 0.0 < window_taper <= 1.0:
            raise ValueError(f"window_taper must be in (0, 1], got {window_taper}")
        self.n_angles = int(n_angles)
        self.n_radii = int(n_radii)
        self.min_radius = float(min_radius)
        self.max_radius = float(max_radius)
        self.window_taper = float(window_taper)
        self.peak_half_width = int(peak_half_width)
        self.pad = int(pad)


__all__ = ["DPCParams"]
