"""The iterated posterior-linearisation smoother: parallel equal to sequential, the Kalman smoother
in one iteration on a linear model, converged on the planar pose model across +-pi and a gap,
exact statistical linearisation of affine maps, gradients against finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.planar import simulate_planar_sequence
from jbevo.filtering import posterior_linearisation as pl
from jbevo.filtering import smoother, ukf
from jbevo.filtering.noise import DiagonalCovariance
from jbevo.filtering.planar import planar_pose_model
from jbevo.geometry.angles import wrap_angle
from tests.filtering.references import P0, Q, R, wrap_np
from tests.helpers import check_leaf_gradients

pytestmark = pytest.mark.usefixtures("float64")


def localization(steps, seed=1, gap=None):
    seq = simulate_planar_sequence(jax.random.PRNGKey(seed), steps, yaw_rate_std=0.2, fix_std=(0.5, 0.5, 0.3))
    fixes = np.array(seq.fixes)
    if gap is not None:
        fixes[gap] = np.nan
    initial = ukf.GaussianState(jnp.asarray(seq.poses[0]) + jnp.array([0.3, -0.2, 0.05]), jnp.asarray(P0))
    return seq, jnp.asarray(fixes), initial


def position_rmse(means, truth):
    d = np.asarray(means) - np.asarray(truth)
    return float(np.sqrt(np.mean(d[:, :2] ** 2)))


def test_statistical_linearisation_of_an_affine_map_is_exact():
    rng = np.random.default_rng(0)
    a, b = jnp.asarray(rng.normal(size=(2, 3))), jnp.asarray(rng.normal(size=2))
    belief = ukf.GaussianState(jnp.asarray(rng.normal(size=3)), jnp.eye(3) + 0.3)
    slr = pl.statistical_linearisation(lambda x: a @ x + b, belief)
    np.testing.assert_allclose(slr.matrix, a, atol=1e-12)
    np.testing.assert_allclose(slr.mean, a @ belief.mean + b, atol=1e-12)
    np.testing.assert_allclose(slr.cov, 0.0, atol=1e-12)


def test_one_iteration_is_the_kalman_smoother_on_a_linear_model():
    rng = np.random.default_rng(2)
    n, m, steps = 4, 2, 80
    a = jnp.asarray(np.eye(n) + 0.1 * rng.normal(size=(n, n)))
    h = jnp.asarray(rng.normal(size=(m, n)))
    model = ukf.StateSpaceModel(motion=lambda x, u: a @ x + u, measurement=lambda x: h @ x)
    controls = jnp.asarray(0.1 * rng.normal(size=(steps, n)))
    z = np.asarray(rng.normal(size=(steps, m)))
    z[30:40] = np.nan
    z[50, 1] = np.nan
    q, r = jnp.diag(jnp.asarray(rng.uniform(0.01, 0.1, n))), jnp.diag(jnp.asarray(rng.uniform(0.1, 1.0, m)))
    initial = ukf.GaussianState(jnp.asarray(rng.normal(size=n)), jnp.eye(n))
    filtered = ukf.filter(model, initial, controls, jnp.asarray(z), q, r)
    reference = smoother.smooth(model, filtered, controls, q)
    # From points far from the answer: a linear model needs no good linearisation.
    ours = pl.smooth(
        model, initial, controls, jnp.asarray(z), q, r, iterations=1, linearisation=pl.prior_linearisation(initial, steps)
    )
    np.testing.assert_allclose(ours.smoothed_mean, reference.smoothed_mean, atol=1e-10)
    np.testing.assert_allclose(ours.smoothed_cov, reference.smoothed_cov, atol=1e-10)
    np.testing.assert_allclose(ours.filtered_mean, filtered.filtered_mean, atol=1e-10)
    np.testing.assert_allclose(ours.filtered_cov, filtered.filtered_cov, atol=1e-10)
    assert float(ours.log_likelihood) == pytest.approx(float(filtered.log_likelihood), abs=1e-9)


def test_parallel_equals_sequential_and_converges_on_the_planar_model():
    seq, fixes, initial = localization(300, gap=slice(100, 140))
    assert np.any(np.abs(np.diff(np.asarray(seq.poses[:, 2]))) > np.pi), "the drive must cross +-pi"
    model = planar_pose_model()
    run = lambda parallel: pl.smooth(
        model, initial, seq.increments, fixes, jnp.asarray(Q), jnp.asarray(R), iterations=6, parallel_in_time=parallel
    )
    par, sequential = run(True), run(False)
    for a, b in zip(par, sequential, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-9)
    assert float(par.mean_change[-1]) < 1e-9 < float(par.mean_change[0])  # converged
    filtered = ukf.filter(model, initial, seq.increments, fixes, jnp.asarray(Q), jnp.asarray(R))
    uks = smoother.smooth(model, filtered, seq.increments, jnp.asarray(Q))
    d = np.array(par.smoothed_mean - uks.smoothed_mean)
    d[:, 2] = wrap_np(d[:, 2])
    assert 1e-6 < np.abs(d).max() < 0.3  # close to the unscented RTS smoother (most in the gap), not the same
    truth = seq.poses[1:]
    assert position_rmse(par.smoothed_mean, truth) < 1.05 * position_rmse(uks.smoothed_mean, truth)
    assert position_rmse(par.smoothed_mean, truth) < 0.8 * position_rmse(filtered.filtered_mean, truth)
    assert np.all(np.abs(np.asarray(par.smoothed_mean[:, 2])) <= np.pi)


def test_a_first_linearisation_at_the_prior_can_converge_to_a_wrong_fixed_point():
    # Why the default first linearisation is the unscented smoother's: documented in pl.smooth.
    seq, fixes, initial = localization(500)
    model = planar_pose_model()
    prior_start = pl.smooth(
        model,
        initial,
        seq.increments,
        fixes,
        jnp.asarray(Q),
        jnp.asarray(R),
        iterations=30,
        linearisation=pl.prior_linearisation(initial, 500),
        parallel_in_time=False,  # the same fixed point (tested above); quicker to compile
    )
    default = pl.smooth(
        model, initial, seq.increments, fixes, jnp.asarray(Q), jnp.asarray(R), iterations=5, parallel_in_time=False
    )
    assert float(prior_start.mean_change[-1]) < 1e-4 * float(prior_start.mean_change[0])  # converging ...
    assert position_rmse(prior_start.smoothed_mean, seq.poses[1:]) > 1.0  # ... metres off
    assert position_rmse(default.smoothed_mean, seq.poses[1:]) < 0.3


@pytest.mark.parametrize("parallel", [False, True], ids=["sequential", "parallel"])
def test_gradient_matches_finite_differences(parallel):
    # Through the sigma-point linearisation and the iterations, the affine passes sequential
    # (lax.scan) or parallel in time (associative_scan).
    seq, fixes, initial = localization(20, gap=slice(8, 12))
    model = planar_pose_model()
    truth = seq.poses[1:]

    def loss(params):
        q, r = DiagonalCovariance(params["q"])(), DiagonalCovariance(params["r"])()
        out = pl.smooth(model, initial, seq.increments, fixes, q, r, iterations=2, parallel_in_time=parallel)
        d = out.smoothed_mean - truth
        return jnp.mean(d[:, 0] ** 2 + d[:, 1] ** 2 + wrap_angle(d[:, 2]) ** 2) - 1e-3 * out.log_likelihood

    params = {"q": jnp.log(jnp.array([0.03, 0.02, 0.01])), "r": jnp.log(jnp.array([0.4, 0.6, 0.1]))}
    grads = jax.jit(jax.grad(loss))(params)
    assert check_leaf_gradients(jax.jit(loss), grads, params, abs_tol=1e-7, rel_tol=1e-4) == 6


def test_bad_input_gives_clear_errors(as_users_run):
    seq, fixes, initial = localization(20)
    model = planar_pose_model()
    args = (model, initial, seq.increments, fixes, jnp.asarray(Q), jnp.asarray(R))
    with pytest.raises(ValueError, match="iterations must be at least 1"):
        pl.smooth(*args, iterations=0)
    with pytest.raises(ValueError, match="linearisation must hold 21 beliefs"):
        pl.smooth(*args, linearisation=pl.prior_linearisation(initial, 19))
    with pytest.raises(ValueError, match=r"measurements must have shape \(T, m\)"):
        pl.smooth(model, initial, seq.increments, fixes[0], jnp.asarray(Q), jnp.asarray(R))
