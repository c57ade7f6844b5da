"""The unscented RTS smoother: equal to filterpy's on a nonlinear model with angles (also across a
gap in the measurements), to the Kalman RTS smoother on a linear model (also with entries missing
as NaN or by mask), better than the filter,
with gradients that match finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from jbevo.data.synthetic.planar import simulate_planar_sequence
from jbevo.filtering import ukf
from jbevo.filtering.noise import DiagonalCovariance
from jbevo.filtering.planar import planar_pose_model
from jbevo.filtering.smoother import smooth
from jbevo.filtering.unscented import MerweScaled
from jbevo.geometry.angles import wrap_angle
from tests.filtering.references import P0, Q, R, filterpy_localization, wrap_np
from tests.helpers import check_leaf_gradients

pytestmark = pytest.mark.usefixtures("float64")


def localization(steps=300, seed=1):
    seq = simulate_planar_sequence(jax.random.PRNGKey(seed), steps, yaw_rate_std=0.2, fix_std=(0.5, 0.5, 0.3))
    return seq, np.asarray(seq.poses[0]) + [0.3, -0.2, 0.05]


def run(seq, x0, fixes=None, q=Q, scheme=MerweScaled(), recompute=False):
    model = planar_pose_model()
    fixes = seq.fixes if fixes is None else fixes
    result = ukf.filter(
        model,
        ukf.GaussianState(jnp.asarray(x0), jnp.asarray(P0)),
        seq.increments,
        fixes,
        jnp.asarray(q),
        jnp.asarray(R),
        scheme=scheme,
    )
    given = result._replace(smoother_gains=None) if recompute else result
    return result, smooth(model, given, seq.increments, jnp.asarray(q), scheme=scheme)


def filterpy_smoothed(seq, x0, fixes, alpha, beta, kappa):
    increments = np.asarray(seq.increments)
    ref = filterpy_localization(x0, increments, fixes, alpha, beta, kappa)
    f = ref["filter"]
    fx = f.fx
    f.fx = lambda x, k: fx(x, 1.0, increments[int(k) + 1])  # step k -> k + 1 moves by increment k + 1
    means, covs, _ = f.rts_smoother(ref["mean"], ref["cov"], dts=np.arange(len(increments)))
    return means, covs


def assert_close_states(a, b, atol):
    d = np.asarray(a) - np.asarray(b)
    d[..., 2] = wrap_np(d[..., 2])
    assert np.abs(d).max() < atol


@pytest.mark.parametrize("alpha,beta,kappa,recompute", [(1.0, 2.0, 0.0, False), (0.5, 2.0, 1.0, False), (0.5, 2.0, 1.0, True)])
def test_equals_filterpy_rts_smoother_with_yaw_wrapping(alpha, beta, kappa, recompute):
    seq, x0 = localization()
    assert np.any(np.abs(np.diff(np.asarray(seq.poses[:, 2]))) > np.pi), "the drive must cross +-pi"
    _, ours = run(seq, x0, scheme=MerweScaled(alpha, beta, kappa), recompute=recompute)
    means, covs = filterpy_smoothed(seq, x0, np.asarray(seq.fixes), alpha, beta, kappa)
    assert_close_states(ours.smoothed_mean, means, 1e-8)
    np.testing.assert_allclose(ours.smoothed_cov, covs, atol=1e-8)


def test_a_gap_in_the_measurements_is_bridged_as_filterpy_does():
    seq, x0 = localization(200)
    fixes = np.array(seq.fixes)
    fixes[60:120] = np.nan  # sixty steps without a fix: the filter predicts only
    filtered, ours = run(seq, x0, fixes=jnp.asarray(fixes))
    means, covs = filterpy_smoothed(seq, x0, fixes, 1.0, 2.0, 0.0)
    assert_close_states(ours.smoothed_mean, means, 1e-8)
    np.testing.assert_allclose(ours.smoothed_cov, covs, atol=1e-8)
    # Inside the gap the smoother knows what follows it: its uncertainty peaks mid-gap and falls
    # again towards the gap's end, where the filter's is near its largest.
    position_var = lambda covs: np.asarray(covs[60:120, 0, 0] + covs[60:120, 1, 1])
    sm_var, f_var = position_var(ours.smoothed_cov), position_var(filtered.filtered_cov)
    assert 10 < np.argmax(sm_var) < 50 and sm_var[-1] < 0.5 * f_var[-1]
    assert np.all(sm_var < f_var)


def test_the_filters_gains_give_the_smoother_that_recomputes_them():
    # filter() keeps each step's smoother gain; a result without them (filter_blocks, beliefs
    # assembled by hand) makes the smoother push the sigma points through the motion again.
    seq, x0 = localization(120)
    fixes = np.array(seq.fixes)
    fixes[40:70] = np.nan
    q_seq = jnp.asarray(Q)[None] * jnp.linspace(0.5, 3.0, 120)[:, None, None]
    filtered, kept = run(seq, x0, fixes=jnp.asarray(fixes), q=q_seq)
    assert filtered.smoother_gains is not None
    recomputed = smooth(planar_pose_model(), filtered._replace(smoother_gains=None), seq.increments, q_seq)
    for a, b in zip(kept, recomputed, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def linear_model(rng, n, m, steps):
    """A random linear model: transition, observation, Q, R, measurements, initial mean and the
    UKF's model of it."""
    a = np.eye(n) + 0.1 * rng.normal(size=(n, n))
    h = rng.normal(size=(m, n))
    qm, rm = np.diag(rng.uniform(0.01, 0.1, n)), np.diag(rng.uniform(0.1, 1.0, m))
    zs, m0 = rng.normal(size=(steps, m)), rng.normal(size=n)
    model = ukf.StateSpaceModel(motion=lambda x, u: jnp.asarray(a) @ x, measurement=lambda x: jnp.asarray(h) @ x)
    return a, h, qm, rm, zs, m0, model


