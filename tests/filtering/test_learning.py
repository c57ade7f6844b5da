"""Fitting Q and R: maximum likelihood recovers the true noise, padding is exact (a padded batch
has the value and gradient of the sequences run one by one), the supervised loss learns the
demo's noise, and bad input is named."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jbevo.data.synthetic.planar import simulate_planar_sequence
from jbevo.filtering import ukf
from jbevo.filtering.learning import Noise, batch_objective, fit_noise
from jbevo.filtering.noise import CholeskyCovariance, DiagonalCovariance
from jbevo.filtering.planar import planar_pose_model

ODOMETRY_STD = np.array([0.02, 0.01, 0.005])
FIX_STD = np.array([0.5, 0.5, 0.05])
PRIOR = ukf.GaussianState(jnp.zeros(3), jnp.diag(jnp.array([0.1, 0.1, 0.01])))


def drives(count, steps, seed=0):
    keys = jax.random.split(jax.random.PRNGKey(seed), count)
    return jax.vmap(
        lambda k: simulate_planar_sequence(k, steps, odometry_std=tuple(ODOMETRY_STD), fix_std=tuple(FIX_STD), fix_dropout=0.2)
    )(keys)


def wrong_noise():
    return Noise(
        DiagonalCovariance.from_std(jnp.asarray(ODOMETRY_STD) / 10), DiagonalCovariance.from_std(jnp.asarray(FIX_STD) * 5)
    )


def prior_at(seqs):
    return ukf.GaussianState(seqs.poses[:, 0], jnp.broadcast_to(PRIOR.cov, (seqs.poses.shape[0], 3, 3)))


def linear_drives(count, steps, q_std, r_std, seed=0):
    """A damped, coupled 2-D random walk with both states observed: data from exactly the
    model's class, with diagonal Q and R."""
    rng = np.random.default_rng(seed)
    a, h = np.array([[0.95, 0.1], [0.0, 0.9]]), np.eye(2)
    xs, zs = np.zeros((count, steps, 2)), np.zeros((count, steps, 2))
    x = np.zeros((count, 2))
    for t in range(steps):
        x = x @ a.T + rng.normal(size=(count, 2)) * q_std
        xs[:, t], zs[:, t] = x, x @ h.T + rng.normal(size=(count, 2)) * r_std
    model = ukf.StateSpaceModel(
        motion=lambda x, u: jnp.asarray(a, x.dtype) @ x, measurement=lambda x: jnp.asarray(h, x.dtype) @ x
    )
    return model, jnp.asarray(xs, jnp.float32), jnp.asarray(zs, jnp.float32)


def test_maximum_likelihood_recovers_the_true_noise():
    q_std, r_std = np.array([0.3, 0.1]), np.array([0.5, 0.2])
    model, _, zs = linear_drives(32, 200, q_std, r_std)
    start = Noise(DiagonalCovariance.from_std(jnp.array([1.0, 1.0])), DiagonalCovariance.from_std(jnp.array([2.0, 2.0])))
    prior = ukf.GaussianState(jnp.zeros(2), jnp.eye(2))
    fit = fit_noise(model, prior, None, zs, start, optimizer=optax.adam(0.05), iterations=300)
    assert fit.losses[-1] < fit.losses[0]
    np.testing.assert_allclose(np.exp(fit.noise.motion.log_std), q_std, rtol=0.15)
    np.testing.assert_allclose(np.exp(fit.noise.measurement.log_std), r_std, rtol=0.1)


