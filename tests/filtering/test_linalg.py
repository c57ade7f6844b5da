import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.filtering import linalg

# Exactness against independent references needs float64 (conftest's fixture).
pytestmark = pytest.mark.usefixtures("float64")


def random_spd(rng, n, batch=()):
    a = rng.normal(size=batch + (n, n))
    return a @ np.swapaxes(a, -1, -2) + n * np.eye(n)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 10])
def test_cholesky_and_solves_match_numpy(n):
    rng = np.random.default_rng(n)
    a = random_spd(rng, n)
    b = rng.normal(size=(n, 4))
    low = linalg.cholesky(jnp.asarray(a))
    np.testing.assert_allclose(low, np.linalg.cholesky(a), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(linalg.solve_lower(low, b), np.linalg.solve(np.linalg.cholesky(a), b), atol=1e-12)
    np.testing.assert_allclose(linalg.cho_solve(low, b), np.linalg.solve(a, b), atol=1e-12)
    x, logdet = linalg.whiten(jnp.asarray(a), jnp.asarray(b))
    np.testing.assert_allclose(x, np.linalg.solve(np.linalg.cholesky(a), b), atol=1e-12)
    np.testing.assert_allclose(logdet, np.linalg.slogdet(a)[1], rtol=1e-12)
    np.testing.assert_allclose(linalg.logdet_from_cholesky(low), np.linalg.slogdet(a)[1], rtol=1e-12)


def test_general_solve_pivots_and_matches_numpy_with_its_gradient():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(40, 4, 4)) + 4 * np.eye(4)
    # Zero leading pivots: elimination without row exchanges would divide by zero.
    a[0] = [[0.0, 1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 1.0], [2.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]
    a[1] = np.eye(4)[[3, 2, 1, 0]]
    b = rng.normal(size=(40, 4, 2))
    np.testing.assert_allclose(linalg.solve(jnp.asarray(a), jnp.asarray(b)), np.linalg.solve(a, b), rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(linalg.solve(a[2, :1, :1], b[2, :1]), b[2, :1] / a[2, 0, 0], rtol=1e-14)
    loss = lambda f: lambda m: jnp.sum(jnp.sin(f(m, jnp.asarray(b))))
    np.testing.assert_allclose(
        jax.grad(loss(linalg.solve))(jnp.asarray(a)), jax.grad(loss(jnp.linalg.solve))(jnp.asarray(a)), rtol=1e-9, atol=1e-10
    )


def test_batched_and_vmapped_agree():
    rng = np.random.default_rng(0)
    a = jnp.asarray(random_spd(rng, 3, (5, 2)))
    batched = linalg.cholesky(a)
    mapped = jax.vmap(jax.vmap(linalg.cholesky))(a)
    np.testing.assert_allclose(batched, mapped, atol=1e-14)
    np.testing.assert_allclose(batched, np.linalg.cholesky(np.asarray(a)), atol=1e-12)


def test_singular_input_gives_finite_factor_and_gradient():
    v = jnp.array([1.0, 2.0, 3.0])
    a = jnp.outer(v, v)  # rank one
    low = linalg.cholesky(a)
    assert np.all(np.isfinite(low))
    np.testing.assert_allclose(low @ low.T, a, atol=1e-5)
    grad = jax.grad(lambda s: jnp.sum(linalg.cholesky(s * a + 1e-30 * jnp.eye(3))))(1.0)
    assert np.isfinite(grad)
    x, logdet = linalg.whiten(a, jnp.ones((3, 1)))
    assert np.all(np.isfinite(x)) and np.isfinite(logdet)


def test_is_positive_definite():
    assert bool(linalg.is_positive_definite(jnp.eye(3)))
    assert not bool(linalg.is_positive_definite(jnp.diag(jnp.array([1.0, 0.0, 1.0]))))
    assert not bool(linalg.is_positive_definite(jnp.diag(jnp.array([1.0, -1.0, 1.0]))))
    assert not bool(linalg.is_positive_definite(jnp.array([[1.0, jnp.nan], [jnp.nan, 1.0]])))
    assert not bool(linalg.is_positive_definite(jnp.array([[1.0, 0.5], [0.0, 1.0]])))  # not symmetric
    batch = jnp.stack([jnp.eye(2), -jnp.eye(2)])
    np.testing.assert_array_equal(linalg.is_positive_definite(batch), [True, False])


def test_float32_runs_in_float32():
    a = jnp.asarray(random_spd(np.random.default_rng(1), 3), jnp.float32)
    assert linalg.cholesky(a).dtype == jnp.float32
    x, logdet = linalg.whiten(a, jnp.ones((3, 2), jnp.float32))
    assert x.dtype == jnp.float32 and logdet.dtype == jnp.float32