def test_equals_the_kalman_rts_smoother_on_a_linear_model():
    n, m = 4, 2
    a, h, qm, rm, zs, m0, model = linear_model(np.random.default_rng(0), n, m, 150)
    result = ukf.filter(
        model, ukf.GaussianState(jnp.asarray(m0), jnp.eye(n)), None, jnp.asarray(zs), jnp.asarray(qm), jnp.asarray(rm)
    )
    ours = smooth(model, result, None, jnp.asarray(qm))

    kf = KalmanFilter(n, m)
    kf.x, kf.P, kf.F, kf.H, kf.Q, kf.R = m0.copy(), np.eye(n), a, h, qm, rm
    means, covs, _, _ = kf.batch_filter(zs)
    np.testing.assert_allclose(result.filtered_mean, means, atol=1e-9)
    s_means, s_covs, _, _ = kf.rts_smoother(means, covs)
    np.testing.assert_allclose(ours.smoothed_mean, s_means, atol=1e-9)
    np.testing.assert_allclose(ours.smoothed_cov, s_covs, atol=1e-9)


def test_partial_and_masked_measurements_equal_the_kalman_smoother_of_the_observed_entries():
    # A linear model with some measurements partly and some wholly missing, given as NaN or as a
    # mask: the reference is filterpy's Kalman filter updated with the observed rows of H and R
    # only (no update where none is observed), then its RTS smoother.
    rng = np.random.default_rng(4)
    n, m, steps = 3, 3, 80
    a, h, qm, rm, zs, m0, model = linear_model(rng, n, m, steps)
    observed = rng.uniform(size=(steps, m)) > 0.3
    observed[20:30] = False  # ten steps with nothing observed
    prior = ukf.GaussianState(jnp.asarray(m0), jnp.eye(n))

    def smoothed(measurements, mask):
        result = ukf.filter(model, prior, None, jnp.asarray(measurements), jnp.asarray(qm), jnp.asarray(rm), mask=mask)
        return smooth(model, result, None, jnp.asarray(qm))

    by_nan = smoothed(np.where(observed, zs, np.nan), None)
    by_mask = smoothed(zs, jnp.asarray(observed))

    kf = KalmanFilter(n, m)
    kf.x, kf.P, kf.F, kf.Q = m0.copy(), np.eye(n), a, qm
    means, covs = [], []
    for z, seen in zip(zs, observed, strict=True):
        kf.predict()
        if seen.any():
            kf.update(z[seen], R=rm[np.ix_(seen, seen)], H=h[seen])
        means.append(kf.x.copy())
        covs.append(kf.P.copy())
    s_means, s_covs, _, _ = kf.rts_smoother(np.array(means), np.array(covs))
    for ours in (by_nan, by_mask):
        np.testing.assert_allclose(ours.smoothed_mean, s_means, atol=1e-9)
        np.testing.assert_allclose(ours.smoothed_cov, s_covs, atol=1e-9)


