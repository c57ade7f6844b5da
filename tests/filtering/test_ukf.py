import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.planar import simulate_planar_sequence
from jbevo.filtering import ukf
from jbevo.filtering.planar import planar_pose_model
from jbevo.filtering.unscented import MerweScaled
from jbevo.geometry.angles import wrap_angle
from tests.filtering.references import P0, Q, R, filterpy_localization, wrap_np

# Exactness against independent references needs float64 (conftest's fixture).
pytestmark = pytest.mark.usefixtures("float64")


def run_localization(x0, seq, *, form=ukf, scheme=MerweScaled(), q=Q, r=R, **kw):
    """``form``'s filter (:mod:`ukf` or :mod:`sqrt_ukf`) on the localization model over ``seq``."""
    return form.filter(
        planar_pose_model(),
        ukf.GaussianState(jnp.asarray(x0), jnp.asarray(P0)),
        seq.increments,
        seq.fixes,
        jnp.asarray(q),
        jnp.asarray(r),
        scheme=scheme,
        **kw,
    )


@pytest.mark.parametrize("alpha,beta,kappa", [(1.0, 2.0, 0.0), (0.5, 2.0, 1.0)])
def test_equals_filterpy_step_by_step_with_yaw_wrapping(alpha, beta, kappa):
    seq = simulate_planar_sequence(jax.random.PRNGKey(1), 400, yaw_rate_std=0.2, fix_std=(0.5, 0.5, 0.3))
    assert np.any(np.abs(np.diff(np.asarray(seq.poses[:, 2]))) > np.pi), "the drive must cross +-pi"
    x0 = np.asarray(seq.poses[0]) + [0.3, -0.2, 0.05]
    ours = run_localization(x0, seq, scheme=MerweScaled(alpha, beta, kappa))
    ref = filterpy_localization(x0, np.asarray(seq.increments), np.asarray(seq.fixes), alpha, beta, kappa)
    for key, mine in [("mean", ours.filtered_mean), ("pred_mean", ours.predicted_mean)]:
        diff = np.asarray(mine) - ref[key]
        diff[:, 2] = wrap_np(diff[:, 2])
        assert np.abs(diff).max() < 1e-8, key
    np.testing.assert_allclose(ours.filtered_cov, ref["cov"], atol=1e-8)
    np.testing.assert_allclose(ours.predicted_cov, ref["pred_cov"], atol=1e-8)
    np.testing.assert_allclose(ours.log_likelihoods, ref["ll"], atol=1e-8)


def kalman_filter_reference(A, B, H, Qm, Rm, m0, P0m, us, zs):
    """A plain linear Kalman filter (predict then update), numpy."""
    m, P = m0.copy(), P0m.copy()
    means, covs, ll = [], [], 0.0
    for u, z in zip(us, zs):
        m, P = A @ m + B @ u, A @ P @ A.T + Qm
        S = H @ P @ H.T + Rm
        K = P @ H.T @ np.linalg.inv(S)
        y = z - H @ m
        ll += -0.5 * (y @ np.linalg.solve(S, y) + np.linalg.slogdet(S)[1] + len(z) * np.log(2 * np.pi))
        m, P = m + K @ y, (np.eye(len(m)) - K @ H) @ P
        means.append(m)
        covs.append(P)
    return np.array(means), np.array(covs), ll


@pytest.mark.parametrize("scheme", [MerweScaled(), MerweScaled(0.3, 2.0, 1.0), MerweScaled(np.sqrt(3), 2, 1)])
def test_equals_linear_kalman_filter_on_linear_model(scheme):
    rng = np.random.default_rng(0)
    n, m, T = 4, 2, 200
    A = np.eye(n) + 0.1 * rng.normal(size=(n, n))
    B, H = rng.normal(size=(n, 2)), rng.normal(size=(m, n))
    Qm, Rm = np.diag(rng.uniform(0.01, 0.1, n)), np.diag(rng.uniform(0.1, 1.0, m))
    us, zs = rng.normal(size=(T, 2)), rng.normal(size=(T, m))
    m0, P0m = rng.normal(size=n), np.eye(n)
    model = ukf.StateSpaceModel(
        motion=lambda x, u: jnp.asarray(A) @ x + jnp.asarray(B) @ u, measurement=lambda x: jnp.asarray(H) @ x
    )
    res = ukf.filter(
        model,
        ukf.GaussianState(jnp.asarray(m0), jnp.asarray(P0m)),
        jnp.asarray(us),
        jnp.asarray(zs),
        jnp.asarray(Qm),
        jnp.asarray(Rm),
        scheme=scheme,
    )
    ref_means, ref_covs, ref_ll = kalman_filter_reference(A, B, H, Qm, Rm, m0, P0m, us, zs)
    np.testing.assert_allclose(res.filtered_mean, ref_means, atol=1e-9)
    np.testing.assert_allclose(res.filtered_cov, ref_covs, atol=1e-9)
    np.testing.assert_allclose(res.log_likelihood, ref_ll, rtol=1e-9)


