"""Differentiable phase correlation (DPC): rotation and translation between two images.

Pure JAX (jit, vmap, grad; float32 by default). The pipeline:

1. **Window.** Both images are mean-subtracted inside a radial (disk) Tukey window, so that
   rotating the windowed image equals windowing the rotated image and the magnitude spectrum
   turns with the content; a square window would add a cross to the spectrum that does not.
2. **Rotation.** The magnitude spectrum ``|F|`` of a real image is symmetric, and rotating the
   image rotates it by the same angle. ``log |F|`` is resampled bilinearly on a polar grid
   (angles over a half turn, radii in a bounded band: high radii carry mostly noise), each
   radius is weighted by a high-pass emphasis, and a phase correlation along the angle axis
   gives the rotation modulo 180 degrees.
3. **Translation.** Image ``a`` is turned by the candidate angle (bilinear, about the image
   centre) and phase-correlated with ``b``; the second candidate (angle + 180 degrees) is the same
   turned image flipped on both axes. The stronger correlation peak picks the candidate.
4. **Sub-pixel peak.** Every phase correlation whitens the cross-power spectrum and multiplies it
   by a Gaussian low-pass, so the correlation peak is a smooth Gaussian rather than a sinc; a
   soft-argmax in the log domain (the centroid of ``(c / c_max) ** (1 / T)`` over a small window
   around the integer peak) is then nearly unbiased, where ``softmax((c - max) / T)`` would be
   pulled toward the integer peak.

Convention (tested against OpenCV and scikit-image): pixel coordinates are ``p = (x, y)``, ``x``
the column index (right), ``y`` the row index (down), the centre ``c = ((W - 1) / 2, (H - 1) / 2)``.
:func:`register` returns ``rotation`` and ``translation`` such that the content at ``p`` in ``a``
is at ``R(rotation) (p - c) + c + translation`` in ``b``, with
``R(t) = [[cos t, sin t], [-sin t, cos t]]``: a positive rotation turns the image
counter-clockwise as displayed (row 0 on top), as ``cv2.getRotationMatrix2D`` and
``skimage.transform.rotate`` do. Translation is ``(x, y)`` in pixels.

* ``cv2.phaseCorrelate(a, b)`` returns ``(x, y)`` = our ``translation`` (same sign and order).
* ``skimage.registration.phase_cross_correlation(a, b)`` returns ``(row, col)`` =
  ``-translation[::-1]`` (the shift that registers ``b`` back onto ``a``).
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jbevo.geometry.angles import wrap_angle
from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.phase_correlation import (
    disk_window,
    estimate_rotation,
    rotate_image,
    translation_from_spectra,
    windowed,
)


class Registration(NamedTuple):
    """The result of :func:`register` (see the module docstring for the convention)."""

    rotation: Float[Array, "..."]  # radians in [-pi, pi)
    translation: Float[Array, "... 2"]  # (x, y) pixels
    confidence: Float[Array, "..."]  # in [0, 1]; ~0 for featureless input


def _check_pair(a: Array, b: Array, min_size: int = 16) -> None:
    if a.ndim < 2 or b.ndim < 2:
        raise ValueError(f"images must have shape (..., H, W), got a {a.shape} and b {b.shape}")
    if a.shape != b.shape:
        raise ValueError(f"images a and b must have the same shape, got {a.shape} and {b.shape}")
    if min(a.shape[-2:]) < min_size:
        raise ValueError(f"images must be at least {min_size}x{min_size} pixels, got {a.shape[-2:]}")


def _hw(image: Array) -> tuple[int, int]:
    """The (rows, columns) of one image."""
    return int(image.shape[0]), int(image.shape[1])


def _check_finite(image: Array, name: str) -> Array:
    return eqx.error_if(image, ~jnp.all(jnp.isfinite(image)), f"register: image {name} contains NaN or inf")


def _checked_batched(fn, a, b, params: DPCParams | None, *per_pair):
    """Check the shapes, promote to a float dtype, default the parameters, and vmap ``fn(a, b,
    params, *per_pair)`` over the leading batch axes (``per_pair``: arrays with those axes)."""
    params = DPCParams() if params is None else params
    a, b = jnp.asarray(a), jnp.asarray(b)
    _check_pair(a, b)
    dtype = jnp.result_type(a.dtype, b.dtype, jnp.float32)
    for _ in range(a.ndim - 2):
        fn = jax.vmap(fn, in_axes=(0, 0, None) + (0,) * len(per_pair))
    return fn(a.astype(dtype), b.astype(dtype), params, *per_pair)


def register_translation(
    a: Float[Array, "*batch H W"], b: Float[Array, "*batch H W"], params: DPCParams | None = None
) -> tuple[Float[Array, "*batch 2"], Float[Array, " *batch"]]:
    """Translation ``(x, y)`` in pixels carrying ``a`` onto ``b`` (no rotation), and confidence.

    Leading batch axes are vmapped.
    """
    return _checked_batched(_register_translation_pair, a, b, params)


def _register_translation_pair(a, b, params):
    a, b = _check_finite(a, "a"), _check_finite(b, "b")
    window = disk_window(_hw(a), params.window_taper, a.dtype)
    fa = jnp.fft.rfft2(windowed(a, window))
    fb = jnp.fft.rfft2(windowed(b, window))
    return translation_from_spectra(fa, fb, _hw(a), params)


def register(
    a: Float[Array, "*batch H W"],
    b: Float[Array, "*batch H W"],
    params: DPCParams | None = None,
    rotation_prior: Float[Array, "*batch"] | None = None,
    prior_window: float = np.radians(2.0),
) -> Registration:
    """Rotation (radians, ``[-pi, pi)``), translation ``(x, y)`` (pixels) and confidence that carry
    image ``a`` onto image ``b``; leading batch axes are vmapped.

    The rotation is found modulo 180 degrees from the magnitude spectra, and the full turn is
    resolved by correlating both candidates for the translation and keeping the stronger peak.
    ``confidence`` is the height of the chosen translation peak relative to a perfect match: about
    1 for identical content, about 0 for unrelated or featureless images.

    With a ``rotation_prior`` (radians; e.g. a gyro's turn between two frames), the rotation is
    searched within ``prior_window`` of it only, and the candidate 180 degrees away is never
    taken: a faint or noisy image (night) then cannot produce a gross rotation outlier, and one
    translation correlation instead of two makes it faster.

    Raises ``ValueError`` for shapes that are not ``(..., H, W)`` alike with ``H, W >= 16``; a NaN or
    inf in either image raises at run time (also under ``jit``).
    """
    if rotation_prior is None:
        return _checked_batched(_register_pair, a, b, params)
    prior = jnp.asarray(rotation_prior)
    if prior.shape != jnp.shape(a)[:-2]:
        raise ValueError(f"rotation_prior must have the batch shape {jnp.shape(a)[:-2]}, got {prior.shape}")
    return _checked_batched(lambda x, y, p, r: _register_pair_prior(x, y, p, r, prior_window), a, b, params, prior)


def _register_pair_prior(a, b, params, prior, window) -> Registration:
    a, b = _check_finite(a, "a"), _check_finite(b, "b")
    win = disk_window(_hw(a), params.window_taper, a.dtype)
    wa, wb = windowed(a, win), windowed(b, win)
    half_turn, _ = estimate_rotation(wa, wb, params, prior, window)
    # The candidate (half_turn or half_turn + pi) nearest the prior.
    flip = jnp.abs(wrap_angle(half_turn - prior)) > jnp.pi / 2
    turned = rotate_image(wa, half_turn)
    turned = jnp.where(flip, turned[::-1, ::-1], turned)
    t, c = translation_from_spectra(jnp.fft.rfft2(turned), jnp.fft.rfft2(wb), _hw(a), params)
    return Registration(wrap_angle(jnp.where(flip, half_turn + jnp.pi, half_turn)), t, c)


def _register_pair(a, b, params) -> Registration:
    a, b = _check_finite(a, "a"), _check_finite(b, "b")
    window = disk_window(_hw(a), params.window_taper, a.dtype)
    wa, wb = windowed(a, window), windowed(b, window)
    half_turn, _ = estimate_rotation(wa, wb, params)
    turned = rotate_image(wa, half_turn)
    fb = jnp.fft.rfft2(wb)
    t0, c0 = translation_from_spectra(jnp.fft.rfft2(turned), fb, _hw(a), params)
    t1, c1 = translation_from_spectra(jnp.fft.rfft2(turned[::-1, ::-1]), fb, _hw(a), params)
    flip = c1 > c0
    rotation = wrap_angle(jnp.where(flip, half_turn + jnp.pi, half_turn))
    return Registration(rotation, jnp.where(flip, t1, t0), jnp.where(flip, c1, c0))


__all__ = ["DPCParams", "Registration", "register", "register_translation"]
