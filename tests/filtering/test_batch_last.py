"""vmap_last: the filters over a batch held in the last axis equal jax.vmap's results and
gradients, compile as one XLA:CPU kernel, and refuse what they cannot batch by name."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.planar import simulate_planar_sequence
from jbevo.filtering import smoother, sqrt_ukf, ukf
from jbevo.filtering.batch_last import vmap_last
from jbevo.filtering.planar import planar_pose_model
from tests.filtering.references import P0, Q, R

pytestmark = pytest.mark.usefixtures("float64")

BATCH, STEPS = 5, 40


def drives():
    """``BATCH`` drives across +-pi, with missing fix entries and a step without a fix."""
    keys = jax.random.split(jax.random.PRNGKey(3), BATCH)
    seqs = jax.vmap(lambda k: simulate_planar_sequence(k, STEPS, yaw_rate_std=0.3))(keys)
    fixes = seqs.fixes.at[:, 7].set(jnp.nan).at[:, 12:18, 1].set(jnp.nan)
    x0 = seqs.poses[:, 0] + jnp.array([0.5, -0.5, 0.05])
    return x0, seqs.increments, fixes


def run(form=ukf, smoothed=False):
    """``(x0, increments, fixes, q_scale) -> (means, covariances or factors, log-likelihood)``."""
    model = planar_pose_model()

    def one(x0, increments, fixes, q_scale):
        q = q_scale * jnp.asarray(Q)
        res = form.filter(
            model,
            ukf.GaussianState(x0, jnp.asarray(P0)),
            increments,
            fixes,
            q,
            jnp.asarray(R),
            one_kernel=False,
            check_inputs=False,
        )
        if smoothed:
            sm = smoother.smooth(model, res, increments, q, one_kernel=False)
            return sm.smoothed_mean, sm.smoothed_cov, res.log_likelihood
        return res[0], res[1], res.log_likelihood

    return one


def last(a):
    return jnp.moveaxis(a, 0, -1)


def first(a):
    return jnp.moveaxis(a, -1, 0)


@pytest.mark.parametrize(("form", "smoothed"), [(ukf, False), (sqrt_ukf, False), (ukf, True)], ids=["ukf", "sqrt", "smoother"])
def test_equals_vmap(form, smoothed):
    x0, u, z = drives()
    q = jnp.full(BATCH, 1.3)
    expected = jax.jit(jax.vmap(run(form, smoothed)))(x0, u, z, q)
    got = jax.jit(vmap_last(run(form, smoothed)))(last(x0), last(u), last(z), q)
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_allclose(first(b), a, rtol=1e-11, atol=1e-12)


def test_gradient_equals_vmap_and_finite_differences():
    x0, u, z = drives()
    fn = run()

    def total_vmap(scale):
        return jnp.sum(jax.vmap(fn, in_axes=(0, 0, 0, None))(x0, u, z, scale)[2])

    def total_last(scale):
        return jnp.sum(vmap_last(fn)(last(x0), last(u), last(z), jnp.full(BATCH, scale))[2])

    grad = jax.jit(jax.grad(total_last))(1.3)
    np.testing.assert_allclose(grad, jax.jit(jax.grad(total_vmap))(1.3), rtol=1e-10)
    eps = 1e-6
    fd = (total_last(1.3 + eps) - total_last(1.3 - eps)) / (2 * eps)
    np.testing.assert_allclose(grad, fd, rtol=1e-6)


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="the one-function call is XLA:CPU's")
def test_compiles_as_one_kernel():
    x0, u, z = drives()
    batched = jax.jit(vmap_last(run()))
    text = batched.lower(last(x0), last(u), last(z), jnp.ones(BATCH)).compile().as_text()
    assert 'xla_cpu_small_call="true"' in text


def test_a_large_batch_runs_in_groups_and_equals_vmap():
    # 129 sequences: the step's sums over sigma points exceed what one kernel can run
    # (cpu_kernel.LARGE_REDUCTION), so the batch runs as groups of 64 (the last one padded), each
    # one kernel.
    x0, increments, fixes = (jnp.tile(a, (26,) + (1,) * (a.ndim - 1))[:129] for a in drives())
    args = (x0, increments, fixes, jnp.full(129, 1.0))
    batched = jax.jit(vmap_last(run()))
    if jax.default_backend() == "cpu":
        assert 'xla_cpu_small_call="true"' in batched.lower(*map(last, args)).compile().as_text()
    for a, b in zip(batched(*map(last, args)), jax.vmap(run())(*args), strict=True):
        np.testing.assert_allclose(first(a), b, rtol=1e-9, atol=1e-12)


def test_nested_calls_and_checkpoints_equal_vmap():
    def fn(x, y):
        inner = jax.checkpoint(lambda a: jnp.sin(a) * y[0] + a[::-1] ** 2 + a[:1])
        return jax.jit(inner)(x), jnp.stack([x[0], y[1]])

    x, y = jax.random.normal(jax.random.PRNGKey(0), (2, 6, 4))
    x, y = x[:3], y[:2]
    expected = jax.vmap(fn, in_axes=-1, out_axes=-1)(x, y)
    for a, b in zip(expected, vmap_last(fn)(x, y), strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-14)


def test_refuses_what_it_cannot_batch():
    with pytest.raises(NotImplementedError, match="'sort'"):
        vmap_last(jnp.sort)(jnp.ones((4, 3)))
    with pytest.raises(NotImplementedError, match="'cholesky'"):
        vmap_last(jnp.linalg.cholesky)(jnp.ones((3, 3, 4)) + jnp.eye(3)[..., None])
    with pytest.raises(ValueError, match="same batch size"):
        vmap_last(jnp.add)(jnp.ones((4, 3)), jnp.ones((4, 2)))