def test_scalar_linear_update_equals_the_unscented_update():
    """``linear_update`` with ``z = h x`` is the UKF's update on that (linear) measurement, which
    the unscented transform gets exactly; ``use=False`` leaves the belief as it was."""
    rng = np.random.default_rng(1)
    a = rng.normal(size=(4, 4))
    prior = ukf.GaussianState(jnp.asarray(rng.normal(size=4)), jnp.asarray(a @ a.T + np.eye(4)))
    h, z, variance = jnp.asarray(rng.normal(size=4)), 0.7, 0.3
    model = ukf.StateSpaceModel(motion=lambda x, u: x, measurement=lambda x: (h @ x)[None])
    expected, _ = ukf.update(model, prior, jnp.array([z]), jnp.array([[variance]]))
    post = ukf.linear_update(prior, h, z - h @ prior.mean, variance)
    np.testing.assert_allclose(post.mean, expected.mean, atol=1e-12)
    np.testing.assert_allclose(post.cov, expected.cov, atol=1e-12)
    np.testing.assert_array_equal(post.cov, post.cov.T)
    kept = ukf.linear_update(prior, h, z - h @ prior.mean, variance, use=jnp.asarray(False))
    np.testing.assert_array_equal(kept.mean, prior.mean)
    np.testing.assert_array_equal(kept.cov, prior.cov)


def test_all_missing_measurement_is_a_predict_only_step():
    model = planar_pose_model()
    prior = ukf.GaussianState(jnp.array([1.0, 2.0, 3.1]), jnp.asarray(P0))
    predicted = ukf.predict(model, prior, jnp.array([1.0, 0.1, 0.2]), jnp.asarray(Q))
    post, ll = ukf.update(model, predicted, jnp.full(3, jnp.nan), jnp.asarray(R))
    np.testing.assert_array_equal(post.mean, predicted.mean)
    np.testing.assert_array_equal(post.cov, predicted.cov)
    assert float(ll) == 0.0
    post_mask, ll_mask = ukf.update(model, predicted, jnp.ones(3), jnp.asarray(R), mask=jnp.zeros(3, bool))
    np.testing.assert_array_equal(post_mask.mean, predicted.mean)
    assert float(ll_mask) == 0.0


def test_partial_measurement_equals_update_with_observed_entries_only():
    full = planar_pose_model()
    yaw_only = ukf.StateSpaceModel(
        motion=full.motion,
        measurement=lambda x: x[2:],
        state_residual=full.state_residual,
        state_add=full.state_add,
        state_mean=full.state_mean,
        measurement_residual=lambda a, b: wrap_angle(a - b),
        measurement_mean=lambda p, w: full.measurement_mean(jnp.pad(p, ((0, 0), (2, 0))), w)[2:],
    )
    rng = np.random.default_rng(1)
    a = rng.normal(size=(3, 3))
    state = ukf.GaussianState(jnp.array([1.0, -2.0, 3.0]), jnp.asarray(a @ a.T + 0.1 * np.eye(3)))
    r_full = jnp.asarray(np.array([[0.3, 0.1, 0.02], [0.1, 0.4, 0.01], [0.02, 0.01, 0.05]]))
    z = jnp.array([jnp.nan, jnp.nan, -3.1])
    post, ll = ukf.update(full, state, z, r_full)
    ref, ref_ll = ukf.update(yaw_only, state, z[2:], r_full[2:, 2:])
    np.testing.assert_allclose(post.mean, ref.mean, atol=1e-12)
    np.testing.assert_allclose(post.cov, ref.cov, atol=1e-12)
    np.testing.assert_allclose(ll, ref_ll, atol=1e-12)
    # the explicit mask gives the same as NaN
    post_m, ll_m = ukf.update(full, state, jnp.array([5.0, 5.0, -3.1]), r_full, mask=jnp.array([False, False, True]))
    np.testing.assert_allclose(post_m.mean, post.mean, atol=1e-14)
    np.testing.assert_allclose(ll_m, ll, atol=1e-14)