@pytest.mark.usefixtures("float64")
@pytest.mark.parametrize("objective,with_gradient", [("likelihood", True), ("supervised", False)])
def test_a_padded_batch_equals_the_sequences_run_one_by_one(objective, with_gradient):
    seqs = drives(3, 40, seed=1)
    lengths = np.array([40, 25, 12])
    model = planar_pose_model()
    garbage = jnp.where(jnp.arange(40)[None, :, None] < lengths[:, None, None], seqs.fixes, 1e3)  # after the end
    targets = seqs.poses[:, 1:]
    padded = batch_objective(
        model, prior_at(seqs), seqs.increments, garbage, objective=objective, targets=targets, lengths=jnp.asarray(lengths)
    )
    singles = [
        batch_objective(
            model,
            jax.tree.map(lambda a, b=b: a[b : b + 1], prior_at(seqs)),
            seqs.increments[b : b + 1, :n],
            seqs.fixes[b : b + 1, :n],
            objective=objective,
            targets=targets[b : b + 1, :n],
        )
        for b, n in enumerate(lengths)
    ]
    noise = wrong_noise()
    pooled = lambda nz: sum(f(nz) * n for f, n in zip(singles, lengths)) / lengths.sum()
    if not with_gradient:
        np.testing.assert_allclose(jax.jit(padded)(noise), jax.jit(pooled)(noise), rtol=1e-12)
        return
    (v_pad, g_pad), (v_one, g_one) = (jax.jit(jax.value_and_grad(f))(noise) for f in (padded, pooled))
    np.testing.assert_allclose(v_pad, v_one, rtol=1e-12)
    for a, b in zip(jax.tree.leaves(g_pad), jax.tree.leaves(g_one)):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)


def test_supervised_fit_lowers_the_validation_error_with_a_full_measurement_covariance():
    train, val = drives(8, 150, seed=2), drives(8, 150, seed=3)
    model = planar_pose_model()
    weights = jnp.array([1.0, 1.0, 100.0])  # 10 m per radian of yaw
    # (CholeskyCovariance's off-diagonal entries are absolute: at Adam's 0.05 per step they would
    # swamp Q's millimetre-sized diagonal, so Q stays diagonal here.)
    start = Noise(
        DiagonalCovariance.from_std(jnp.asarray(ODOMETRY_STD) / 10),
        CholeskyCovariance.from_matrix(jnp.diag(jnp.asarray(FIX_STD) * 5) ** 2),
    )
    fit = fit_noise(
        model,
        prior_at(train),
        train.increments,
        train.fixes,
        start,
        objective="supervised",
        targets=train.poses[:, 1:],
        state_weights=weights,
        optimizer=optax.adam(0.05),
        iterations=80,
    )
    val_loss = batch_objective(
        model, prior_at(val), val.increments, val.fixes, objective="supervised", targets=val.poses[:, 1:], state_weights=weights
    )
    assert float(val_loss(fit.noise)) < 0.5 * float(val_loss(start))


def test_a_custom_objective_and_clear_errors(as_users_run):
    seqs = drives(2, 20)
    model = planar_pose_model()

    def final_position(result, targets, valid):
        return jnp.sum((result.filtered_mean[-1, :2] - targets[-1, :2]) ** 2)

    loss = batch_objective(
        model, prior_at(seqs), seqs.increments, seqs.fixes, objective=final_position, targets=seqs.poses[:, 1:]
    )
    assert np.isfinite(float(loss(wrong_noise())))
    with pytest.raises(ValueError, match=r"measurements must have shape \(B, T, m\)"):
        batch_objective(model, PRIOR, seqs.increments[0], seqs.fixes[0])
    with pytest.raises(ValueError, match=r"lengths must be 2 integers in \[1, 20\]"):
        batch_objective(model, PRIOR, seqs.increments, seqs.fixes, lengths=jnp.array([20, 21]))
    with pytest.raises(ValueError, match='"supervised" needs targets'):
        batch_objective(model, PRIOR, seqs.increments, seqs.fixes, objective="supervised")
    with pytest.raises(ValueError, match="objective must be"):
        batch_objective(model, PRIOR, seqs.increments, seqs.fixes, objective="mse")
    with pytest.raises(ValueError, match=r"every controls leaf must have leading axes \(2, 20\)"):
        batch_objective(model, PRIOR, seqs.increments[:, :10], seqs.fixes)
