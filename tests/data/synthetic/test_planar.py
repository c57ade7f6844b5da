import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.planar import simulate_planar_sequence
from jbevo.geometry.se2 import se2_between


def test_deterministic_shapes_and_noise_levels():
    a = simulate_planar_sequence(jax.random.PRNGKey(0), 2000, fix_dropout=0.25)
    b = simulate_planar_sequence(jax.random.PRNGKey(0), 2000, fix_dropout=0.25)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert a.poses.shape == (2001, 3) and a.increments.shape == (2000, 3) and a.fixes.shape == (2000, 3)
    missing = np.isnan(np.asarray(a.fixes[:, 0]))
    assert 0.2 < missing.mean() < 0.3
    true_inc = se2_between(a.poses[:-1], a.poses[1:])
    np.testing.assert_allclose(np.std(np.asarray(a.increments - true_inc), axis=0), [0.02, 0.01, 0.005], rtol=0.1)
    fix_err = np.asarray(a.fixes - a.poses[1:])[~missing]
    np.testing.assert_allclose(np.std(fix_err[:, :2], axis=0), [0.5, 0.5], rtol=0.1)
    assert np.all(np.abs(np.asarray(a.poses[:, 2])) <= np.pi)


def test_vmaps_over_keys_and_rejects_bad_arguments():
    seqs = jax.vmap(lambda k: simulate_planar_sequence(k, 10))(jax.random.split(jax.random.PRNGKey(1), 4))
    assert seqs.poses.shape == (4, 11, 3)
    assert simulate_planar_sequence(jax.random.PRNGKey(1), 5, dtype=jnp.float32).fixes.dtype == jnp.float32
    with pytest.raises(ValueError, match="steps"):
        simulate_planar_sequence(jax.random.PRNGKey(0), 0)
    with pytest.raises(ValueError, match="fix_dropout"):
        simulate_planar_sequence(jax.random.PRNGKey(0), 5, fix_dropout=1.5)
