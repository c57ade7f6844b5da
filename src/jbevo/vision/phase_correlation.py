"""The building blocks of DPC (:mod:`jbevo.vision.registration`): the disk window, image
rotation, the log-polar magnitude spectrum, whitened and low-passed correlations, and the
log-domain soft-argmax that finds their peaks to a fraction of a sample. Pure JAX."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax.scipy.ndimage import map_coordinates
from jaxtyping import Array, ArrayLike, Float

from jbevo.vision.dpc_params import DPCParams

_TINY = 1e-30  # keeps sqrt differentiable at exactly zero spectra


_WHITEN_EPS = 1e-6  # whitening regulariser relative to the mean cross-power magnitude


# Featureless input: an image whose windowed standard deviation is below ~1e-4 (intensities in
# [0, 1]) gives spectra below these floors, so it whitens to ~0 (confidence ~0) with bounded
# gradients instead of amplifying rounding noise to a unit spectrum.
_TEXTURE_FLOOR = 1e-4


_FLOOR = 1e-6  # smallest relative correlation value the log-domain centroid sees


_PEAK_MIN = 1e-20  # a correlation peak below this is no peak (featureless input)


#: Spectral bins at least this far from the origin (cycles per pixel) estimate the noise floor.
NOISE_BAND = 0.4
#: Samples of that band the noise floor's median is taken over.
NOISE_SAMPLES = 1024


def noise_power(spectrum: Array, shape: tuple[int, int]) -> Array:
    """The power ``|F|^2`` of white noise in an ``rfft2`` spectrum of an image of ``shape`` (its
    padded size): the median power of the bins at least :data:`NOISE_BAND` cycles per pixel from
    the origin, where images hold little of their own energy, over ``ln 2`` (the median of an
    exponential variable). Differentiable almost everywhere (through the median sample), so that
    gradients through DPC see how the floor follows the image."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    outer = np.flatnonzero(np.broadcast_to(np.hypot(fy, fx) >= NOISE_BAND, spectrum.shape))
    # The median of evenly spaced samples of the band: sorting all of it cost three times the
    # rest of a 256 x 256 registration; 1,024 samples estimate it to a few per cent.
    outer = outer[:: max(1, len(outer) // NOISE_SAMPLES)]
    flat = spectrum.reshape(-1)[outer]
    power = jnp.real(flat) ** 2 + jnp.imag(flat) ** 2
    return jnp.median(power) / np.log(2.0)


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


def rotate_image(
    image: Float[Array, "H W"], angle: Float[ArrayLike, ""], fill: Float[ArrayLike, ""] = 0.0
) -> Float[Array, "H W"]:
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
    """``log(|F| + n)`` of a windowed image, zero-padded by ``params.pad``, on the polar grid
    ``(radius, angle)`` with bilinear interpolation; ``n`` is the magnitude of the image's noise
    (:func:`noise_power`).

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
    # The magnitude the image's own noise gives, added inside the log: where the noise
    # dominates (high radii of a smooth image) log |F| is nearly flat along the angle and adds
    # little to the rotation's correlation, instead of the noise's fluctuations.
    # (The clamp keeps the square root's gradient finite where a featureless image has none.)
    noise = jnp.sqrt(jnp.maximum(noise_power(spectrum, (ph, pw)), _PEAK_MIN))
    floor = _TEXTURE_FLOOR * (h * w) ** 0.5 + noise
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


def signed_position(position: Array, n: int) -> Array:
    """Map a periodic position in ``[0, n)`` to ``[-n / 2, n / 2)``."""
    return jnp.mod(position + n / 2, n) - n / 2


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


def translation_from_spectra(fa: Array, fb: Array, shape: tuple[int, int], params: DPCParams):
    """The translation ``(x, y)`` (pixels) between two images given their ``rfft2`` spectra, and the
    peak's confidence relative to a perfect match."""
    corr, ideal = _translation_correlation(fa, fb, shape, params)
    temperature = jnp.exp(params.log_shift_temperature).astype(corr.dtype)
    pos, peak = soft_argmax_2d(corr, temperature, params.peak_half_width)
    h, w = shape
    translation = jnp.stack([signed_position(pos[1], w), signed_position(pos[0], h)])
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
        near = jnp.abs(signed_position(bins, n)) <= window * (n / jnp.pi)
        pos, peak = soft_argmax_1d(corr, temperature, params.peak_half_width, near)
    rotation = signed_position(pos, n) * (jnp.pi / n)
    return rotation, jnp.clip(peak / ideal, 0.0, 1.0)


__all__ = [
    "NOISE_BAND",
    "NOISE_SAMPLES",
    "disk_window",
    "estimate_rotation",
    "log_polar_spectrum",
    "noise_power",
    "rotate_image",
    "signed_position",
    "soft_argmax_1d",
    "soft_argmax_2d",
    "translation_from_spectra",
    "windowed",
]
