"""The blocked scan: the results of ``lax.scan`` bit for bit (and its gradients), forwards and in
reverse, with and without left-over steps (as a plain program, ``one_kernel=False``); its block
choice; the filters and the smoother with ``block="auto"`` equal to their plain runs step for step
(as plain loops; each compiled as one kernel is tests/filtering/test_cpu_kernel.py's)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.planar import simulate_planar_sequence
from jbevo.filtering import smoother, sqrt_ukf, ukf
from jbevo.filtering.blocked_scan import SEQUENTIAL_BUFFER_BYTES, block_size, blocked_scan
from jbevo.filtering.planar import planar_pose_model
from tests.filtering.references import P0, Q, R

pytestmark = pytest.mark.usefixtures("float64")


def step(carry, inputs):
    """A nonlinear step with a pytree carry and outputs, and a ``None`` input leaf."""
    x, total = carry
    u, skipped = inputs
    assert skipped is None
    x = jnp.tanh(x @ jnp.array([[0.9, 0.2], [-0.3, 0.8]]) + u)
    return (x, total + jnp.sum(x)), {"x": x, "norm": jnp.linalg.norm(x)}


def inputs(steps):
    return jax.random.normal(jax.random.PRNGKey(0), (steps, 2)), None


@pytest.mark.parametrize("steps, block", [(12, 4), (13, 4), (13, 1), (3, 8), (12, "auto"), (13, "auto")])
@pytest.mark.parametrize("reverse", [False, True])
def test_equals_lax_scan_bit_for_bit(steps, block, reverse):
    init = (jnp.array([0.1, -0.2]), jnp.array(0.0))
    expected = jax.lax.scan(step, init, inputs(steps), reverse=reverse)
    got = jax.jit(lambda i, x: blocked_scan(step, i, x, block=block, reverse=reverse, one_kernel=False))(init, inputs(steps))
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(expected), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("reverse", [False, True])
def test_gradients_equal_lax_scan(reverse):
    def loss(x0, scan):
        (_, total), ys = scan(step, (x0, jnp.array(0.0)), inputs(13), reverse=reverse)
        return total + jnp.sum(ys["norm"] ** 2)

    x0 = jnp.array([0.3, 0.1])
    expected = jax.grad(loss)(x0, jax.lax.scan)
    got = jax.grad(loss)(x0, lambda *a, **k: blocked_scan(*a, block=5, one_kernel=False, **k))
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-15)


def test_block_size_fits_the_sequential_threshold():
    init = (jnp.zeros(2), jnp.array(0.0))
    # The widest per-step slice is 2 float64 (16 bytes): 32 steps fit; 96 = 3 x 32.
    assert block_size(step, init, inputs(96), 96) == SEQUENTIAL_BUFFER_BYTES // 16
    # 98 = 2 x 7 x 7: the largest divisor up to 32 is 14, so no step is left over.
    assert block_size(step, init, inputs(98), 98) == 14
    # 97 is prime: the full block, the left-over steps after it.
    assert block_size(step, init, inputs(97), 97) == 32
    # A carry over the threshold, or a step too wide for two per block: a plain scan.
    big = (jnp.zeros(2), jnp.zeros(SEQUENTIAL_BUFFER_BYTES // 8 + 1))
    assert block_size(lambda c, x: (c, x), big, jnp.zeros((10, 2)), 10) == 1
    assert block_size(lambda c, x: (c, x), init, jnp.zeros((10, 40)), 10) == 1


@pytest.mark.parametrize("block", [0, -2, 2.5, "fast"])
def test_bad_block_is_named(block):
    # Wrong types meet the test suite's run-time type checker first (a TypeError naming block).
    with pytest.raises((ValueError, TypeError), match="block"):
        blocked_scan(step, (jnp.zeros(2), jnp.array(0.0)), inputs(4), block=block)


def test_needs_inputs():
    with pytest.raises(ValueError, match="xs"):
        blocked_scan(lambda c, x: (c, c), jnp.zeros(2), None, block=2)


def loops(jitted, *args) -> int:
    """The number of loops in ``jitted``'s program for ``args``."""
    return jitted.lower(*args).as_text().count("stablehlo.while")


@pytest.fixture(scope="module")
def drive():
    seq = simulate_planar_sequence(jax.random.PRNGKey(4), 103, yaw_rate_std=0.2)
    fixes = seq.fixes.at[20:30, :2].set(jnp.nan)  # missing entries cross a block boundary
    return seq, fixes, ukf.GaussianState(seq.poses[0] + jnp.array([0.3, -0.2, 0.05]), jnp.asarray(P0))


@pytest.mark.parametrize("form", [ukf, sqrt_ukf])
def test_filters_with_auto_blocks_equal_their_plain_runs(drive, form):
    seq, fixes, prior = drive
    model = planar_pose_model()

    def filtered(block):
        noise = jnp.asarray(Q), jnp.asarray(R)
        return jax.jit(lambda p: form.filter(model, p, seq.increments, fixes, *noise, block=block, one_kernel=False))

    assert loops(filtered("auto"), prior) > loops(filtered(1), prior) == 1  # the blocks are there
    blocked, plain = filtered("auto")(prior), filtered(1)(prior)
    for name in blocked._fields:
        if name == "log_likelihood":  # a sum over the steps, reduced in another order
            np.testing.assert_allclose(blocked.log_likelihood, plain.log_likelihood, rtol=1e-14)
        else:
            np.testing.assert_array_equal(getattr(blocked, name), getattr(plain, name), err_msg=name)


@pytest.mark.parametrize("recompute", [False, True])
def test_smoother_with_auto_blocks_equals_its_plain_run(drive, recompute):
    seq, fixes, prior = drive
    model = planar_pose_model()
    result = ukf.filter(model, prior, seq.increments, fixes, jnp.asarray(Q), jnp.asarray(R))
    if recompute:
        result = result._replace(smoother_gains=None)

    def smoothed(block):
        return jax.jit(lambda r: smoother.smooth(model, r, seq.increments, jnp.asarray(Q), block=block, one_kernel=False))

    assert loops(smoothed("auto"), result) > loops(smoothed(1), result) == 1
    for a, b in zip(smoothed("auto")(result), smoothed(1)(result), strict=True):
        np.testing.assert_array_equal(a, b)
