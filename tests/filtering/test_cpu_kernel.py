"""One XLA:CPU kernel per loop: which functions it takes (and which it leaves alone), that the
compiled program really holds the one-function call, and that results, batches and gradients are
those of the plain program to round-off."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.filtering import parallel, ukf
from jbevo.filtering.cpu_kernel import LARGE_REDUCTION, batch_size, compiles_as_one_kernel, one_kernel, primitives
from jbevo.filtering.planar import planar_pose_model
from tests.filtering.references import P0, Q, R
from tests.filtering.test_parallel import random_model

pytestmark = pytest.mark.usefixtures("float64")

ON_CPU = jax.default_backend() == "cpu"


def loop(carry, xs):
    """A nonlinear recursion with a pytree carry (the kind of loop a filter is)."""

    def step(c, u):
        x, total = c
        x = jnp.tanh(jnp.array([0.9, 0.8]) * x + jnp.array([0.2, -0.3]) * x[::-1] + u)
        return (x, total + jnp.sum(jnp.sin(x))), x

    return jax.lax.scan(step, carry, xs)


def args():
    return (jnp.array([0.1, -0.2]), jnp.array(0.0)), jax.random.normal(jax.random.PRNGKey(0), (50, 2))


def small_calls(fn, *a) -> int:
    """How many one-function calls the compiled program of ``fn(*a)`` holds."""
    return jax.jit(fn).lower(*a).compile().as_text().count('xla_cpu_small_call="true"')


def test_primitives_include_nested_jaxprs():
    def f(x):
        return jax.lax.cond(x[0] > 0, lambda y: jax.lax.scan(lambda c, v: (c * v, c), 1.0, y)[1], jnp.cos, x)

    names = primitives(jax.make_jaxpr(f)(jnp.ones(3)).jaxpr)
    assert {"cond", "scan", "mul", "cos"} <= names


def test_takes_elementwise_loops_and_leaves_library_calls_alone():
    carry, xs = args()
    assert compiles_as_one_kernel(loop, carry, xs)
    # LAPACK, FFT, sort, gather (whose transpose is a scatter) and matrix products are not
    # one-function code.
    assert not compiles_as_one_kernel(lambda a: jnp.linalg.cholesky(a @ a.T + jnp.eye(3)), jnp.eye(3))
    assert not compiles_as_one_kernel(lambda a: jnp.fft.fft(a).real, jnp.ones(8))
    assert not compiles_as_one_kernel(jnp.sort, jnp.ones(8))
    assert not compiles_as_one_kernel(lambda a, i: a[i], jnp.ones(8), jnp.array([1, 3]))
    assert not compiles_as_one_kernel(lambda a: jax.pure_callback(np.sin, a, a), jnp.ones(2))
    assert not compiles_as_one_kernel(lambda a: a @ a, jnp.ones((4, 4)))


@pytest.mark.skipif(not ON_CPU, reason="the one-function call is XLA:CPU's")
def test_compiled_program_holds_the_call_only_where_taken():
    carry, xs = args()
    assert small_calls(one_kernel(loop), carry, xs) >= 1

    # A loop with a LAPACK call runs as it is, and runs.
    def with_lapack(a):
        return jax.lax.scan(lambda c, _: (jnp.linalg.cholesky(c @ c.T + jnp.eye(2)), c[0, 0]), a, jnp.arange(3.0))

    assert small_calls(one_kernel(with_lapack), jnp.eye(2)) == 0
    np.testing.assert_allclose(jax.jit(one_kernel(with_lapack))(jnp.eye(2))[1], with_lapack(jnp.eye(2))[1])


def test_equals_plain_program_batched_and_differentiated():
    carry, xs = args()
    fused = jax.jit(one_kernel(loop))
    for a, b in zip(jax.tree.leaves(fused(carry, xs)), jax.tree.leaves(jax.jit(loop)(carry, xs)), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13)

    batch = jax.random.normal(jax.random.PRNGKey(1), (4, 50, 2))
    got = jax.jit(jax.vmap(one_kernel(loop), in_axes=(None, 0)))(carry, batch)
    want = jax.vmap(loop, in_axes=(None, 0))(carry, batch)
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13)

    def total(x0, fn):
        return fn((x0, jnp.array(0.0)), xs)[0][1]

    grad = jax.jit(jax.grad(lambda x0: total(x0, one_kernel(loop))))(carry[0])
    np.testing.assert_allclose(grad, jax.grad(lambda x0: total(x0, loop))(carry[0]), rtol=1e-12)
    eps = 1e-6
    fd = [(total(carry[0].at[i].add(eps), loop) - total(carry[0].at[i].add(-eps), loop)) / (2 * eps) for i in range(2)]
    np.testing.assert_allclose(grad, fd, rtol=1e-6)


@pytest.mark.skipif(not ON_CPU, reason="the one-function call is XLA:CPU's")
def test_localization_ukf_and_its_gradient_compile_as_one_kernel():
    """The filters take it through their scans: the UKF and its gradient with respect to Q hold the
    call, and equal the same filter with the plain loop."""
    model = planar_pose_model()
    steps = 2000  # too large for XLA:CPU to make the plain loop one function by itself
    u = jnp.tile(jnp.array([0.5, 0.0, 0.02]), (steps, 1))
    z = jnp.cumsum(u, axis=0) + 0.1

    def ll(q_scale, one_kernel=True):
        prior = ukf.GaussianState(jnp.zeros(3), jnp.asarray(P0))
        noise = q_scale * jnp.asarray(Q), jnp.asarray(R)
        return ukf.filter(model, prior, u, z, *noise, check_inputs=False, one_kernel=one_kernel).log_likelihood

    assert small_calls(ll, 1.0) >= 1
    assert small_calls(jax.grad(ll), 1.0) >= 1
    fused = jax.jit(jax.value_and_grad(ll))(1.3)
    assert small_calls(lambda q: ll(q, one_kernel=False), 1.0) == 0
    plain = jax.jit(jax.value_and_grad(lambda q: ll(q, one_kernel=False)))(1.3)
    np.testing.assert_allclose(fused, plain, rtol=1e-12)


@pytest.mark.skipif(not ON_CPU, reason="the one-function call is XLA:CPU's")
def test_affine_sequential_filter_and_smoother_compile_as_one_kernel():
    """The Kalman filter and RTS smoother of the IPLS's sequential pass hold the call (a model
    with missing entries and a step without data) and equal their plain loops, value and
    gradient."""
    model, prior = random_model(steps=2000)

    def total(scale, one_kernel=True):
        m = model._replace(transition_cov=scale * model.transition_cov)
        filtered = parallel.sequential_filter(m, prior, one_kernel=one_kernel)
        smoothed = parallel.sequential_smoother(m, filtered, one_kernel=one_kernel)
        return jnp.sum(filtered.log_likelihoods) + jnp.sum(smoothed.mean) + jnp.sum(smoothed.cov)

    assert small_calls(total, 1.0) >= 2 and small_calls(jax.grad(total), 1.0) >= 2
    assert small_calls(lambda s: total(s, one_kernel=False), 1.0) == 0
    fused = jax.jit(jax.value_and_grad(total))(1.3)
    plain = jax.jit(jax.value_and_grad(lambda s: total(s, one_kernel=False)))(1.3)
    np.testing.assert_allclose(fused, plain, rtol=1e-12)


@pytest.mark.skipif(not ON_CPU, reason="the one-function call is XLA:CPU's")
def test_constant_operands_compile():
    """Operands that XLA knows at compile time (trace-time arrays, data computed inside ``jit``
    from constants alone, a large captured table): without the barrier in front of the call, such
    an operand of 10 kB or more makes XLA abort the process."""
    steps = 2000
    model = planar_pose_model()
    prior = ukf.GaussianState(jnp.zeros(3), jnp.asarray(P0))

    def ll(q_scale, u, z):
        return ukf.filter(model, prior, u, z, q_scale * jnp.asarray(Q), jnp.asarray(R), check_inputs=False).log_likelihood

    u_known = jnp.tile(jnp.array([0.5, 0.0, 0.02]), (steps, 1))
    z_known = jnp.cumsum(u_known, axis=0) + 0.1
    from_args = jax.jit(ll)(1.0, u_known, z_known)

    def folded(q_scale):
        u = jnp.tile(jnp.array([0.5, 0.0, 0.02]), (steps, 1))
        return ll(q_scale, u, jnp.cumsum(u, axis=0) + 0.1)

    np.testing.assert_allclose(jax.jit(folded)(1.0), from_args, rtol=1e-12)
    np.testing.assert_allclose(jax.jit(lambda q: ll(q, u_known, z_known))(1.0), from_args, rtol=1e-12)
    np.testing.assert_allclose(jax.jit(jax.grad(folded))(1.0), jax.grad(lambda q: ll(q, u_known, z_known))(1.0), rtol=1e-10)

    table = np.linspace(0.0, 1.0, 4000).reshape(1000, 4)  # 32 kB, read a row per step

    def with_table(carry, xs):
        def step(c, x):
            value, t = c
            row = jax.lax.dynamic_slice(jnp.asarray(table), (t % 1000, 0), (1, 3))[0]
            return (0.9 * value + x + row, t + 1), value

        return jax.lax.scan(step, carry, xs)

    start, xs = (jnp.zeros(3), jnp.array(0)), jnp.ones((3000, 3))
    assert small_calls(one_kernel(with_table), start, xs) >= 1
    np.testing.assert_allclose(jax.jit(one_kernel(with_table))(start, xs)[1], with_table(start, xs)[1], rtol=1e-13)


def test_batch_size_counts_the_copies_of_enclosing_vmaps():
    seen = []

    def record(x):
        seen.append(batch_size(x, 1.0))
        return jnp.sum(x**2)

    x = jnp.ones((4, 3, 2))
    record(x[0, 0])
    jax.jit(jax.vmap(record))(x[0])
    jax.jit(jax.vmap(jax.vmap(record)))(x)
    jax.grad(lambda a: jnp.sum(jax.vmap(record)(a)))(x[0])
    jax.jit(jax.vmap(jax.grad(record)))(x[0])
    assert seen == [1, 3, 12, 3, 3]


@pytest.mark.skipif(not ON_CPU, reason="the one-function call is XLA:CPU's")
@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_a_large_batch_runs_as_the_plain_loop(dtype):
    """Batched, a sum over sigma points' outer products in a loop reaches XLA:CPU's size for
    handing reductions to YNNPACK, which the one-function call cannot run (compiling failed):
    such a batch is left to the plain loop, a small one keeps the call, and both compute."""

    def covariances(points):
        def step(total, xi):
            w = jnp.arange(11, dtype=dtype)
            total = total + jnp.sum(w[:, None, None] * xi[:, :, None] * xi[:, None, :], axis=0)
            return total, total[0]

        return jax.lax.scan(step, jnp.zeros((5, 5), dtype), points)

    points = jax.random.normal(jax.random.PRNGKey(1), (64, 6, 11, 5), dtype)
    assert 64 * 11 * 25 >= LARGE_REDUCTION > 2 * 11 * 25
    for batch, calls in ((64, 0), (2, 1)):
        fused = jax.vmap(one_kernel(covariances))
        assert (small_calls(fused, points[:batch]) > 0) == bool(calls)
        for a, b in zip(jax.jit(fused)(points[:batch]), jax.vmap(covariances)(points[:batch]), strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-5 if dtype == jnp.float32 else 1e-12)


@pytest.mark.skipif(not ON_CPU, reason="the one-function call is XLA:CPU's")
def test_the_ukf_vmapped_over_many_sequences_compiles():
    model = planar_pose_model()
    u = jnp.tile(jnp.array([0.5, 0.0, 0.02]), (100, 20, 1))
    z = jnp.cumsum(u, axis=1) + 0.1

    def means(u, z, one_kernel=True):
        prior = ukf.GaussianState(jnp.zeros(3), jnp.asarray(P0))
        return ukf.filter(model, prior, u, z, jnp.asarray(Q), jnp.asarray(R), one_kernel=one_kernel).filtered_mean

    np.testing.assert_allclose(
        jax.jit(jax.vmap(means))(u, z), jax.vmap(lambda a, b: means(a, b, one_kernel=False))(u, z), rtol=1e-12
    )
