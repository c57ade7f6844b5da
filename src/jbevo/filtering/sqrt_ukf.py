"""The square-root unscented Kalman filter: the belief carried as a lower Cholesky factor.

The same model, step order, missing-data semantics and results as :mod:`jbevo.filtering.ukf`
(equal to round-off in float64), but no covariance is ever formed and differenced: every factor
comes from a QR decomposition of a stack of weighted square roots, ``tria(A) = L`` with
``L L^T = A A^T`` (:func:`tria`), so it is positive semi-definite by construction, and the
conditioning that matters is that of the factor (the square root of the covariance's).

* Predict: ``L^- = tria([sqrt(Wc_i) dy_i | chol(Q)])``; a negative central weight ``Wc_0``
  leaves the central point out of the ``tria`` and takes its term off by a rank-one Cholesky
  downdate.
* Update: one ``tria`` of the joint square roots of the measurement and the state,
  ``[[sqrt(Wc_i) dz_i, chol(R)], [sqrt(Wc_i) dx_i, 0]]`` (and the central term), which is
  ``[[L_S, 0], [P_xz L_S^-T, L^+]]``: the innovation's factor, the whitened gain ``W^T`` and the
  posterior's factor, with ``L^+ L^+T = P - W^T W`` computed as a sum of squares, never a
  difference; the mean moves by ``W^T L_S^-1 y`` (one triangular solve).
* Missing entries (NaN, or ``mask`` False): their rows of the sigma points' square roots of ``S``
  are zeroed and the noise's factor is that of R with their rows and columns replaced by the
  identity (``chol(R)`` itself when nothing is missing), which is the covariance form's
  replacement of their rows and columns of ``S`` by the identity; their columns of the gain are
  then zero. That factor is computed every step (R formed from its factor, ``chol(R) chol(R)^T``,
  and factored again) and selected where an entry is missing: an ``m x m`` noise block keeps the
  update's stack at ``m + n`` rows by ``2n + 1 + m`` columns.

The weights of the default :class:`~jbevo.filtering.unscented.MerweScaled` scheme have
``Wc_0 = 2 > 0``; schemes with a negative ``Wc_0`` use the downdate, which needs the result to
stay positive definite (as the covariance form does).
"""

from __future__ import annotations

from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from jbevo.filtering import linalg
from jbevo.filtering.blocked_scan import blocked_scan
from jbevo.filtering.ukf import (
    _LOG_2PI,
    GaussianState,
    Scheme,
    StateSpaceModel,
    _noise_at,
    _sequence_inputs,
    constant_or_sequence,
)
from jbevo.filtering.unscented import MerweScaled, offset_points, residuals, sigma_offsets, weighted_mean


class SqrtGaussianState(NamedTuple):
    """A Gaussian belief: mean ``(n,)`` and lower Cholesky factor ``(n, n)`` of its covariance."""

    mean: Float[Array, " n"]
    chol: Float[Array, "n n"]

    @classmethod
    def from_gaussian(cls, state: GaussianState) -> SqrtGaussianState:
        """The factored form of a mean-and-covariance belief."""
        return cls(state.mean, linalg.cholesky(state.cov))

    def to_gaussian(self) -> GaussianState:
        """The mean-and-covariance form."""
        return GaussianState(self.mean, self.chol @ jnp.swapaxes(self.chol, -1, -2))


class SqrtFilterResult(NamedTuple):
    """Output of :func:`filter`: as :class:`jbevo.filtering.ukf.FilterResult`, with lower
    Cholesky factors in place of covariances."""

    filtered_mean: Float[Array, "T n"]
    filtered_chol: Float[Array, "T n n"]
    predicted_mean: Float[Array, "T n"]
    predicted_chol: Float[Array, "T n n"]
    log_likelihoods: Float[Array, " T"]
    log_likelihood: Float[Array, ""]

    def covariances(self) -> tuple[Float[Array, "T n n"], Float[Array, "T n n"]]:
        """``(filtered, predicted)`` covariances ``L L^T``."""
        square = lambda c: c @ jnp.swapaxes(c, -1, -2)
        return square(self.filtered_chol), square(self.predicted_chol)


