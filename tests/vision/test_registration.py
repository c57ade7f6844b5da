"""DPC registration: conventions against OpenCV and scikit-image, accuracy on real textures,
the 180-degree disambiguation, batching, featureless and malformed input, and gradients.

Images are 96x96 crops of scikit-image's CC0 photos (small, so the suite stays fast); the
accuracy figures on 256x256 pairs are in benchmarks/registration.py.
"""

import cv2
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.ndimage as ndi
import skimage.data
from skimage.registration import phase_cross_correlation

from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.phase_correlation import rotate_image, soft_argmax_1d
from jbevo.vision.registration import register, register_translation

SIZE = 96
FAST = DPCParams(n_angles=256, n_radii=32)


def photo(name: str) -> np.ndarray:
    """A 2x-downsampled scikit-image photo, intensities in [0, 1] (256x256)."""
    im = getattr(skimage.data, name)().astype(np.float64) / 255.0
    return im[::2, ::2]


def warp(full: np.ndarray, angle: float, shift, size: int = SIZE) -> np.ndarray:
    """Central crop of ``full`` after moving content at p to R(angle)(p - c) + c + shift."""
    c = (full.shape[0] - 1) / 2
    co, si = np.cos(angle), np.sin(angle)
    m = np.array([[co, si], [-si, co]])
    offset = np.array([c, c]) - m @ np.array([c + shift[1], c + shift[0]])
    out = ndi.affine_transform(full, m, offset=offset, order=3, mode="reflect")
    s = (full.shape[0] - size) // 2
    return out[s : s + size, s : s + size]


def crop(full: np.ndarray, size: int = SIZE) -> np.ndarray:
    s = (full.shape[0] - size) // 2
    return full[s : s + size, s : s + size]


def angle_diff(a, b):
    return np.abs((np.asarray(a) - b + np.pi) % (2 * np.pi) - np.pi)


register_jit = jax.jit(register)
register_translation_jit = jax.jit(register_translation)


@pytest.fixture(scope="module")
def gravel():
    return photo("gravel")


def test_fourier_shift_integer_and_subpixel(gravel):
    a = crop(gravel)
    fy = np.fft.fftfreq(SIZE)[:, None]
    fx = np.fft.fftfreq(SIZE)[None, :]
    for shift in [(3.0, -7.0), (0.37, 0.0), (-4.25, 2.6), (12.5, -11.5)]:
        b = np.real(np.fft.ifft2(np.fft.fft2(a) * np.exp(-2j * np.pi * (fx * shift[0] + fy * shift[1]))))
        t, conf = register_translation_jit(jnp.float32(a), jnp.float32(b))
        np.testing.assert_allclose(t, shift, atol=0.03)
        assert conf > 0.4


def test_real_subpixel_shifts(gravel):
    rng = np.random.default_rng(1)
    shifts = rng.uniform(-8, 8, (8, 2))
    a = np.stack([crop(gravel)] * len(shifts))
    b = np.stack([warp(gravel, 0.0, s) for s in shifts])
    t, conf = register_translation_jit(jnp.float32(a), jnp.float32(b))
    err = np.linalg.norm(np.asarray(t) - shifts, axis=1)
    assert np.median(err) < 0.03 and err.max() < 0.08, err
    assert np.all(np.asarray(conf) > 0.5)


def test_sign_convention_matches_cv2_and_is_opposite_to_skimage(gravel):
    a = crop(gravel)
    b = warp(gravel, 0.0, (4.3, -2.6))
    t, _ = register_translation_jit(jnp.float32(a), jnp.float32(b))
    window = cv2.createHanningWindow((SIZE, SIZE), cv2.CV_32F)
    (cx, cy), _ = cv2.phaseCorrelate(np.float32(a), np.float32(b), window)
    (sr, sc), _, _ = phase_cross_correlation(a, b, upsample_factor=20)
    np.testing.assert_allclose(t, [4.3, -2.6], atol=0.05)
    np.testing.assert_allclose(t, [cx, cy], atol=0.4)  # cv2: same order and sign, biased peak
    np.testing.assert_allclose(t, [-sc, -sr], atol=0.2)  # skimage: (row, col), opposite sign


