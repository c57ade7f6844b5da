"""The parallel-in-time Kalman filter and RTS smoother of an affine model: equal to the sequential
recursion and to filterpy's KalmanFilter (time-varying model, offsets, missing entries), under
jit and vmap, with gradients that match finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from jbevo.filtering import parallel
from jbevo.filtering.ukf import GaussianState
from tests.helpers import check_leaf_gradients

pytestmark = pytest.mark.usefixtures("float64")

# Compiled once and shared: run eagerly, every level of the associative scan dispatches (and
# compiles) its small operations one by one. One length for every test, not a power of two.
STEPS = 33
parallel_filter, parallel_smooth = jax.jit(parallel.filter), jax.jit(parallel.smooth)
sequential_filter, sequential_smoother = jax.jit(parallel.sequential_filter), jax.jit(parallel.sequential_smoother)


def spd(rng, k, scale):
    a = rng.normal(size=(k, k))
    return scale * (a @ a.T / k + 0.2 * np.eye(k))


def random_model(steps=STEPS, n=3, m=2, seed=0):
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(steps, m))
    z[10] = np.nan  # a step without a measurement
    z[11:20, 0] = np.nan  # a partial gap
    return parallel.AffineModel(
        transition=jnp.asarray(np.stack([np.eye(n) + 0.1 * rng.normal(size=(n, n)) for _ in range(steps)])),
        transition_offset=jnp.asarray(0.1 * rng.normal(size=(steps, n))),
        transition_cov=jnp.asarray(np.stack([spd(rng, n, 0.05) for _ in range(steps)])),
        observation=jnp.asarray(rng.normal(size=(steps, m, n))),
        observation_offset=jnp.asarray(0.1 * rng.normal(size=(steps, m))),
        observation_cov=jnp.asarray(np.stack([spd(rng, m, 0.5) for _ in range(steps)])),
        measurements=jnp.asarray(z),
    ), GaussianState(jnp.asarray(rng.normal(size=n)), jnp.asarray(spd(rng, n, 1.0)))


def filterpy_reference(model, prior):
    """filterpy's KalmanFilter step by step (offsets as a control and a shifted measurement,
    missing entries by dropping their rows), then its RTS smoother."""
    steps, m, n = model.observation.shape
    kf = KalmanFilter(n, m)
    kf.x, kf.P = np.asarray(prior.mean).copy(), np.asarray(prior.cov).copy()
    means, covs = [], []
    for t in range(steps):
        kf.predict(
            u=np.asarray(model.transition_offset[t]),
            B=np.eye(n),
            F=np.asarray(model.transition[t]),
            Q=np.asarray(model.transition_cov[t]),
        )
        z = np.asarray(model.measurements[t])
        keep = np.isfinite(z)
        if keep.any():
            kf.dim_z = int(keep.sum())
            h = np.asarray(model.observation[t])[keep]
            r = np.asarray(model.observation_cov[t])[np.ix_(keep, keep)]
            kf.update(z[keep] - np.asarray(model.observation_offset[t])[keep], R=r, H=h)
        means.append(kf.x.copy())
        covs.append(kf.P.copy())
    means, covs = np.array(means), np.array(covs)
    # filterpy's rts_smoother moves from step k to k + 1 with Fs[k + 1] and Qs[k + 1].
    fs, qs = np.asarray(model.transition), np.asarray(model.transition_cov)
    # Offsets shift the prediction; smooth the offset-free residual form: x_t - o_t, where o
    # follows the offsets through the transitions, is a model without offsets.
    o = np.zeros((steps, n))
    for t in range(1, steps):
        o[t] = np.asarray(model.transition[t]) @ o[t - 1] + np.asarray(model.transition_offset[t])
    s_means, s_covs, _, _ = kf.rts_smoother(means - o, covs, Fs=fs, Qs=qs)
    return means, covs, s_means + o, s_covs


def test_parallel_equals_sequential_and_filterpy():
    model, prior = random_model()
    par = parallel_filter(model, prior)
    seq = sequential_filter(model, prior)
    for a, b in zip(par, seq, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-11)
    means, covs, s_means, s_covs = filterpy_reference(model, prior)
    np.testing.assert_allclose(par.filtered_mean, means, atol=1e-10)
    np.testing.assert_allclose(par.filtered_cov, covs, atol=1e-10)
    smoothed, sequential = parallel_smooth(model, par), sequential_smoother(model, seq)
    np.testing.assert_allclose(smoothed.mean, sequential.mean, atol=1e-11)
    np.testing.assert_allclose(smoothed.cov, sequential.cov, atol=1e-11)
    np.testing.assert_allclose(smoothed.mean, s_means, atol=1e-9)
    np.testing.assert_allclose(smoothed.cov, s_covs, atol=1e-9)


def test_missing_entries_equal_masked_ones_and_a_step_without_data_is_a_prediction():
    model, prior = random_model()
    z = np.asarray(model.measurements)
    mask = np.isfinite(z)
    mask[30] = False
    with_nan = parallel_filter(model._replace(measurements=jnp.asarray(np.where(mask, z, np.nan))), prior)
    masked = parallel_filter(model._replace(measurements=jnp.asarray(np.where(mask, z, 123.0))), prior, mask=jnp.asarray(mask))
    for a, b in zip(with_nan, masked, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(masked.filtered_mean[30], masked.predicted_mean[30], atol=1e-12)
    np.testing.assert_allclose(masked.filtered_cov[30], masked.predicted_cov[30], atol=1e-12)
    assert masked.log_likelihoods[30] == pytest.approx(0.0, abs=1e-12)
    assert np.all(np.isfinite(masked.log_likelihoods))


def test_runs_under_jit_and_vmap():
    model, prior = random_model()
    run = jax.jit(lambda model: parallel.smooth(model, parallel.filter(model, prior)).mean)
    shifted = model._replace(measurements=model.measurements + 0.5)
    batch = jax.tree.map(lambda a, b: jnp.stack([a, b]), model, shifted)
    np.testing.assert_allclose(jax.vmap(run)(batch)[1], run(shifted), atol=1e-11)


def test_gradients_match_finite_differences():
    model, prior = random_model()

    def loss(params):
        m = model._replace(
            transition_cov=model.transition_cov * jnp.exp(params["q"]),
            observation_cov=model.observation_cov * jnp.exp(params["r"]),
        )
        filtered = parallel.filter(m, prior)
        smoothed = parallel.smooth(m, filtered)
        return jnp.sum(filtered.log_likelihoods) + jnp.sum(smoothed.mean**2)

    params = {"q": jnp.array(0.1), "r": jnp.array(-0.2)}
    grads = jax.jit(jax.grad(loss))(params)
    assert check_leaf_gradients(jax.jit(loss), grads, params, abs_tol=1e-7, rel_tol=1e-5) == 2