def tria(a: Float[Array, "n k"]) -> Float[Array, "n n"]:
    """The lower-triangular ``L`` with ``L L^T = a a^T`` and a non-negative diagonal (``k >= n``).

    Up to :data:`~jbevo.filtering.linalg.UNROLL_MAX` rows: modified Gram-Schmidt on the rows of
    ``a`` (``L`` is the R factor of ``a^T``'s QR decomposition, transposed; MGS computes that
    factor as accurately as Householder QR does, only its Q loses orthogonality, and Q is not
    needed), as unrolled elementwise code that XLA fuses (``benchmarks/ukf.py`` times the filter
    with it against the filter with LAPACK's QR in its place). Above, LAPACK's QR of ``a^T``
    (``L = R^T``, signs fixed)."""
    n, k = a.shape
    if k < n:
        raise ValueError(f"tria needs at least as many columns as rows, got {a.shape}")
    if n > linalg.UNROLL_MAX:
        r = jnp.linalg.qr(a.T, mode="r")
        return (r * jnp.where(jnp.diagonal(r) < 0, -1.0, 1.0).astype(a.dtype)[:, None]).T
    tiny = jnp.finfo(a.dtype).tiny
    cols, rest = [], a  # rest: the rows not yet orthogonalised, less their projections so far
    for j in range(n):
        norm = jnp.sqrt(jnp.sum(rest[0] * rest[0]) + tiny)
        q = rest[0] / norm
        below = jnp.sum(rest[1:] * q[None, :], axis=1)  # column j of L under the diagonal
        cols.append(jnp.concatenate([jnp.zeros(j, a.dtype), norm[None], below]))
        rest = rest[1:] - below[:, None] * q[None, :]
    return jnp.stack(cols, axis=1)


def rank_one(low: Float[Array, "n n"], x: Float[Array, " n"], sign: float) -> Float[Array, "n n"]:
    """The Cholesky factor of ``low low^T + sign * x x^T`` (``sign`` +1: update, -1: downdate),
    column by column (unrolled; the downdate's pivots floored as :func:`linalg.cholesky`'s)."""
    n = low.shape[-1]
    cols = [low[:, j] for j in range(n)]
    for k in range(n):
        lkk, xk = cols[k][k], x[k]
        r2 = lkk**2 + sign * xk**2
        floor = jnp.maximum(linalg.PIVOT_FLOOR * lkk**2, jnp.finfo(low.dtype).tiny)
        r = jnp.sqrt(jnp.where(r2 > floor, r2, floor))
        c, s = r / lkk, xk / lkk
        col = jnp.where(np.arange(n) == k, r, (cols[k] + sign * s * x) / c)
        x = c * x - s * col
        cols[k] = jnp.where(np.arange(n) >= k, col, 0.0)
    return jnp.stack(cols, axis=-1)