@pytest.mark.parametrize("name", ["grass", "brick", "camera"])
def test_rotations_over_the_full_turn(name):
    full = photo(name)
    angles = np.radians([0.0, 0.02, -0.3, 37.0, 89.9, 90.0, -90.0, 179.5, 180.0, -179.5, 120.0, -145.0])
    rng = np.random.default_rng(2)
    shifts = rng.uniform(-5, 5, (len(angles), 2))
    a = np.stack([crop(full)] * len(angles))
    b = np.stack([warp(full, ang, s) for ang, s in zip(angles, shifts)])
    r = register_jit(jnp.float32(a), jnp.float32(b))
    assert np.all(np.asarray(r.rotation) >= -np.pi) and np.all(np.asarray(r.rotation) < np.pi)
    err_deg = np.degrees(angle_diff(r.rotation, angles))
    err_px = np.linalg.norm(np.asarray(r.translation) - shifts, axis=1)
    assert err_deg.max() < 0.12, err_deg
    assert err_px.max() < 0.3, err_px
    assert np.all(np.asarray(r.confidence) > 0.3)


def test_half_turn_is_disambiguated(gravel):
    # The magnitude spectra of theta and theta + 180 deg are identical; the translation peak
    # must pick the right one for both.
    a = crop(gravel)
    for angle in (0.7, 0.7 - np.pi):
        b = warp(gravel, angle, (2.0, -3.0))
        r = register_jit(jnp.float32(a), jnp.float32(b))
        assert np.degrees(angle_diff(r.rotation, angle)) < 0.1
        np.testing.assert_allclose(r.translation, [2.0, -3.0], atol=0.2)


def test_rotation_sign_matches_cv2(gravel):
    angle_deg = 25.0
    c = (gravel.shape[0] - 1) / 2
    m = cv2.getRotationMatrix2D((c, c), angle_deg, 1.0)  # counter-clockwise as displayed
    b = crop(cv2.warpAffine(np.float32(gravel), m, gravel.shape[::-1], flags=cv2.INTER_CUBIC))
    r = register_jit(jnp.float32(crop(gravel)), jnp.float32(b))
    assert abs(np.degrees(r.rotation) - angle_deg) < 0.1
    np.testing.assert_allclose(r.translation, [0.0, 0.0], atol=0.2)


def test_rotate_image_turns_counter_clockwise():
    image = jnp.zeros((33, 33)).at[16, 30].set(1.0)  # a dot right of the centre
    turned = rotate_image(image, jnp.pi / 2)
    assert np.unravel_index(np.argmax(turned), turned.shape) == (2, 16)  # now above it


def test_batch_equals_per_pair(gravel):
    rng = np.random.default_rng(3)
    angles = rng.uniform(-np.pi, np.pi, 4)
    a = np.stack([crop(gravel)] * 4)
    b = np.stack([warp(gravel, ang, rng.uniform(-4, 4, 2)) for ang in angles])
    batch = register_jit(jnp.float32(a), jnp.float32(b), FAST)
    for i in range(4):
        one = register_jit(jnp.float32(a[i]), jnp.float32(b[i]), FAST)
        for x, y in zip(batch, one):
            np.testing.assert_allclose(x[i], y, rtol=1e-5, atol=1e-5)
    nested = register_jit(jnp.float32(a).reshape(2, 2, SIZE, SIZE), jnp.float32(b).reshape(2, 2, SIZE, SIZE), FAST)
    np.testing.assert_allclose(nested.rotation.reshape(4), batch.rotation, rtol=1e-5, atol=1e-6)


def test_odd_and_rectangular_shapes(gravel):
    a = crop(gravel, 96)[:95, :81]
    b = warp(gravel, 0.0, (1.5, -2.25))[:95, :81]
    t, conf = register_translation(jnp.float32(a), jnp.float32(b))
    np.testing.assert_allclose(t, [1.5, -2.25], atol=0.08)
    r = register(jnp.float32(a), jnp.float32(warp(gravel, 0.4, (1.5, -2.25))[:95, :81]), FAST)
    assert np.degrees(angle_diff(r.rotation, 0.4)) < 0.3


def test_featureless_images_give_finite_output_low_confidence_and_finite_gradients(gravel):
    flat = jnp.full((SIZE, SIZE), 0.5, jnp.float32)
    textured = jnp.float32(crop(gravel))

    @jax.jit
    def value_and_grad(a, b):
        def loss(b):
            r = register(a, b, FAST)
            return jnp.sum(r.translation) + r.rotation + r.confidence, r

        return jax.grad(loss, has_aux=True)(b)

    for a, b in [(flat, flat), (textured, flat), (flat, textured), (jnp.zeros_like(flat), jnp.zeros_like(flat))]:
        grad, r = value_and_grad(a, b)
        for x in r:
            assert np.all(np.isfinite(x))
        assert r.confidence < 0.05
        assert np.all(np.isfinite(grad))
    t, conf = register_translation(flat, flat)
    assert np.all(np.isfinite(t)) and conf < 0.05