def test_gradients_finite_with_missing_data():
    seq = simulate_planar_sequence(jax.random.PRNGKey(2), 50, fix_dropout=0.3)
    seq = seq._replace(fixes=seq.fixes.at[::7, 1].set(jnp.nan))
    assert np.isnan(np.asarray(seq.fixes)).any()

    def loss(log_std):
        return -run_localization(seq.poses[0], seq, q=jnp.diag(jnp.exp(2 * log_std))).log_likelihood

    g = jax.grad(loss)(jnp.log(jnp.array([0.02, 0.01, 0.005])))
    assert np.all(np.isfinite(g)) and np.any(g != 0)


def central_difference(f, x, eps):
    x = np.asarray(x, float)
    out = np.zeros_like(x)
    for i in range(x.size):
        d = np.zeros_like(x)
        d.flat[i] = eps
        out.flat[i] = (f(jnp.asarray(x + d)) - f(jnp.asarray(x - d))) / (2 * eps)
    return out


@pytest.mark.parametrize("kind", ["diagonal", "cholesky"])
def test_log_likelihood_gradient_matches_finite_differences(kind):
    seq = simulate_planar_sequence(jax.random.PRNGKey(3), 1000, fix_dropout=0.1)
    model = planar_pose_model()
    r_true = np.diag([0.5, 0.5, 0.05]) ** 2

    if kind == "diagonal":
        params0 = ukf.DiagonalCovariance.from_std(jnp.array([0.05, 0.02, 0.01]))
    else:
        params0 = ukf.CholeskyCovariance.from_matrix(jnp.asarray(np.diag([0.05, 0.02, 0.01]) ** 2 + 1e-5))
    flat0, unflatten = jax.flatten_util.ravel_pytree(params0)

    @jax.jit
    def log_lik(flat):
        q = unflatten(flat)()
        return ukf.filter(
            model, ukf.GaussianState(seq.poses[0], jnp.asarray(P0)), seq.increments, seq.fixes, q, jnp.asarray(r_true)
        ).log_likelihood

    grad = np.asarray(jax.grad(log_lik)(flat0))
    fd = central_difference(lambda f: float(log_lik(f)), flat0, 1e-5)
    np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-6 * np.abs(fd).max())


def test_gradient_under_vmap_matches_per_sequence_and_finite_differences():
    keys = jax.random.split(jax.random.PRNGKey(4), 3)
    seqs = jax.vmap(lambda k: simulate_planar_sequence(k, 300))(keys)
    model = planar_pose_model()

    @jax.jit
    def log_lik(log_std, seq):
        r = jnp.diag(jnp.exp(2 * log_std))
        return ukf.filter(
            model, ukf.GaussianState(seq.poses[0], jnp.asarray(P0)), seq.increments, seq.fixes, jnp.asarray(Q), r
        ).log_likelihood

    theta = jnp.log(jnp.array([0.4, 0.6, 0.04]))
    batched = jax.jit(jax.vmap(jax.grad(log_lik), in_axes=(None, 0)))(theta, seqs)
    single_grad = jax.jit(jax.grad(log_lik))
    for i in range(3):
        seq = jax.tree.map(lambda a, i=i: a[i], seqs)
        single = single_grad(theta, seq)
        np.testing.assert_allclose(batched[i], single, rtol=1e-10)
        fd = central_difference(lambda t, seq=seq: float(log_lik(t, seq)), theta, 1e-5)
        np.testing.assert_allclose(batched[i], fd, rtol=1e-4)


def test_gradient_finite_when_covariances_are_nearly_rank_deficient():
    seq = simulate_planar_sequence(jax.random.PRNGKey(5), 200)
    model = planar_pose_model()
    p0 = jnp.diag(jnp.array([1.0, 1.0, 1e-14]))  # yaw known almost exactly

    def log_lik(log_std):
        q = jnp.diag(jnp.exp(2 * log_std))
        return ukf.filter(model, ukf.GaussianState(seq.poses[0], p0), seq.increments, seq.fixes, q, jnp.asarray(R)).log_likelihood

    theta = jnp.log(jnp.array([0.02, 0.01, 1e-7]))  # yaw motion noise ~ 1e-14 variance
    value, grad = jax.value_and_grad(log_lik)(theta)
    assert np.isfinite(value) and np.all(np.isfinite(grad))


