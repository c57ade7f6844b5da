"""Small dense linear algebra written as plain ``jnp`` operations.

Filters in jbevo have states of 2 to 6 dimensions. For matrices that small, a LAPACK call per
step (``jnp.linalg.cholesky``, ``jax.scipy.linalg.solve_triangular``) costs far more than the
arithmetic: each is a separate custom call that XLA cannot fuse, and under ``vmap`` it becomes a
batched call with its own overhead. Unrolling the factorisation over the (static) matrix size
turns it into a few dozen elementwise operations that XLA fuses with the rest of the filter step
and vectorises over any batch axes.

All functions take arrays with arbitrary leading batch axes (``...``) and fall back to the LAPACK
path above :data:`UNROLL_MAX` rows, where the unrolled code would grow as n^3 in program size.
Everything is differentiable; gradients stay finite on (nearly) singular input because the
Cholesky pivots are floored (see :func:`cholesky`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

#: Largest matrix size that is factorised by unrolled elementwise code.
UNROLL_MAX = 8

#: Relative floor on Cholesky pivots: a pivot that falls below ``PIVOT_FLOOR * a_jj`` (round-off
#: has made column j dependent on the earlier columns) is raised to it. A no-op on any matrix
#: whose condition number is below ~1/PIVOT_FLOOR.
PIVOT_FLOOR = 1e-12


def symmetrize(a: Float[ArrayLike, "... n n"]) -> Float[Array, "... n n"]:
    """Return ``(a + a^T) / 2``: removes the round-off asymmetry of covariance updates."""
    a = jnp.asarray(a)
    return 0.5 * (a + jnp.swapaxes(a, -1, -2))


def _floored_rsqrt(s: Array, diag: Array) -> Array:
    """1 / sqrt(s), with s floored relative to the original diagonal (double-where safe)."""
    tiny = jnp.finfo(s.dtype).tiny
    floor = jnp.maximum(PIVOT_FLOOR * jnp.abs(diag), tiny)
    return jax.lax.rsqrt(jnp.where(s > floor, s, floor))


def cholesky(a: Float[ArrayLike, "... n n"]) -> Float[Array, "... n n"]:
    """Lower Cholesky factor ``L`` with ``L @ L^T = a`` for symmetric positive definite ``a``.

    Only the lower triangle of ``a`` is read. Pivots are floored at ``PIVOT_FLOOR`` times the
    diagonal entry (a "modified Cholesky" jitter): for a positive definite matrix of reasonable
    condition this changes nothing, and for a matrix that round-off has made singular it returns
    a finite factor of a nearby positive definite matrix instead of NaN. Callers that must
    *reject* non-positive-definite input (user-supplied noise covariances) check
    :func:`is_positive_definite` at their boundary.

    Computed column by column on vectors (right-looking): each column costs one ``rsqrt``, so
    XLA keeps a whole column in one fused kernel.
    """
    a = jnp.asarray(a)
    n = a.shape[-1]
    if n > UNROLL_MAX:
        return jnp.linalg.cholesky(a)
    rest = a  # the trailing Schur complement, shrinking by one row and column per step
    cols = []
    for j in range(n):
        inv_pivot = _floored_rsqrt(rest[..., 0, 0], a[..., j, j])
        col = rest[..., :, 0] * inv_pivot[..., None]  # column j of L from row j down
        cols.append(col)
        rest = rest[..., 1:, 1:] - col[..., 1:, None] * col[..., None, 1:]
    zeros = jnp.zeros_like(a[..., 0, :])
    full = [jnp.concatenate([zeros[..., :j], c], axis=-1) for j, c in enumerate(cols)]
    return jnp.stack(full, axis=-1)


def solve_lower(low: Float[ArrayLike, "... n n"], b: Float[ArrayLike, "... n k"]) -> Float[Array, "... n k"]:
    """Solve ``low @ x = b`` for lower-triangular ``low`` by forward substitution."""
    low, b = jnp.asarray(low), jnp.asarray(b)
    n = low.shape[-1]
    if n > UNROLL_MAX:
        import jax.scipy.linalg as jsl

        return jsl.solve_triangular(low, b, lower=True)
    xs = []
    rest = b  # right-hand side rows i.. with the solved rows' contributions removed
    for i in range(n):
        x = rest[..., 0, :] / low[..., i, i, None]
        xs.append(x)
        rest = rest[..., 1:, :] - low[..., i + 1 :, i, None] * x[..., None, :]
    return jnp.stack(xs, axis=-2)


def whiten(a: Float[ArrayLike, "... n n"], b: Float[ArrayLike, "... n k"]) -> tuple[Float[Array, "... n k"], Float[Array, "..."]]:
    """``L^-1 b`` and ``log det a`` for ``L = cholesky(a)``, without forming ``L``.

    This is all a Kalman update needs of the innovation covariance: with ``b = [Pxz^T | y]``
    it gives the gain factor, the whitened innovation and the log-determinant. The factorisation
    and the forward substitution run together on ``[a | b]`` (right-looking), one ``rsqrt`` per
    column and no division, so XLA fuses each column into one kernel. Pivots are floored as in
    :func:`cholesky`.
    """
    a, b = jnp.asarray(a), jnp.asarray(b)
    n = a.shape[-1]
    if n > UNROLL_MAX:
        low = jnp.linalg.cholesky(a)
        return solve_lower(low, b), logdet_from_cholesky(low)
    rest, rhs = a, b
    xs, log_inv_pivots = [], []
    for j in range(n):
        inv_pivot = _floored_rsqrt(rest[..., 0, 0], a[..., j, j])
        log_inv_pivots.append(jnp.log(inv_pivot))
        col = rest[..., :, 0] * inv_pivot[..., None]
        x = rhs[..., 0, :] * inv_pivot[..., None]
        xs.append(x)
        rest = rest[..., 1:, 1:] - col[..., 1:, None] * col[..., None, 1:]
        rhs = rhs[..., 1:, :] - col[..., 1:, None] * x[..., None, :]
    logdet = -2.0 * sum(log_inv_pivots[1:], log_inv_pivots[0])
    return jnp.stack(xs, axis=-2), logdet


def solve_upper_transposed(low: Float[ArrayLike, "... n n"], b: Float[ArrayLike, "... n k"]) -> Float[Array, "... n k"]:
    """Solve ``low^T @ x = b`` for lower-triangular ``low`` by back substitution."""
    low, b = jnp.asarray(low), jnp.asarray(b)
    n = low.shape[-1]
    if n > UNROLL_MAX:
        import jax.scipy.linalg as jsl

        return jsl.solve_triangular(low, b, lower=True, trans="T")
    xs: dict[int, Array] = {}
    for i in reversed(range(n)):
        s = b[..., i, :]
        for k in range(i + 1, n):
            s = s - low[..., k, i, None] * xs[k]
        xs[i] = s / low[..., i, i, None]
    return jnp.stack([xs[i] for i in range(n)], axis=-2)


def cho_solve(low: Float[ArrayLike, "... n n"], b: Float[ArrayLike, "... n k"]) -> Float[Array, "... n k"]:
    """Solve ``(low @ low^T) x = b`` given the lower Cholesky factor ``low``."""
    return solve_upper_transposed(low, solve_lower(low, b))


def solve(a: Float[ArrayLike, "... n n"], b: Float[ArrayLike, "... n k"]) -> Float[Array, "... n k"]:
    """Solve ``a @ x = b`` for a general (non-symmetric) ``a``: Gaussian elimination with partial
    pivoting on ``[a | b]``, then back substitution. The pivot row is chosen per batch element
    and moved by a one-hot select (no gather, no LAPACK call), so the whole solve is elementwise
    code that XLA fuses and vectorises over the batch axes; differentiable like ``jnp.linalg.solve``
    (the pivot choice is piecewise constant)."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    n = a.shape[-1]
    if n > UNROLL_MAX:
        return jnp.linalg.solve(a, b)
    rest = jnp.concatenate([a, b], axis=-1)  # the rows not yet eliminated, columns j.. of [a | b]
    rows = []  # row j of the upper-triangular system: columns j.. of [U | c]
    for j in range(n):
        pick = jnp.arange(n - j) == jnp.argmax(jnp.abs(rest[..., :, 0]), axis=-1)[..., None]
        pivot = jnp.sum(jnp.where(pick[..., None], rest, 0.0), axis=-2)
        # The pivot's place takes the first row; the first row's slot is then dropped.
        others = jnp.where(pick[..., None], rest[..., :1, :], rest)[..., 1:, :]
        rest = others[..., :, 1:] - (others[..., :, 0] / pivot[..., 0, None])[..., None] * pivot[..., None, 1:]
        rows.append(pivot)
    zeros = jnp.zeros_like(a[..., 0, :])
    upper = jnp.stack([jnp.concatenate([zeros[..., :j], r[..., : n - j]], axis=-1) for j, r in enumerate(rows)], axis=-2)
    rhs = jnp.stack([r[..., n - j :] for j, r in enumerate(rows)], axis=-2)
    return solve_upper_transposed(jnp.swapaxes(upper, -1, -2), rhs)


