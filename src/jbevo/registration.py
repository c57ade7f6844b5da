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
from jax.scipy.ndimage import map_coordinates
from jaxtyping import Array, Float

from jbevo.geometry import wrap_angle

_TINY = 1e-30  # keeps sqrt differentiable at exactly zero spectra
_WHITEN_EPS = 1e-6  # whitening regulariser relative to the mean cross-power magnitude
# Featureless input: an image whose windowed standard deviation is below ~1e-4 (intensities in
# [0, 1]) gives spectra below these floors, so it whitens to ~0 (confidence ~0) with bounded
# gradients instead of amplifying rounding noise to a unit spectrum.
_TEXTURE_FLOOR = 1e-4
_FLOOR = 1e-6  # smallest relative correlation value the log-domain centroid sees
_PEAK_MIN = 1e-20  # a correlation peak below this is no peak (featureless input)


class DPCParams(eqx.Module):
    """The learnable parameters of DPC (array leaves) and its static settings.

    The defaults meet the accuracy targets of ``benchmarks/registration.py`` without training.
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


class Registration(NamedTuple):
    """The result of :func:`register` (see the module docstring for the convention)."""

    rotation: Float[Array, "..."]  # radians in [-pi, pi)
    translation: Float[Array, "... 2"]  # (x, y) pixels
    confidence: Float[Array, "..."]  # in [0, 1]; ~0 for featureless input


# ----------------------------------------------------------------------------- building blocks


def disk_window(shape: tuple[int, int], taper: float = 0.5, dtype=jnp.float32) -> Float[Array, "H W"]:
    """A radial Tukey window: 1 inside, a raised-cosine fall over the outer ``taper`` of the
    largest centred disk, 0 outside it."""
    h, w = shape
    y = jnp.arange(h, dtype=dtype) - (h - 1) / 2
    x = jnp.arange(w, dtype=dtype) - (w - 1) / 2
    radius = min(h, w) / 2
    r = jnp.sqrt(y[:, None] ** 2 + x[None, :] ** 2) / radius
    edge = 1.0 - taper
    fall = 0.5 * (1.0 + jnp.cos(jnp.pi * jnp.clip((r - edge) / taper, 0.0, 1.0)))
    return jnp.where(r <= edge, 1.0, fall).astype(dtype)


def windowed(image: Float[Array, "H W"], window: Float[Array, "H W"]) -> Float[Array, "H W"]:
    """``(image - weighted mean) * window``: zero outside the window, no DC leak."""
    mean = jnp.sum(image * window) / jnp.sum(window)
    return (image - mean) * window


def rotate_image(image: Float[Array, "H W"], angle: Float[Array, ""], fill: Array | float = 0.0) -> Float[Array, "H W"]:
    """``image`` turned by ``angle`` about its centre (positive: counter-clockwise as displayed),
    bilinear, ``fill`` outside."""
    h, w = image.shape
    y = jnp.arange(h, dtype=image.dtype) - (h - 1) / 2
    x = jnp.arange(w, dtype=image.dtype) - (w - 1) / 2
    c, s = jnp.cos(angle), jnp.sin(angle)
    # Output q = R (p - c) + c  =>  p - c = R^T (q - c), R = [[c, s], [-s, c]] on (x, y).
    px = c * x[None, :] - s * y[:, None]
    py = s * x[None, :] + c * y[:, None]
    coords = [py + (h - 1) / 2, px + (w - 1) / 2]
    return map_coordinates(image - fill, coords, order=1, mode="constant", cval=0.0) + fill


def _safe_norm(re: Array, im: Array) -> Array:
    """``|re + i im|``, differentiable at 0."""
    return jnp.sqrt(re**2 + im**2 + _TINY)


def _safe_abs(z: Array) -> Array:
    return _safe_norm(jnp.real(z), jnp.imag(z))


def _whiten(cross: Array, floor: float) -> Array:
    """``cross / |cross|``, regularised relative to its mean and by an absolute ``floor``."""
    mag = _safe_abs(cross)
    return cross / (mag + _WHITEN_EPS * jnp.mean(mag) + floor)


def log_polar_spectrum(image: Float[Array, "H W"], params: DPCParams) -> Float[Array, "R A"]:
    """``log |F|`` of a windowed image, zero-padded by ``params.pad``, on the polar grid
    ``(radius, angle)`` with bilinear interpolation.

    Angles run over ``[-90, 90)`` degrees (the half plane ``u >= 0`` that ``rfft2`` holds; the
    other half mirrors it), radii linearly over ``[min_radius, max_radius]`` cycles per pixel.
    """
    h, w = image.shape
    ph, pw = params.pad * h, params.pad * w
    # Zero-padded spectrum with the phase ramp of the image centre removed (as if the centre sat
    # at the origin): it is then smooth (oversampled by ``pad``), so bilinear interpolation of
    # the complex spectrum is accurate. Interpolating |F| or log |F| instead is not: their kinks
    # and log-singularities at spectral zeros make the interpolation error depend on the position
    # relative to the frequency lattice, which is the same for both images and pulls small
    # rotations toward 0 (by up to 0.35 deg at 96x96).
    spectrum = jnp.fft.rfft2(image, s=(ph, pw)) * _centre_ramp((h, w), (ph, pw), image.dtype)
    radii = _radii(params, image.dtype)
    angles = -jnp.pi / 2 + jnp.pi * jnp.arange(params.n_angles, dtype=image.dtype) / params.n_angles
    u = radii[:, None] * jnp.cos(angles)[None, :]
    v = radii[:, None] * jnp.sin(angles)[None, :]
    # Rows wrap (negative v sits at the end); columns stay inside since u <= max_radius < 1/2.
    coords = [v * ph, u * pw]
    re = map_coordinates(jnp.real(spectrum), coords, order=1, mode="wrap")
    im = map_coordinates(jnp.imag(spectrum), coords, order=1, mode="wrap")
    floor = _TEXTURE_FLOOR * (h * w) ** 0.5  # |F| of white noise of std 1e-4
    return jnp.log(_safe_norm(re, im) + floor)


def _centre_ramp(shape: tuple[int, int], padded: tuple[int, int], dtype) -> np.ndarray:
    """``exp(2 pi i k . c)`` for the centre ``c = (h // 2, w // 2)`` on the ``rfft2`` grid of
    ``padded``: a constant (numpy, built at trace time; in-graph complex exponentials cost more
    than the FFT)."""
    ky = np.fft.fftfreq(padded[0]) * (shape[0] // 2)
    kx = np.fft.rfftfreq(padded[1]) * (shape[1] // 2)
    ramp = np.exp(2j * np.pi * ky)[:, None] * np.exp(2j * np.pi * kx)[None, :]
    return ramp.astype(np.result_type(np.dtype(dtype), np.complex64))


def _radii(params: DPCParams, dtype) -> Array:
    return jnp.linspace(params.min_radius, params.max_radius, params.n_radii, dtype=dtype)


def _gaussian_lowpass(freqs: Array, sigma: Array) -> Array:
    """Fourier transform of a unit-area Gaussian of std ``sigma`` samples at ``freqs`` cycles per
    sample."""
    return jnp.exp(-2.0 * (jnp.pi * sigma * freqs) ** 2)


def _log_domain_weights(local: Array, temperature: Array) -> tuple[Array, Array]:
    """``(local / peak) ** (1 / T)`` over a window and the window's peak. The ratio is clipped to
    ``[_FLOOR, 1]`` and is all ``1`` (a flat window) when the peak is not positive; double-where:
    no ``0 / 0`` in the value or the gradient."""
    peak = jnp.max(local)
    positive = peak > _PEAK_MIN
    safe = jnp.where(positive, peak, 1.0)
    ratio = jnp.where(positive, jnp.clip(local / safe, _FLOOR, 1.0), 1.0)
    return jnp.exp(jnp.log(ratio) / temperature), peak


def soft_argmax_1d(
    c: Float[Array, " N"], temperature: Array, half_width: int, allowed: Array | None = None
) -> tuple[Array, Array]:
    """Sub-sample peak of a periodic signal: the log-domain centroid around the integer peak
    (the largest among the ``allowed`` samples, if given).

    Returns ``(position in [0, N), peak value)``.
    """
    n = c.shape[0]
    k = jnp.argmax(c if allowed is None else jnp.where(allowed, c, -jnp.inf))
    d = jnp.arange(-half_width, half_width + 1)
    weight, peak = _log_domain_weights(jnp.take(c, (k + d) % n), temperature)
    offset = jnp.sum(weight * d) / jnp.sum(weight)
    return jnp.mod(k + offset, n), peak


def soft_argmax_2d(c: Float[Array, "H W"], temperature: Array, half_width: int) -> tuple[Array, Array]:
    """2-D version of :func:`soft_argmax_1d`: ``((row, col) in [0, H) x [0, W), peak value)``."""
    h, w = c.shape
    k = jnp.argmax(c)
    kr, kc = k // w, k % w
    d = jnp.arange(-half_width, half_width + 1)
    weight, peak = _log_domain_weights(c[((kr + d) % h)[:, None], ((kc + d) % w)[None, :]], temperature)
    total = jnp.sum(weight)
    row = kr + jnp.sum(weight * d[:, None]) / total
    col = kc + jnp.sum(weight * d[None, :]) / total
    return jnp.stack([jnp.mod(row, h), jnp.mod(col, w)]), peak


def _signed(position: Array, n: int) -> Array:
    """Map a periodic position in ``[0, n)`` to ``[-n / 2, n / 2)``."""
    return jnp.mod(position + n / 2, n) - n / 2


# ----------------------------------------------------------------------------- correlations


def _translation_correlation(fa: Array, fb: Array, shape: tuple[int, int], params: DPCParams):
    """Low-passed whitened correlation of two rfft2 spectra and its ideal (perfect-match) peak."""
    h, w = shape
    dtype = fa.real.dtype
    sigma = jnp.exp(params.log_shift_peak_width).astype(dtype)
    fy = jnp.fft.fftfreq(h, dtype=dtype)[:, None]
    fx = jnp.fft.rfftfreq(w, dtype=dtype)[None, :]
    lowpass = _gaussian_lowpass(fy, sigma) * _gaussian_lowpass(fx, sigma)
    floor = _TEXTURE_FLOOR**2 * h * w
    corr = jnp.fft.irfft2(_whiten(fb * jnp.conj(fa), floor) * lowpass, s=shape)
    # irfft2 of the low-pass alone at 0: the peak of a perfect integer match.
    full_fx = jnp.fft.fftfreq(w, dtype=dtype)[None, :]
    ideal = jnp.sum(_gaussian_lowpass(fy, sigma) * _gaussian_lowpass(full_fx, sigma)) / (h * w)
    return corr, ideal


def _translation_from(fa: Array, fb: Array, shape: tuple[int, int], params: DPCParams):
    corr, ideal = _translation_correlation(fa, fb, shape, params)
    temperature = jnp.exp(params.log_shift_temperature).astype(corr.dtype)
    pos, peak = soft_argmax_2d(corr, temperature, params.peak_half_width)
    h, w = shape
    translation = jnp.stack([_signed(pos[1], w), _signed(pos[0], h)])
    confidence = jnp.clip(peak / ideal, 0.0, 1.0)
    return translation, confidence


def estimate_rotation(
    a: Float[Array, "H W"], b: Float[Array, "H W"], params: DPCParams, prior: Array | None = None, window: float = 0.0
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Rotation of ``b`` relative to ``a`` modulo 180 degrees, in ``[-pi/2, pi/2)``, and the angle
    peak's confidence. ``a`` and ``b`` must already be windowed (:func:`windowed`). With a
    ``prior`` rotation, the peak is searched within ``window`` radians of it (modulo 180
    degrees) only."""
    pa = log_polar_spectrum(a, params)
    pb = log_polar_spectrum(b, params)
    radii = _radii(params, a.dtype)
    weight = (radii / params.max_radius) ** params.highpass.astype(a.dtype) * jnp.exp(
        -0.5 * (radii / jnp.exp(params.log_radial_width).astype(a.dtype)) ** 2
    )
    fa = jnp.fft.rfft(pa, axis=1)
    fb = jnp.fft.rfft(pb, axis=1)
    cross = jnp.sum(weight[:, None] * fa * jnp.conj(fb), axis=0)
    n = params.n_angles
    sigma = jnp.exp(params.log_angle_peak_width).astype(a.dtype)
    lowpass = _gaussian_lowpass(jnp.fft.rfftfreq(n, dtype=a.dtype), sigma).at[0].set(0.0)
    floor = _TEXTURE_FLOOR**2 * n * n * params.n_radii
    corr = jnp.fft.irfft(_whiten(cross, floor) * lowpass, n=n)
    ideal = (jnp.sum(_gaussian_lowpass(jnp.fft.fftfreq(n, dtype=a.dtype), sigma)) - 1.0) / n
    temperature = jnp.exp(params.log_angle_temperature).astype(a.dtype)
    if prior is None:
        pos, peak = soft_argmax_1d(corr, temperature, params.peak_half_width)
    else:
        bins = jnp.arange(n, dtype=a.dtype) - prior.astype(a.dtype) * (n / jnp.pi)
        near = jnp.abs(_signed(bins, n)) <= window * (n / jnp.pi)
        pos, peak = soft_argmax_1d(corr, temperature, params.peak_half_width, near)
    rotation = _signed(pos, n) * (jnp.pi / n)
    return rotation, jnp.clip(peak / ideal, 0.0, 1.0)


# ----------------------------------------------------------------------------- public API


def _check_pair(a: Array, b: Array, min_size: int = 16) -> None:
    if a.ndim < 2 or b.ndim < 2:
        raise ValueError(f"images must have shape (..., H, W), got a {a.shape} and b {b.shape}")
    if a.shape != b.shape:
        raise ValueError(f"images a and b must have the same shape, got {a.shape} and {b.shape}")
    if min(a.shape[-2:]) < min_size:
        raise ValueError(f"images must be at least {min_size}x{min_size} pixels, got {a.shape[-2:]}")


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
    window = disk_window(a.shape, params.window_taper, a.dtype)
    fa = jnp.fft.rfft2(windowed(a, window))
    fb = jnp.fft.rfft2(windowed(b, window))
    return _translation_from(fa, fb, a.shape, params)


def register(
    a: Float[Array, "*batch H W"], b: Float[Array, "*batch H W"], params: DPCParams | None = None,
    rotation_prior: Float[Array, "*batch"] | None = None, prior_window: float = np.radians(2.0),
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
    win = disk_window(a.shape, params.window_taper, a.dtype)
    wa, wb = windowed(a, win), windowed(b, win)
    half_turn, _ = estimate_rotation(wa, wb, params, prior, window)
    # The candidate (half_turn or half_turn + pi) nearest the prior.
    flip = jnp.abs(wrap_angle(half_turn - prior)) > jnp.pi / 2
    turned = rotate_image(wa, half_turn)
    turned = jnp.where(flip, turned[::-1, ::-1], turned)
    t, c = _translation_from(jnp.fft.rfft2(turned), jnp.fft.rfft2(wb), a.shape, params)
    return Registration(wrap_angle(jnp.where(flip, half_turn + jnp.pi, half_turn)), t, c)


def _register_pair(a, b, params) -> Registration:
    a, b = _check_finite(a, "a"), _check_finite(b, "b")
    window = disk_window(a.shape, params.window_taper, a.dtype)
    wa, wb = windowed(a, window), windowed(b, window)
    half_turn, _ = estimate_rotation(wa, wb, params)
    turned = rotate_image(wa, half_turn)
    fb = jnp.fft.rfft2(wb)
    t0, c0 = _translation_from(jnp.fft.rfft2(turned), fb, a.shape, params)
    t1, c1 = _translation_from(jnp.fft.rfft2(turned[::-1, ::-1]), fb, a.shape, params)
    flip = c1 > c0
    rotation = wrap_angle(jnp.where(flip, half_turn + jnp.pi, half_turn))
    return Registration(rotation, jnp.where(flip, t1, t0), jnp.where(flip, c1, c0))


__all__ = [
    "DPCParams",
    "Registration",
    "disk_window",
    "estimate_rotation",
    "log_polar_spectrum",
    "register",
    "register_translation",
    "rotate_image",
    "soft_argmax_1d",
    "soft_argmax_2d",
    "windowed",
]

