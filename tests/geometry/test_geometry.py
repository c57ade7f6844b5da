import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.se2 import se2_between, se2_compose
from jbevo.geometry.sincos import sincos

# Exactness against independent references needs float64 (conftest's fixture).
pytestmark = pytest.mark.usefixtures("float64")

finite = st.floats(-50.0, 50.0, allow_nan=False)


@settings(deadline=None, max_examples=200)
@given(finite)
def test_wrap_angle_range_and_equivalence(a):
    w = float(wrap_angle(jnp.float64(a)))
    assert -np.pi <= w < np.pi + 1e-12
    assert abs(np.sin(w) - np.sin(a)) < 1e-9 and abs(np.cos(w) - np.cos(a)) < 1e-9


def test_wrap_angle_edges_and_gradient():
    np.testing.assert_allclose(wrap_angle(jnp.array([np.pi, -np.pi, 0.0, 3 * np.pi])), [-np.pi, -np.pi, 0.0, -np.pi])
    assert float(jax.grad(wrap_angle)(2.0)) == 1.0


@settings(deadline=None, max_examples=100)
@given(finite, finite, finite, finite, finite, finite)
def test_se2_between_inverts_compose(x, y, yaw, dx, dy, dyaw):
    pose = jnp.array([x, y, yaw])
    inc = jnp.array([dx, dy, float(wrap_angle(dyaw))])
    back = se2_between(pose, se2_compose(pose, inc))
    np.testing.assert_allclose(back, inc, atol=1e-9)


def test_se2_compose_frames():
    # facing +y (yaw = pi/2), moving 1 m forward and 1 m left ends at (-1, 1)
    out = se2_compose(jnp.array([0.0, 0.0, np.pi / 2]), jnp.array([1.0, 1.0, 0.0]))
    np.testing.assert_allclose(out, [-1.0, 1.0, np.pi / 2], atol=1e-12)


def test_sincos_matches_numpy_in_float64():
    rng = np.random.default_rng(0)
    quarter_turns = np.arange(-200, 201) * (np.pi / 2)
    x = np.concatenate(
        [
            rng.uniform(-1e5, 1e5, 200_000),
            rng.uniform(-7, 7, 100_000),
            quarter_turns,
            np.nextafter(quarter_turns, np.inf),
            [0.0, -0.0, 1e-300, np.pi / 4, -np.pi / 4],
        ]
    )
    s, c = jax.jit(sincos)(jnp.asarray(x))
    assert s.dtype == c.dtype == jnp.float64
    assert np.abs(np.asarray(s) - np.sin(x)).max() <= 2.3e-16
    assert np.abs(np.asarray(c) - np.cos(x)).max() <= 2.3e-16


def test_sincos_non_finite_and_other_dtypes():
    s, c = sincos(jnp.array([np.nan, np.inf, -np.inf]))
    assert np.isnan(s).all() and np.isnan(c).all()
    x32 = jnp.linspace(-10, 10, 101, dtype=jnp.float32)
    s, c = sincos(x32)
    assert s.dtype == jnp.float32
    np.testing.assert_array_equal(s, jnp.sin(x32))
    np.testing.assert_array_equal(c, jnp.cos(x32))


def test_sincos_derivatives_are_exact_under_jit_and_vmap():
    x = jnp.linspace(-20.0, 20.0, 37)
    ds, dc = jax.jit(jax.vmap(jax.jacfwd(sincos)))(x)
    np.testing.assert_allclose(ds, np.cos(np.asarray(x)), rtol=0, atol=2.3e-16)
    np.testing.assert_allclose(dc, -np.sin(np.asarray(x)), rtol=0, atol=2.3e-16)
    g = jax.grad(lambda a: jnp.sum(sincos(a)[0] * 2 + sincos(a)[1] ** 3))(x)
    expected = 2 * np.cos(x) - 3 * np.cos(x) ** 2 * np.sin(x)
    np.testing.assert_allclose(g, expected, rtol=0, atol=1e-15)
    h = 1e-6  # central differences of the polynomial itself, not just of the jvp rule
    fd = (np.asarray(sincos(x + h)[0]) - np.asarray(sincos(x - h)[0])) / (2 * h)
    np.testing.assert_allclose(fd, np.cos(x), atol=1e-9)