def test_unrelated_images_have_low_confidence():
    a = jnp.float32(crop(photo("gravel")))
    b = jnp.float32(crop(photo("brick")))
    assert register(a, b, FAST).confidence < 0.3
    assert register(a, a, FAST).confidence > 0.9


def test_bad_input_is_named(as_users_run):
    good = jnp.zeros((32, 32))
    with pytest.raises(ValueError, match="same shape"):
        register(good, jnp.zeros((32, 31)))
    with pytest.raises(ValueError, match=r"\(\.\.\., H, W\)"):
        register(jnp.zeros(32), jnp.zeros(32))
    with pytest.raises(ValueError, match="at least 16x16"):
        register_translation(jnp.zeros((8, 8)), jnp.zeros((8, 8)))
    with pytest.raises(ValueError, match="min_radius"):
        DPCParams(min_radius=0.4, max_radius=0.3)
    nan = good.at[3, 4].set(jnp.nan)
    with pytest.raises(Exception, match="image b contains NaN or inf"):
        register(good, nan)
    with pytest.raises(Exception, match="image a contains NaN or inf"):
        jax.jit(register_translation)(nan, good)
    with pytest.raises(ValueError, match="rotation_prior"):
        register(jnp.zeros((32, 32), jnp.float32), jnp.zeros((32, 32), jnp.float32), rotation_prior=jnp.zeros(3))


def test_soft_argmax_is_unbiased_on_a_gaussian_peak():
    n = 64
    for true in (10.0, 10.3, 10.5, 63.8):
        d = (np.arange(n) - true + n / 2) % n - n / 2
        c = jnp.asarray(np.exp(-0.5 * d**2))
        pos, peak = soft_argmax_1d(c, jnp.asarray(0.5), 4)
        assert abs((float(pos) - true + n / 2) % n - n / 2) < 1e-3
        # The plain softmax soft-argmax is pulled toward the integer peak.
        k = np.argmax(c)
        w = np.exp((np.asarray(c) - c.max()) / 0.1)
        plain = k + np.sum(w * (((np.arange(n) - k) + n / 2) % n - n / 2)) / np.sum(w)
        if true % 1 not in (0.0, 0.5):
            assert abs(plain - true) > 0.05


# ----------------------------------------------------------------------------- gradients


def smooth_texture(seed: int, size: int = 48) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return ndi.gaussian_filter(rng.normal(size=(size + 32, size + 32)), 2.5)


def smooth_pair():
    full = smooth_texture(0)
    full = (full - full.min()) / (full.max() - full.min())
    a = warp(full, 0.0, (0.0, 0.0), 48)
    b = warp(full, 0.3, (1.3, -0.7), 48)
    return jnp.asarray(a), jnp.asarray(b)


SMALL = DPCParams(n_angles=128, n_radii=16)


def outputs(r):
    return jnp.concatenate([jnp.atleast_1d(r.rotation), r.translation, jnp.atleast_1d(r.confidence)])


def test_gradients_are_finite_for_the_image_and_every_parameter():
    a, b = smooth_pair()
    a32, b32 = a.astype(jnp.float32), b.astype(jnp.float32)
    g_img = jax.jit(jax.grad(lambda b: jnp.sum(outputs(register(a32, b, SMALL)))))(b32)
    assert np.all(np.isfinite(g_img)) and np.any(g_img != 0)
    g = eqx.filter_jit(eqx.filter_grad(lambda p: jnp.sum(outputs(register(a32, b32, p)))))(SMALL)
    leaves = jax.tree_util.tree_leaves(g)
    assert len(leaves) == 6
    for leaf in leaves:
        assert np.all(np.isfinite(leaf))
    assert sum(float(jnp.abs(leaf)) > 0 for leaf in leaves) >= 5
    gt = eqx.filter_jit(eqx.filter_grad(lambda p: jnp.sum(register_translation(a32, b32, p)[0])))(SMALL)
    assert np.all(np.isfinite(gt.log_shift_peak_width)) and np.all(np.isfinite(gt.log_shift_temperature))


