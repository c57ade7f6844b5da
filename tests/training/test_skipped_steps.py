"""A step whose gradient is not finite (with a finite loss) is skipped, counted and reported; too
many in a row end the run as divergence."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.training.loop import MAX_SKIPPED_IN_A_ROW, TrainingDiverged, make_step, run_epoch, skipped_steps, start_run


class Scale(eqx.Module):
    w: jnp.ndarray


def norm_loss(model, batch):
    # |w b| has a finite value (0) but a NaN gradient (0 / 0) where b is 0.
    return jnp.sqrt(jnp.sum((model.w * batch) ** 2))


def setup(tmp_path):
    model, params, static, optimizer, opt_state, progress = start_run(Scale(jnp.ones(2)), tmp_path, 0.1, 1.0, False, "best")
    return make_step(static, optimizer, norm_loss), params, opt_state, progress


def test_a_non_finite_gradient_skips_the_update_and_is_counted(tmp_path, capsys):
    step, params, opt_state, progress = setup(tmp_path)
    assert progress["skipped_steps"] == 0
    windows = jnp.array([[1.0, 2.0], [0.0, 0.0], [2.0, 1.0], [0.0, 0.0]])
    params, opt_state, mean_loss, steps = run_epoch(step, params, opt_state, windows, 1, np.random.default_rng(0), "epoch 1")
    assert steps == 4 and np.isfinite(mean_loss)
    assert skipped_steps(opt_state) == 2
    assert np.all(np.isfinite(np.asarray(params.w))) and not np.allclose(params.w, 1.0)  # the finite steps moved it
    assert capsys.readouterr().err.count("the gradient is not finite; the update was skipped") == 2

    # A skipped step leaves the parameters exactly where they were.
    same, _, _ = step(params, opt_state, jnp.zeros((1, 2)))
    np.testing.assert_array_equal(same.w, params.w)


def test_too_many_non_finite_gradients_in_a_row_end_the_run(tmp_path):
    step, params, opt_state, _ = setup(tmp_path)
    windows = jnp.zeros((MAX_SKIPPED_IN_A_ROW + 2, 2))
    with pytest.raises(TrainingDiverged, match="the loss became nan at epoch 1"):
        run_epoch(step, params, opt_state, windows, 1, np.random.default_rng(0), "epoch 1")