def test_covariances_stay_symmetric_positive_definite_in_float32_over_100k_steps():
    steps = 100_000
    seq = simulate_planar_sequence(jax.random.PRNGKey(6), steps, fix_dropout=0.2, dtype=jnp.float32)
    assert seq.increments.dtype == jnp.float32
    model = planar_pose_model()

    @jax.jit
    def run(seq):
        f32 = lambda a: jnp.asarray(a, jnp.float32)
        res = ukf.filter(model, ukf.GaussianState(seq.poses[0], f32(P0)), seq.increments, seq.fixes, f32(Q), f32(R))
        return res.filtered_cov, res.predicted_cov, res.filtered_mean

    filtered, predicted, means = (np.asarray(a) for a in run(seq))
    assert filtered.dtype == np.float32
    for covs in (filtered, predicted):
        assert np.all(np.isfinite(covs))
        np.testing.assert_array_equal(covs, np.swapaxes(covs, -1, -2))
        assert np.linalg.eigvalsh(covs.astype(np.float64)).min() > 0
    err = means[:, :2] - np.asarray(seq.poses[1:, :2])
    assert np.sqrt(np.mean(err**2)) < 0.5  # better than the 0.5 m fixes


def test_filter_blocks_equals_the_flat_filter_at_block_ends():
    steps, block = 30, 5
    seq = simulate_planar_sequence(jax.random.PRNGKey(7), steps * block, fix_dropout=0.5)
    flat = run_localization(seq.poses[0], seq)
    blocks = ukf.filter_blocks(
        planar_pose_model(),
        ukf.GaussianState(seq.poses[0], jnp.asarray(P0)),
        seq.increments.reshape(steps, block, 3),
        seq.fixes.reshape(steps, block, 3),
        jnp.asarray(Q),
        jnp.asarray(R),
    )
    np.testing.assert_allclose(blocks.filtered_mean, flat.filtered_mean[block - 1 :: block], atol=1e-12)
    np.testing.assert_allclose(blocks.filtered_cov, flat.filtered_cov[block - 1 :: block], atol=1e-12)
    np.testing.assert_allclose(blocks.predicted_mean, flat.predicted_mean[::block], atol=1e-12)
    np.testing.assert_allclose(blocks.log_likelihoods, flat.log_likelihoods.reshape(steps, block).sum(1), atol=1e-10)
    np.testing.assert_allclose(blocks.log_likelihood, flat.log_likelihood, rtol=1e-12)


def test_time_varying_noise_equals_stepwise_predict_update():
    seq = simulate_planar_sequence(jax.random.PRNGKey(8), 20)
    scales = jnp.linspace(0.5, 3.0, 20)
    r_seq = scales[:, None, None] * jnp.asarray(R)
    res = run_localization(seq.poses[0], seq, r=r_seq)
    state, model = ukf.GaussianState(seq.poses[0], jnp.asarray(P0)), planar_pose_model()
    for t in range(20):
        state = ukf.predict(model, state, seq.increments[t], jnp.asarray(Q))
        state, _ = ukf.update(model, state, seq.fixes[t], r_seq[t])
        np.testing.assert_allclose(res.filtered_mean[t], state.mean, atol=1e-12)


def test_filter_works_under_jit_and_controls_may_be_none():
    model = ukf.StateSpaceModel(motion=lambda x, u: 0.9 * x, measurement=lambda x: x[:1])
    run = jax.jit(
        lambda z: (
            ukf.filter(model, ukf.GaussianState(jnp.zeros(2), jnp.eye(2)), None, z, 0.1 * jnp.eye(2), jnp.eye(1)).filtered_mean
        )
    )
    assert run(jnp.ones((5, 1))).shape == (5, 2)