def central_difference(f, x, v, h):
    return (f(x + h * v) - f(x - h * v)) / (2 * h)


def test_jvp_matches_finite_differences_for_the_image(float64):
    a, b = smooth_pair()  # float64 (x64 is on in the tests): FD is not drowned by rounding
    rng = np.random.default_rng(5)
    v = jnp.asarray(ndi.gaussian_filter(rng.normal(size=b.shape), 2.0))

    @jax.jit
    def f(b):
        return outputs(register(a, b, SMALL))

    _, jvp = jax.jit(lambda b, v: jax.jvp(f, (b,), (v,)))(b, v)
    fd = central_difference(f, b, v, 1e-4)
    np.testing.assert_allclose(jvp, fd, rtol=0.05, atol=1e-3 * float(jnp.max(jnp.abs(fd))))
    assert np.any(np.abs(np.asarray(jvp)) > 1e-3)


@pytest.mark.parametrize(
    "leaf",
    [
        "log_angle_temperature",
        "log_shift_temperature",
        "log_angle_peak_width",
        "log_shift_peak_width",
        "highpass",
        "log_radial_width",
    ],
)
def test_jvp_matches_finite_differences_for_each_parameter(float64, leaf):
    a, b = smooth_pair()
    params = jax.tree_util.tree_map(lambda x: x.astype(jnp.float64), SMALL)

    def f(value):
        p = eqx.tree_at(lambda p: getattr(p, leaf), params, value)
        return outputs(register(a, b, p))

    x = getattr(params, leaf)
    _, jvp = jax.jvp(f, (x,), (jnp.ones_like(x),))
    fd = central_difference(f, x, jnp.ones_like(x), 1e-5)
    scale = float(jnp.max(jnp.abs(fd)))
    assert scale > 0, "the parameter has no effect"
    np.testing.assert_allclose(jvp, fd, rtol=0.05, atol=0.02 * scale)


def test_rotation_prior_searches_near_it_and_picks_the_half_turn(gravel):
    """With a prior, the angle peak is searched within the window only and the candidate 180 deg
    from the prior is never taken; near the truth it gives what the free search gives."""
    from jbevo.vision.registration import register

    a = crop(gravel)
    b = warp(gravel, 0.05, (2.0, -3.0))
    free = register(jnp.float32(a), jnp.float32(b))
    near = register(jnp.float32(a), jnp.float32(b), rotation_prior=jnp.float32(0.06))
    assert abs(float(near.rotation) - float(free.rotation)) < 1e-4
    np.testing.assert_allclose(near.translation, free.translation, atol=1e-3)
    # A prior 10 deg off with a 2 deg window cannot reach the true peak: it lands in the window.
    off = register(jnp.float32(a), jnp.float32(b), rotation_prior=jnp.float32(0.05 + np.radians(10)))
    assert np.degrees(abs(float(off.rotation) - (0.05 + np.radians(10)))) <= 2.0 + 0.5
    flipped = register(
        jnp.float32(a), jnp.float32(warp(gravel, 0.05 - np.pi, (2.0, -3.0))), rotation_prior=jnp.float32(0.05 - np.pi)
    )
    assert np.degrees(angle_diff(flipped.rotation, 0.05 - np.pi)) < 0.1
    batch = register(jnp.stack([jnp.float32(a)] * 2), jnp.stack([jnp.float32(b)] * 2), rotation_prior=jnp.float32([0.06, 0.04]))
    assert batch.rotation.shape == (2,)


def test_noise_power_estimates_white_noise_and_ignores_smooth_content():
    """The noise floor DPC's rotation spectrum adds is the power white noise gives a spectrum bin
    (sigma^2 times the window's energy), whether or not the image also holds smooth content."""
    from jbevo.vision.phase_correlation import disk_window, noise_power, windowed

    rng = np.random.default_rng(0)
    window = disk_window((128, 128))
    smooth = np.add.outer(np.sin(np.arange(128) / 9.0), np.cos(np.arange(128) / 13.0))
    for sigma in (0.01, 0.05):
        for content in (0.0, 1.0):
            image = jnp.float32(content * smooth + rng.normal(0, sigma, (128, 128)))
            spectrum = jnp.fft.rfft2(windowed(image, window))
            expected = sigma**2 * float(jnp.sum(window**2))
            assert float(noise_power(spectrum, (128, 128))) == pytest.approx(expected, rel=0.1)
