"""Data-parallel training: the batch split over four CPU devices gives the one-device result to
round-off (run in a subprocess: the device count is fixed when JAX starts)."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from jbevo.training.data_parallel import DataParallel

SCRIPT = textwrap.dedent(
    """
    import equinox as eqx, jax, jax.numpy as jnp, numpy as np, optax
    from jbevo.training.data_parallel import DataParallel
    from jbevo.training.loop import make_step, train_epochs

    assert len(jax.devices()) == 4

    class Line(eqx.Module):
        w: jax.Array

    def loss(model, batch):  # a mean over the batch's windows
        return jnp.mean((batch[:, :, 0] * model.w[0] + model.w[1] - batch[:, :, 1]) ** 2)

    windows = np.random.default_rng(0).normal(size=(24, 5, 2)).astype(np.float32)
    parallel = DataParallel.create()
    assert parallel.local_rows(8).tolist() == list(range(8))
    try:
        parallel.check_batch(6)
        raise AssertionError("6 windows were split over 4 devices")
    except ValueError as error:
        assert "does not split evenly over 4 devices" in str(error)
    from jbevo.cli.common import CommandError, check_batch
    check_batch(parallel, 8, 4)  # a single short batch of 4
    try:
        check_batch(parallel, 4, 2)
        raise AssertionError("2 windows were split over 4 devices")
    except CommandError as error:
        assert "the training set holds 2 windows, fewer than --batch 4" in str(error)
    for name, par in (("one", None), ("four", parallel)):
        params, static = eqx.partition(Line(jnp.array([0.3, -0.2])), eqx.is_inexact_array)
        optimizer = optax.adam(0.05)
        step = make_step(static, optimizer, loss, par)
        progress = {"epoch": 0, "step": 0}
        for model, opt_state, mean_loss in train_epochs(step, params, static, optimizer.init(params), windows, 8, 0, progress, 3, par):
            pass
        print(name, *np.asarray(model.w).tolist(), mean_loss, progress["step"])
    """
)


def test_four_devices_train_as_one():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    result = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    rows = {line.split()[0]: np.array(line.split()[1:], float) for line in result.stdout.splitlines()}
    assert rows["one"][-1] == rows["four"][-1] == 9  # 3 epochs of 3 steps
    assert not np.allclose(rows["one"][:2], [0.3, -0.2])  # it trained
    np.testing.assert_allclose(rows["four"], rows["one"], rtol=1e-5, atol=1e-6)


def test_a_batch_must_split_evenly_over_the_devices():
    parallel = DataParallel.create()
    assert parallel.size == 1 and parallel.local_rows(3).tolist() == [0, 1, 2]
    parallel.check_batch(3)
    with pytest.raises(ValueError, match="does not split evenly over 1 devices"):
        parallel.check_batch(0)