def test_bad_input_gives_clear_errors(as_users_run):
    seq = simulate_planar_sequence(jax.random.PRNGKey(9), 10)
    with pytest.raises(ValueError, match="motion_cov must have shape"):
        run_localization(seq.poses[0], seq, q=np.eye(2))
    with pytest.raises(ValueError, match="measurement_cov must have shape"):
        run_localization(seq.poses[0], seq, r=np.eye(4))
    with pytest.raises(ValueError, match="leading axes"):
        run_localization(seq.poses[0], seq._replace(increments=seq.increments[:5]))
    with pytest.raises(ValueError, match="measurements must have shape"):
        run_localization(seq.poses[0], seq._replace(fixes=seq.fixes[:, 0]))
    with pytest.raises(ValueError, match="initial cov"):
        ukf.filter(
            planar_pose_model(),
            ukf.GaussianState(seq.poses[0], jnp.eye(2)),
            seq.increments,
            seq.fixes,
            jnp.asarray(Q),
            jnp.asarray(R),
        )
    with pytest.raises(ValueError, match="model.measurement must return"):
        model = ukf.StateSpaceModel(motion=lambda x, u: x, measurement=lambda x: x[:2])
        ukf.filter(model, ukf.GaussianState(jnp.zeros(3), jnp.eye(3)), seq.increments, seq.fixes, jnp.asarray(Q), jnp.asarray(R))
    with pytest.raises(ValueError, match="mask must have the shape"):
        run_localization(seq.poses[0], seq, mask=jnp.ones((10, 2), bool))


@pytest.mark.parametrize(
    "change,message",
    [
        (dict(q=-np.eye(3)), "motion_cov"),
        (dict(q=np.diag([1.0, np.nan, 1.0])), "motion_cov"),
        (dict(r=np.diag([1.0, 0.0, 1.0])), "measurement_cov"),
        (dict(increments_nan=True), "controls contain NaN"),
    ],
)
def test_invalid_values_raise_also_under_jit(change, message):
    seq = simulate_planar_sequence(jax.random.PRNGKey(10), 10)
    if change.pop("increments_nan", False):
        seq = seq._replace(increments=seq.increments.at[3, 1].set(jnp.nan))
    kwargs = {k: jnp.asarray(v) for k, v in change.items()}
    with pytest.raises(Exception, match=message):
        jax.block_until_ready(jax.jit(lambda s: run_localization(seq.poses[0], s, **kwargs).filtered_mean)(seq))


def test_covariance_parameterisations():
    target = jnp.asarray(np.array([[2.0, 0.3, 0.1], [0.3, 1.0, -0.2], [0.1, -0.2, 0.5]]))
    chol = ukf.CholeskyCovariance.from_matrix(target)
    np.testing.assert_allclose(chol(), target, atol=1e-12)
    diag = ukf.DiagonalCovariance.from_std(jnp.array([0.1, 2.0]))
    np.testing.assert_allclose(diag(), np.diag([0.01, 4.0]), atol=1e-12)
    rng = np.random.default_rng(0)
    for _ in range(20):  # every parameter vector gives a positive definite matrix
        c = ukf.CholeskyCovariance(jnp.asarray(rng.normal(size=3) * 3), jnp.asarray(rng.normal(size=3) * 3))()
        assert np.linalg.eigvalsh(np.asarray(c)).min() > 0
    with pytest.raises(ValueError):
        ukf.CholeskyCovariance.from_matrix(-target)
    with pytest.raises(ValueError):
        ukf.DiagonalCovariance.from_std(jnp.array([0.1, -1.0]))
    with pytest.raises(ValueError, match="lower must have"):
        ukf.CholeskyCovariance(jnp.zeros(3), jnp.zeros(2))
    assert isinstance(chol, eqx.Module)


def test_measurement_inputs_equal_shifting_the_measurements():
    # z_t = x + r_t with known per-step r_t is the same as measuring z_t - r_t with h(x) = x.
    rng = np.random.default_rng(7)
    steps = 50
    controls = jnp.asarray(rng.normal(size=(steps, 2)) * 0.1)
    offsets = jnp.asarray(rng.normal(size=(steps, 2)))
    z = jnp.asarray(rng.normal(size=(steps, 2)))
    prior = ukf.GaussianState(jnp.zeros(2), jnp.eye(2))
    q, r = 0.01 * jnp.eye(2), 0.5 * jnp.eye(2)
    with_inputs = ukf.StateSpaceModel(motion=lambda x, u: x + u, measurement=lambda x, off: x + off)
    plain = ukf.StateSpaceModel(motion=lambda x, u: x + u, measurement=lambda x: x)
    a = ukf.filter(with_inputs, prior, controls, z, q, r, measurement_inputs=offsets)
    b = ukf.filter(plain, prior, controls, z - offsets, q, r)
    np.testing.assert_allclose(a.filtered_mean, b.filtered_mean, atol=1e-12)
    np.testing.assert_allclose(a.log_likelihood, b.log_likelihood, atol=1e-10)
    with pytest.raises(ValueError, match="measurement_inputs"):
        ukf.filter(with_inputs, prior, controls, z, q, r, measurement_inputs=offsets[:-1])