def matmul(a: Float[ArrayLike, "... n k"], b: Float[ArrayLike, "... k m"]) -> Float[Array, "... n m"]:
    """``a @ b`` as a product and a sum over ``k`` (a reduction, no dot): for the few-number
    products of a filter step, which then stay elementwise code that the step's loop can compile
    as one XLA:CPU kernel (:mod:`jbevo.filtering.cpu_kernel`, which takes no dot)."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    return jnp.sum(a[..., :, :, None] * b[..., None, :, :], axis=-2)


def matvec(a: Float[ArrayLike, "... n k"], x: Float[ArrayLike, "... k"]) -> Float[Array, "... n"]:
    """``a @ x`` for a vector ``x``, as :func:`matmul` does it."""
    a, x = jnp.asarray(a), jnp.asarray(x)
    return jnp.sum(a * x[..., None, :], axis=-1)


def logdet_from_cholesky(low: Float[ArrayLike, "... n n"]) -> Float[Array, "..."]:
    """``log det(low @ low^T)`` from the lower Cholesky factor."""
    low = jnp.asarray(low)
    n = low.shape[-1]
    return 2.0 * sum((jnp.log(low[..., i, i]) for i in range(1, n)), jnp.log(low[..., 0, 0]))


def is_positive_definite(a: Float[ArrayLike, "... n n"]) -> Array:
    """True where ``a`` is finite, symmetric (to round-off) and positive definite.

    Uses LAPACK's Cholesky (no pivot floor), so a singular or indefinite matrix gives False.
    """
    a = jnp.asarray(a)
    finite = jnp.all(jnp.isfinite(a), axis=(-2, -1))
    safe = jnp.where(finite[..., None, None], a, jnp.eye(a.shape[-1], dtype=a.dtype))
    scale = jnp.max(jnp.abs(safe), axis=(-2, -1))
    eps = jnp.finfo(safe.dtype).eps
    sym = jnp.max(jnp.abs(safe - jnp.swapaxes(safe, -1, -2)), axis=(-2, -1)) <= 100 * eps * scale
    chol = jnp.linalg.cholesky(symmetrize(safe))
    pd = jnp.all(jnp.isfinite(chol), axis=(-2, -1)) & jnp.all(jnp.diagonal(chol, axis1=-2, axis2=-1) > 0, axis=-1)
    return finite & sym & pd


__all__ = [
    "PIVOT_FLOOR",
    "UNROLL_MAX",
    "cho_solve",
    "cholesky",
    "is_positive_definite",
    "logdet_from_cholesky",
    "matmul",
    "matvec",
    "solve_lower",
    "solve_upper_transposed",
    "symmetrize",
    "whiten",
]