def _factor(scheme: Scheme, weights: Array, d: Array, extra: Array) -> Array:
    """Lower factor of ``sum_i w_i d_i d_i^T + extra extra^T`` (rows of ``d`` are the points;
    ``weights`` are ``scheme``'s covariance weights): one ``tria`` of the weighted points and
    ``extra``, the central point among them where its weight is positive, else a rank-one
    downdate with it afterwards."""
    with jax.ensure_compile_time_eval():  # the central weight's sign picks the code path
        w0 = float(scheme.weights((d.shape[0] - 1) // 2, d.dtype).cov[0])
    first = 0 if w0 > 0 else 1
    low = tria(jnp.concatenate([(jnp.sqrt(jnp.abs(weights[first:]))[:, None] * d[first:]).T, extra], axis=1))
    return low if w0 >= 0 else rank_one(low, abs(w0) ** 0.5 * d[0], -1.0)


def predict(
    model: StateSpaceModel,
    state: SqrtGaussianState,
    control: Any,
    motion_chol: Float[Array, "n n"],
    scheme: Scheme = MerweScaled(),
) -> SqrtGaussianState:
    """Propagate ``state`` through ``model.motion(x, control)`` with motion noise of lower
    Cholesky factor ``motion_chol``."""
    mean, chol = state
    w = scheme.weights(mean.shape[-1], mean.dtype)
    moved = jax.vmap(model.motion, in_axes=(0, None))(
        offset_points(mean, sigma_offsets(chol, w.spread), model.state_add), control
    )
    new_mean = weighted_mean(moved, w.mean, model.state_mean)
    return SqrtGaussianState(new_mean, _factor(scheme, w.cov, residuals(moved, new_mean, model.state_residual), motion_chol))


def update(
    model: StateSpaceModel,
    state: SqrtGaussianState,
    measurement: Float[Array, " m"],
    measurement_chol: Float[Array, "m m"],
    scheme: Scheme = MerweScaled(),
    mask: Bool[Array, " m"] | None = None,
    measurement_input: Any = None,
) -> tuple[SqrtGaussianState, Float[Array, ""]]:
    """Condition ``state`` on ``measurement`` (noise of lower Cholesky factor
    ``measurement_chol``); missing entries as :func:`jbevo.filtering.ukf.update`. Returns the
    posterior and ``log p(measurement)``."""
    mean, chol = state
    w = scheme.weights(mean.shape[-1], mean.dtype)
    dx = sigma_offsets(chol, w.spread)
    points = offset_points(mean, dx, model.state_add)
    if measurement_input is None:
        z_points = jax.vmap(model.measurement)(points)
    else:
        z_points = jax.vmap(model.measurement, in_axes=(0, None))(points, measurement_input)
    z_pred = weighted_mean(z_points, w.mean, model.measurement_mean)
    dz = residuals(z_points, z_pred, model.measurement_residual)

    observed = jnp.isfinite(measurement)
    if mask is not None:
        observed = observed & mask
    z_safe = jnp.where(observed, measurement, z_pred)
    innovation = z_safe - z_pred if model.measurement_residual is None else model.measurement_residual(z_safe, z_pred)
    innovation = jnp.where(observed, innovation, 0.0)
    m, n = measurement.shape[-1], mean.shape[-1]
    # The noise's factor with the missing entries' rows and columns of R replaced by the identity,
    # as one m x m factor: chol(R) itself when all are observed, else the factor of that matrix
    # (an m x m block keeps the joint stack below at m + n rows by 2n + 1 + m columns).
    dz_seen = jnp.where(observed[None, :], dz, 0.0)
    both = observed[:, None] & observed[None, :]
    r = jnp.sum(measurement_chol[:, None, :] * measurement_chol[None, :, :], axis=-1)
    partial = linalg.cholesky(jnp.where(both, r, jnp.eye(m, dtype=mean.dtype)))
    noise = jnp.where(jnp.all(observed), measurement_chol, partial)
    # One factorisation of the joint second moments of (z, x): tria of the stacked points
    # [[dz, noise], [dx, 0]] is [[L_S, 0], [Pxz L_S^-T, L_post]].
    joint = _factor(
        scheme, w.cov, jnp.concatenate([dz_seen, dx], axis=1), jnp.concatenate([noise, jnp.zeros((n, m), mean.dtype)])
    )
    s_chol, whitened_gain_t, new_chol = joint[:m, :m], joint[m:, :m], joint[m:, m:]
    e = linalg.solve_lower(s_chol, innovation[:, None])[:, 0]
    correction = linalg.matvec(whitened_gain_t, e)
    new_mean = correction + mean if model.state_add is None else model.state_add(mean, correction)
    logdet = linalg.logdet_from_cholesky(s_chol)
    log_lik = -0.5 * (jnp.sum(e * e) + logdet + jnp.sum(observed).astype(mean.dtype) * _LOG_2PI)
    return SqrtGaussianState(new_mean, new_chol), log_lik


def filter(
    model: StateSpaceModel,
    initial: SqrtGaussianState | GaussianState,
    controls: Any,
    measurements: Float[Array, "T m"],
    motion_cov: Float[Array, "n n"] | Float[Array, "T n n"],
    measurement_cov: Float[Array, "m m"] | Float[Array, "T m m"],
    *,
    scheme: Scheme = MerweScaled(),
    mask: Bool[Array, "T m"] | None = None,
    check_inputs: bool = True,
    unroll: int = 1,
    measurement_inputs: Any = None,
    block: int | Literal["auto"] = 1,
    one_kernel: bool = True,
) -> SqrtFilterResult:
    """Run the square-root UKF over a sequence with ``jax.lax.scan``: the arguments and their
    checks as :func:`jbevo.filtering.ukf.filter` (Q and R as covariances, factored once, or per
    step if they have a time axis; ``block`` and ``one_kernel`` as there); ``initial`` as a factor or as a
    covariance."""
    if isinstance(initial, SqrtGaussianState):
        initial = initial.to_gaussian()
    initial, controls, measurements, motion_cov, measurement_cov, mask = _sequence_inputs(
        model, initial, controls, measurements, motion_cov, measurement_cov, mask, check_inputs, measurement_inputs
    )
    start = SqrtGaussianState.from_gaussian(initial)
    q_chol, r_chol = linalg.cholesky(motion_cov), linalg.cholesky(measurement_cov)
    q_const, q_seq = constant_or_sequence(q_chol)
    r_const, r_seq = constant_or_sequence(r_chol)

    def body(state, inputs):
        control, z, z_mask, q_t, r_t, z_input = inputs
        predicted = predict(model, state, control, _noise_at(q_const, q_t), scheme)
        filtered, ll = update(model, predicted, z, _noise_at(r_const, r_t), scheme, z_mask, z_input)
        return filtered, (filtered, predicted, ll)

    _, (filtered, predicted, lls) = blocked_scan(
        body,
        start,
        (controls, measurements, mask, q_seq, r_seq, measurement_inputs),
        block=block,
        unroll=unroll,
        one_kernel=one_kernel,
    )
    return SqrtFilterResult(filtered.mean, filtered.chol, predicted.mean, predicted.chol, lls, jnp.sum(lls))


__all__ = ["SqrtFilterResult", "SqrtGaussianState", "filter", "predict", "rank_one", "tria", "update"]
