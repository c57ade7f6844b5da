import jax
import jax.numpy as jnp
import numpy as np
import pytest
from filterpy.kalman import JulierSigmaPoints, MerweScaledSigmaPoints
from hypothesis import given, settings
from hypothesis import strategies as st

from jbevo.filtering import linalg
from jbevo.filtering.unscented import (
    Julier,
    MerweScaled,
    circular_mean_fn,
    sigma_points,
    unscented_transform,
    wrapped_add_fn,
    wrapped_residual_fn,
)
from jbevo.geometry.angles import wrap_angle

# Exactness against independent references needs float64 (conftest's fixture).
pytestmark = pytest.mark.usefixtures("float64")


def random_gaussian(rng, n):
    a = rng.normal(size=(n, n))
    return jnp.asarray(rng.normal(size=n)), jnp.asarray(a @ a.T + 0.1 * np.eye(n))


@pytest.mark.parametrize(
    "scheme", [MerweScaled(), MerweScaled(1e-3, 2.0, 0.0), MerweScaled(np.sqrt(3), 2, 1), Julier(), Julier(0.5)]
)
@pytest.mark.parametrize("n", [1, 2, 3, 6])
def test_weights_sum_to_one(scheme, n):
    w = scheme.weights(n)
    assert w.mean.shape == (2 * n + 1,)
    # alpha = 1e-3 gives weights of order 1e6 that cancel: judge round-off against their size
    assert abs(float(jnp.sum(w.mean)) - 1.0) <= 1e-14 * float(jnp.sum(jnp.abs(w.mean))) + 1e-15


@pytest.mark.parametrize("n", [1, 3, 5])
def test_points_and_weights_match_filterpy(n):
    mean, cov = random_gaussian(np.random.default_rng(n), n)
    for ours, theirs in [
        (MerweScaled(0.5, 2.0, 1.0), MerweScaledSigmaPoints(n, 0.5, 2.0, 1.0)),
        (Julier(3.0 - n if n < 3 else 0.5), JulierSigmaPoints(n, 3.0 - n if n < 3 else 0.5)),
    ]:
        w = ours.weights(n)
        np.testing.assert_allclose(w.mean, theirs.Wm, rtol=1e-12)
        np.testing.assert_allclose(w.cov, theirs.Wc, rtol=1e-12)
        pts = sigma_points(mean, linalg.cholesky(cov), w.spread)
        np.testing.assert_allclose(pts, theirs.sigma_points(np.asarray(mean), np.asarray(cov)), atol=1e-12)


@settings(deadline=None, max_examples=40)
@given(
    n=st.integers(1, 5),
    m=st.integers(1, 4),
    alpha=st.floats(0.3, 2.0),
    beta=st.floats(0.0, 3.0),
    kappa=st.floats(0.0, 3.0),
    seed=st.integers(0, 2**31 - 1),
)
def test_linear_maps_are_exact(n, m, alpha, beta, kappa, seed):
    rng = np.random.default_rng(seed)
    mean, cov = random_gaussian(rng, n)
    a, b = jnp.asarray(rng.normal(size=(m, n))), jnp.asarray(rng.normal(size=m))
    r = unscented_transform(lambda x: a @ x + b, mean, cov, scheme=MerweScaled(alpha, beta, kappa))
    np.testing.assert_allclose(r.mean, a @ mean + b, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(r.cov, a @ cov @ a.T, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(r.cross_cov, cov @ a.T, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("mu,sigma", [(1.0, 0.5), (-2.0, 0.1), (0.0, 3.0), (10.0, 1e-3)])
def test_square_is_exact_with_kappa_two(mu, sigma):
    r = unscented_transform(
        lambda x: x**2, jnp.array([mu]), jnp.array([[sigma**2]]), scheme=MerweScaled(alpha=1.0, beta=0.0, kappa=2.0)
    )
    np.testing.assert_allclose(r.mean[0], mu**2 + sigma**2, rtol=1e-12)
    np.testing.assert_allclose(r.cov[0, 0], 4 * mu**2 * sigma**2 + 2 * sigma**4, rtol=1e-12)


def test_cholesky_input_equals_covariance_input_and_noise_is_added():
    mean, cov = random_gaussian(np.random.default_rng(3), 3)
    fn = lambda x: jnp.stack([jnp.sin(x[0]) * x[1], x[2] ** 3])
    noise = jnp.diag(jnp.array([0.1, 0.2]))
    r1 = unscented_transform(fn, mean, cov, noise_cov=noise)
    r2 = unscented_transform(fn, mean, chol=jnp.linalg.cholesky(cov), noise_cov=noise)
    r3 = unscented_transform(fn, mean, cov)
    for a, b in zip(r1, r2):
        np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(r1.cov - r3.cov, noise, atol=1e-12)


def test_angles_are_averaged_and_differenced_on_the_circle():
    # yaw near pi, sigma points on both sides of the cut: a linear map of (x, yaw) must stay
    # exact modulo 2 pi
    mean = jnp.array([1.0, np.pi - 0.01])
    cov = jnp.diag(jnp.array([0.04, 0.09]))
    kw = dict(
        mean_fn=circular_mean_fn([1]),
        residual_fn=wrapped_residual_fn([1]),
        input_residual_fn=wrapped_residual_fn([1]),
        input_add_fn=wrapped_add_fn([1]),
    )
    fn = lambda x: jnp.stack([2.0 * x[0], wrap_angle(x[1])])
    r = unscented_transform(fn, mean, cov, **kw)
    np.testing.assert_allclose(r.mean, [2.0, np.pi - 0.01], atol=1e-12)
    np.testing.assert_allclose(r.cov, np.diag([0.16, 0.09]), atol=1e-12)
    np.testing.assert_allclose(r.cross_cov, np.diag([0.08, 0.09]), atol=1e-12)
    naive = unscented_transform(fn, mean, cov)
    assert abs(float(naive.mean[1]) - float(r.mean[1])) > 0.5  # a linear mean is wrong here


def test_jit_vmap_grad():
    mean, cov = random_gaussian(np.random.default_rng(4), 2)
    f = jax.jit(lambda m, c: unscented_transform(jnp.sin, m, c).mean)
    batch = jax.vmap(f)(jnp.stack([mean, mean + 1]), jnp.stack([cov, cov]))
    np.testing.assert_allclose(batch[0], f(mean, cov), atol=1e-12)
    g = jax.grad(lambda c: jnp.sum(unscented_transform(jnp.sin, mean, c).cov))(cov)
    assert np.all(np.isfinite(g))


def test_bad_input_is_rejected(as_users_run):
    with pytest.raises(ValueError, match="exactly one"):
        unscented_transform(jnp.sin, jnp.zeros(2))
    with pytest.raises(ValueError, match="cov must have shape"):
        unscented_transform(jnp.sin, jnp.zeros(2), jnp.eye(3))
    with pytest.raises(ValueError, match="mean must have shape"):
        unscented_transform(jnp.sin, jnp.zeros((2, 2)), jnp.eye(2))
    with pytest.raises(ValueError, match="n \\+ lambda"):
        MerweScaled(alpha=0.1, kappa=-3.5).weights(3)
    with pytest.raises(ValueError, match="alpha"):
        MerweScaled(alpha=0.0)
    with pytest.raises(ValueError, match="angle_dims"):
        wrapped_residual_fn([5])(jnp.zeros(3), jnp.zeros(3))
