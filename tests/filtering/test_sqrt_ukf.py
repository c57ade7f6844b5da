"""The square-root UKF: equal to filterpy's UKF step by step and to the covariance form to
round-off in float64 (angles, missing
entries, every sigma-point scheme, also a negative central weight), far more accurate in float32
on an ill-conditioned problem, with gradients that match finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.planar import simulate_planar_sequence
from jbevo.filtering import sqrt_ukf, ukf
from jbevo.filtering.noise import DiagonalCovariance
from jbevo.filtering.planar import planar_pose_model
from jbevo.filtering.unscented import Julier, MerweScaled
from tests.filtering.references import P0, Q, R, filterpy_localization, wrap_np
from tests.filtering.test_ukf import run_localization
from tests.helpers import check_leaf_gradients

SCHEMES = [MerweScaled(), MerweScaled(0.5, 2.0, 1.0), MerweScaled(0.5, 0.0, 0.0), Julier()]  # Wc_0: 2, 0.75, -2.25, 0


def both(model, x0, p0, controls, measurements, q, r, **kw):
    args = (
        model,
        ukf.GaussianState(jnp.asarray(x0), jnp.asarray(p0)),
        controls,
        jnp.asarray(measurements),
        jnp.asarray(q),
        jnp.asarray(r),
    )
    return ukf.filter(*args, **kw), sqrt_ukf.filter(*args, **kw)


@pytest.mark.usefixtures("float64")
@pytest.mark.parametrize("scheme", SCHEMES[::2], ids=str)  # a positive and a negative central weight
def test_equals_the_covariance_form_with_angles_and_missing_entries(scheme):
    seq = simulate_planar_sequence(jax.random.PRNGKey(1), 300, yaw_rate_std=0.2, fix_dropout=0.2)
    fixes = np.array(seq.fixes)
    fixes[5, 1] = fixes[9, 2] = np.nan  # partial fixes besides the dropped ones
    mask = np.ones(fixes.shape, bool)
    mask[20, 0] = False
    cov_form, root = both(
        planar_pose_model(), seq.poses[0], P0, seq.increments, fixes, Q, R, scheme=scheme, mask=jnp.asarray(mask)
    )
    filtered_cov, predicted_cov = root.covariances()
    np.testing.assert_allclose(root.filtered_mean, cov_form.filtered_mean, atol=1e-12)
    np.testing.assert_allclose(filtered_cov, cov_form.filtered_cov, atol=1e-13)
    np.testing.assert_allclose(predicted_cov, cov_form.predicted_cov, atol=1e-13)
    np.testing.assert_allclose(root.log_likelihoods, cov_form.log_likelihoods, atol=1e-11)
    assert np.all(np.triu(np.asarray(root.filtered_chol), 1) == 0)
    assert np.all(np.diagonal(np.asarray(root.filtered_chol), axis1=1, axis2=2) > 0)


@pytest.mark.usefixtures("float64")
@pytest.mark.parametrize("scheme", SCHEMES, ids=str)
def test_equals_the_covariance_form_on_a_linear_model_with_fewer_measurements_than_states(scheme):
    rng = np.random.default_rng(0)
    n, m, steps = 4, 2, 150
    a, h = np.eye(n) + 0.1 * rng.normal(size=(n, n)), rng.normal(size=(m, n))
    qm, rm = np.diag(rng.uniform(0.01, 0.1, n)), np.diag(rng.uniform(0.1, 1.0, m))
    rm[0, 1] = rm[1, 0] = 0.05  # correlated measurement noise
    zs = rng.normal(size=(steps, m))
    zs[3, 0] = np.nan
    zs[7] = np.nan
    model = ukf.StateSpaceModel(motion=lambda x, u: jnp.asarray(a) @ x, measurement=lambda x: jnp.asarray(h) @ x)
    cov_form, root = both(model, np.zeros(n), np.eye(n), None, zs, qm, rm, scheme=scheme)
    np.testing.assert_allclose(root.filtered_mean, cov_form.filtered_mean, atol=1e-12)
    np.testing.assert_allclose(root.covariances()[0], cov_form.filtered_cov, atol=1e-13)
    np.testing.assert_allclose(root.log_likelihood, cov_form.log_likelihood, rtol=1e-12)


@pytest.mark.usefixtures("float64")
@pytest.mark.parametrize("scheme", [MerweScaled(), MerweScaled(0.5, 0.0, 0.0)], ids=str)
def test_equals_filterpy_step_by_step_with_yaw_wrapping(scheme):
    # An independent reference: filterpy's covariance UKF, with the same sigma points (the
    # second scheme's negative central covariance weight takes the rank-one downdate path).
    seq = simulate_planar_sequence(jax.random.PRNGKey(1), 300, yaw_rate_std=0.2, fix_std=(0.5, 0.5, 0.3))
    assert np.any(np.abs(np.diff(np.asarray(seq.poses[:, 2]))) > np.pi), "the drive must cross +-pi"
    x0 = np.asarray(seq.poses[0]) + [0.3, -0.2, 0.05]
    root = run_localization(x0, seq, form=sqrt_ukf, scheme=scheme)
    ref = filterpy_localization(x0, np.asarray(seq.increments), np.asarray(seq.fixes), scheme.alpha, scheme.beta, scheme.kappa)
    diff = np.asarray(root.filtered_mean) - ref["mean"]
    diff[:, 2] = wrap_np(diff[:, 2])
    assert np.abs(diff).max() < 1e-8
    np.testing.assert_allclose(root.covariances()[0], ref["cov"], atol=1e-8)
    np.testing.assert_allclose(root.log_likelihoods, ref["ll"], atol=1e-8)


def constant_velocity(dtype, steps=5000):
    """Position measured to 1 cm, a nearly singular random-acceleration Q, a vague prior: the
    covariance form's ``P - W^T W`` cancels catastrophically in float32."""
    dt, q, r = 0.1, 1e-6, 1e-4
    f = np.array([[1.0, dt], [0.0, 1.0]])
    qm = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    rng = np.random.default_rng(0)
    x, zs = np.zeros(2), []
    for _ in range(steps):
        x = f @ x + rng.multivariate_normal(np.zeros(2), qm)
        zs.append([x[0] + 0.01 * rng.normal()])
    model = ukf.StateSpaceModel(motion=lambda x, u: jnp.asarray(f, x.dtype) @ x, measurement=lambda x: x[:1])
    args = (model, np.zeros(2), 1e4 * np.eye(2), None, np.asarray(zs), qm, [[r]])
    return both(*(jnp.asarray(a, dtype) if isinstance(a, np.ndarray | list) else a for a in args), check_inputs=False)