def test_smoothing_lowers_the_error_and_the_variance():
    seq, x0 = localization(400, seed=3)
    filtered, smoothed = run(seq, x0)
    truth = np.asarray(seq.poses[1:])  # poses[0] is the start, before the first step

    def rmse(means):
        d = np.asarray(means) - truth
        d[:, 2] = wrap_np(d[:, 2])
        return np.sqrt(np.mean(d[:, :2] ** 2))

    assert rmse(smoothed.smoothed_mean) < 0.8 * rmse(filtered.filtered_mean)
    assert np.all(
        np.diagonal(smoothed.smoothed_cov, axis1=1, axis2=2) <= np.diagonal(filtered.filtered_cov, axis1=1, axis2=2) + 1e-12
    )
    np.testing.assert_array_equal(smoothed.smoothed_mean[-1], filtered.filtered_mean[-1])


@pytest.mark.parametrize("gains", ["the filter's", "recomputed"])
def test_gradient_through_the_smoother_matches_finite_differences(gains):
    seq, x0 = localization(60)
    fixes = np.array(seq.fixes)
    fixes[20:30] = np.nan
    truth = seq.poses[1:]
    model = planar_pose_model()

    def loss(params):
        q = DiagonalCovariance(params["q"])()
        r = DiagonalCovariance(params["r"])()
        result = ukf.filter(model, ukf.GaussianState(jnp.asarray(x0), jnp.asarray(P0)), seq.increments, jnp.asarray(fixes), q, r)
        if gains == "recomputed":
            result = result._replace(smoother_gains=None)
        sm = smooth(model, result, seq.increments, q).smoothed_mean
        d = sm - truth
        return jnp.mean(d[:, 0] ** 2 + d[:, 1] ** 2 + wrap_angle(d[:, 2]) ** 2)

    params = {"q": jnp.log(jnp.array([0.03, 0.02, 0.01])), "r": jnp.log(jnp.array([0.4, 0.6, 0.1]))}
    grads = jax.jit(jax.grad(loss))(params)
    assert check_leaf_gradients(jax.jit(loss), grads, params, abs_tol=1e-7, rel_tol=1e-4) == 6


@pytest.mark.parametrize("recompute", [False, True])
def test_runs_under_jit_and_vmap_with_time_varying_noise(recompute):
    seq, x0 = localization(50)
    model = planar_pose_model()
    q_seq = jnp.asarray(Q)[None] * jnp.linspace(0.5, 2.0, 50)[:, None, None]

    @jax.jit
    def run_one(fixes):
        result = ukf.filter(
            model, ukf.GaussianState(jnp.asarray(x0), jnp.asarray(P0)), seq.increments, fixes, q_seq, jnp.asarray(R)
        )
        if recompute:
            result = result._replace(smoother_gains=None)
        return smooth(model, result, seq.increments, q_seq).smoothed_mean

    fixes = jnp.stack([seq.fixes, seq.fixes + 0.1])
    batched = jax.vmap(run_one)(fixes)
    np.testing.assert_allclose(batched[1], run_one(fixes[1]), atol=1e-10)


def test_bad_input_gives_clear_errors(as_users_run):
    seq, x0 = localization(20)
    model = planar_pose_model()
    result = ukf.filter(
        model, ukf.GaussianState(jnp.asarray(x0), jnp.asarray(P0)), seq.increments, seq.fixes, jnp.asarray(Q), jnp.asarray(R)
    )
    with pytest.raises(ValueError, match=r"motion_cov must have shape \(3, 3\) or \(20, 3, 3\)"):
        smooth(model, result, seq.increments, jnp.eye(2))
    with pytest.raises(ValueError, match="every controls leaf must have leading axis 20"):
        smooth(model, result, seq.increments[:10], jnp.asarray(Q))
    with pytest.raises(ValueError, match="predictions and gains must have the filtered beliefs' shapes"):
        smooth(model, result._replace(smoother_gains=result.smoother_gains[:, :2]), seq.increments, jnp.asarray(Q))
    one = smooth(model, jax.tree.map(lambda a: a[:1] if jnp.ndim(a) else a, result), seq.increments[:1], jnp.asarray(Q))
    np.testing.assert_array_equal(one.smoothed_mean, result.filtered_mean[:1])