def test_float32_stays_close_to_float64_where_the_covariance_form_does_not():
    with jax.enable_x64(True):
        ref, _ = constant_velocity(jnp.float64)
        ref_mean, ref_cov = np.asarray(ref.filtered_mean), np.asarray(ref.filtered_cov)
    cov_form, root = constant_velocity(jnp.float32)
    std = np.sqrt(np.diagonal(ref_cov, axis1=1, axis2=2))

    def errors(mean, cov):
        # A form that breaks down (non-finite beliefs) is as far off as can be.
        mean_err = np.abs(np.asarray(mean, float) - ref_mean) / std
        cov_err = np.abs(np.asarray(cov, float) - ref_cov) / (std[:, :, None] * std[:, None, :])
        return np.max(np.nan_to_num(mean_err, nan=np.inf)), np.max(np.nan_to_num(cov_err, nan=np.inf))

    root_mean, root_cov = errors(root.filtered_mean, root.covariances()[0])
    form_mean, form_cov = errors(cov_form.filtered_mean, cov_form.filtered_cov)
    assert root_mean < 0.01 and root_cov < 0.01  # in standard deviations
    assert form_cov > 100 * root_cov and form_mean > 10 * root_mean


def test_tria_and_rank_one_factor_what_they_say():
    rng = np.random.default_rng(1)
    a = jnp.asarray(rng.normal(size=(3, 8)), jnp.float32)
    low = sqrt_ukf.tria(a)
    np.testing.assert_allclose(low @ low.T, a @ a.T, rtol=1e-5, atol=1e-5)
    assert np.all(np.triu(np.asarray(low), 1) == 0) and np.all(np.diag(np.asarray(low)) >= 0)
    big = jnp.asarray(rng.normal(size=(10, 12)), jnp.float32)  # above the unrolled size: LAPACK's QR
    np.testing.assert_allclose(sqrt_ukf.tria(big), jnp.linalg.cholesky(big @ big.T), rtol=1e-3, atol=1e-4)
    x = 0.3 * jnp.asarray(rng.normal(size=3), jnp.float32)
    for sign in (1.0, -1.0):
        np.testing.assert_allclose(
            sqrt_ukf.rank_one(low, x, sign), jnp.linalg.cholesky(a @ a.T + sign * jnp.outer(x, x)), atol=1e-5
        )
    with pytest.raises(ValueError, match="at least as many columns as rows"):
        sqrt_ukf.tria(a.T)


@pytest.mark.usefixtures("float64")
@pytest.mark.parametrize("scheme", [MerweScaled(), MerweScaled(0.5, 0.0, 0.0)], ids=str)
def test_log_likelihood_gradient_matches_finite_differences(scheme):
    seq = simulate_planar_sequence(jax.random.PRNGKey(2), 80, fix_dropout=0.2)
    fixes = seq.fixes.at[5, 1].set(jnp.nan).at[9, 2].set(jnp.nan)  # partial fixes besides the dropped ones

    def log_lik(params):
        q, r = DiagonalCovariance(params["q"])(), DiagonalCovariance(params["r"])()
        run = sqrt_ukf.filter(
            planar_pose_model(), ukf.GaussianState(seq.poses[0], jnp.asarray(P0)), seq.increments, fixes, q, r, scheme=scheme
        )
        return run.log_likelihood

    params = {"q": jnp.log(jnp.array([0.03, 0.02, 0.01])), "r": jnp.log(jnp.array([0.4, 0.6, 0.1]))}
    value = jax.jit(log_lik)
    assert check_leaf_gradients(value, jax.jit(jax.grad(log_lik))(params), params, abs_tol=1e-6, rel_tol=1e-5) == 6


def test_runs_under_jit_and_vmap_and_checks_its_inputs(as_users_run):
    seq = simulate_planar_sequence(jax.random.PRNGKey(3), 40)

    @jax.jit
    def run(fixes):
        return sqrt_ukf.filter(
            planar_pose_model(),
            ukf.GaussianState(seq.poses[0], jnp.asarray(P0, jnp.float32)),
            seq.increments,
            fixes,
            jnp.asarray(Q, jnp.float32),
            jnp.asarray(R, jnp.float32),
        ).filtered_mean

    fixes = jnp.stack([seq.fixes, seq.fixes + 0.1])
    np.testing.assert_allclose(jax.vmap(run)(fixes)[1], run(fixes[1]), atol=1e-5)
    start = sqrt_ukf.SqrtGaussianState.from_gaussian(ukf.GaussianState(seq.poses[0], jnp.asarray(P0, jnp.float32)))
    with pytest.raises(ValueError, match=r"motion_cov must have shape \(3, 3\)"):
        sqrt_ukf.filter(planar_pose_model(), start, seq.increments, seq.fixes, jnp.eye(2), jnp.asarray(R))
    with pytest.raises(Exception, match="measurement_cov \\(R\\) is not finite symmetric positive definite"):
        sqrt_ukf.filter(planar_pose_model(), start, seq.increments, seq.fixes, jnp.asarray(Q), -jnp.eye(3))
