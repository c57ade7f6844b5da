"""Sigma points, weights and the unscented transform (pure JAX).

A point set ("scheme") gives ``2n + 1`` sigma points for an ``n``-dimensional Gaussian:
the mean and the mean plus and minus ``spread`` times each column of the lower Cholesky factor of
the covariance, with weights for the mean and for the covariance.

Schemes
-------
:class:`MerweScaled` (van der Merwe's scaled points) with ``lambda = alpha^2 (n + kappa) - n``,
``spread = sqrt(n + lambda)``, ``Wm0 = lambda / (n + lambda)``,
``Wc0 = Wm0 + 1 - alpha^2 + beta`` and ``Wm_i = Wc_i = 1 / (2 (n + lambda))``.
Defaults here are ``alpha = 1, beta = 2, kappa = 0``: then ``lambda = 0``, the mean weights are all
non-negative (``Wm0 = 0``) and the points lie at ``sqrt(n)`` standard deviations, which is well
conditioned in float32 for the 2- and 3-dimensional filters of BEVO. Peers disagree on defaults:
dynamax uses ``alpha = sqrt(3), beta = 2, kappa = 1`` (points at ``sqrt(3 (n + 1))`` standard
deviations), filterpy has no default; the classic ``alpha = 1e-3`` gives weights of order ``-1e6``
and is unusable in float32.

:class:`Julier` (Julier and Uhlmann's symmetric set) with ``spread = sqrt(n + kappa)``,
``W0 = kappa / (n + kappa)``, ``Wi = 1 / (2 (n + kappa))``; ``kappa = 3 - n`` by default, which
matches the fourth moment of a Gaussian. It equals ``MerweScaled(alpha=1, beta=0, kappa)``.

Angles
------
States and measurements that hold angles (yaw) need a mean and a difference on the circle: pass
``mean_fn``/``residual_fn``/``add_fn``, for example those made by :func:`circular_mean_fn`,
:func:`wrapped_residual_fn` and :func:`wrapped_add_fn`. Signatures follow filterpy:
``mean_fn(points[N, d], weights[N]) -> [d]``, ``residual_fn(a[d], b[d]) -> a - b``,
``add_fn(x[d], dx[d]) -> x + dx``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jbevo.filtering import linalg
from jbevo.geometry.angles import wrap_angle

MeanFn = Callable[[Array, Array], Array]
ResidualFn = Callable[[Array, Array], Array]
AddFn = Callable[[Array, Array], Array]


class SigmaWeights(NamedTuple):
    """Weights of a sigma-point set for an ``n``-dimensional state."""

    mean: Float[Array, " N"]  #: weights for the mean, N = 2n + 1, sum to one
    cov: Float[Array, " N"]  #: weights for the (cross-)covariance
    spread: Float[Array, ""]  #: points lie at mean +- spread * columns of chol(P)


class MerweScaled(eqx.Module):
    """Van der Merwe's scaled sigma points (see the module docstring for the formulas)."""

    alpha: float = eqx.field(static=True, default=1.0, converter=float)
    beta: float = eqx.field(static=True, default=2.0, converter=float)
    kappa: float = eqx.field(static=True, default=0.0, converter=float)

    def __check_init__(self):
        if not self.alpha > 0:
            raise ValueError(f"MerweScaled: alpha must be > 0, got {self.alpha}")

    def weights(self, n: int, dtype=None) -> SigmaWeights:
        """Weights for an ``n``-dimensional state, in ``dtype`` (default: JAX's float)."""
        if n < 1:
            raise ValueError(f"state dimension must be >= 1, got {n}")
        lam = self.alpha**2 * (n + self.kappa) - n
        if not n + lam > 0:
            raise ValueError(
                f"MerweScaled(alpha={self.alpha}, kappa={self.kappa}) gives n + lambda = {n + lam} <= 0 "
                f"for n = {n}; increase alpha or kappa"
            )
        c = 0.5 / (n + lam)
        wm = np.full(2 * n + 1, c)
        wc = np.full(2 * n + 1, c)
        wm[0] = lam / (n + lam)
        wc[0] = wm[0] + (1.0 - self.alpha**2 + self.beta)
        return _as_weights(wm, wc, np.sqrt(n + lam), dtype)


class Julier(eqx.Module):
    """Julier and Uhlmann's symmetric sigma points; ``kappa=None`` means ``3 - n``."""

    kappa: float | None = eqx.field(static=True, default=None, converter=lambda k: None if k is None else float(k))

    def weights(self, n: int, dtype=None) -> SigmaWeights:
        """Weights for an ``n``-dimensional state, in ``dtype`` (default: JAX's float)."""
        if n < 1:
            raise ValueError(f"state dimension must be >= 1, got {n}")
        kappa = 3.0 - n if self.kappa is None else self.kappa
        if not n + kappa > 0:
            raise ValueError(f"Julier(kappa={kappa}) needs n + kappa > 0 for n = {n}")
        w = np.full(2 * n + 1, 0.5 / (n + kappa))
        w[0] = kappa / (n + kappa)
        return _as_weights(w, w.copy(), np.sqrt(n + kappa), dtype)


def _as_weights(wm, wc, spread, dtype) -> SigmaWeights:
    dtype = dtype or jnp.result_type(float)
    return SigmaWeights(jnp.asarray(wm, dtype), jnp.asarray(wc, dtype), jnp.asarray(spread, dtype))


def sigma_offsets(chol: Float[Array, "n n"], spread: Float[Array, ""]) -> Float[Array, "N n"]:
    """The ``2n + 1`` sigma-point offsets ``[0, s L_1 .. s L_n, -s L_1 .. -s L_n]`` from the mean.

    They are also the exact residuals of the sigma points from their mean, which saves
    recomputing (and re-wrapping) them where the points were just drawn.
    """
    offsets = spread * jnp.swapaxes(chol, -1, -2)  # row i = column i of chol
    return jnp.concatenate([jnp.zeros_like(offsets[:1]), offsets, -offsets], axis=0)


def offset_points(mean: Float[Array, " n"], offsets: Float[Array, "N n"], add_fn: AddFn | None = None):
    """``mean + offsets[k]`` for every row (``add_fn`` replaces ``+`` for angles)."""
    if add_fn is None:
        return mean + offsets
    return jax.vmap(add_fn, in_axes=(None, 0))(mean, offsets)


def sigma_points(
    mean: Float[Array, " n"],
    chol: Float[Array, "n n"],
    spread: Float[Array, ""],
    add_fn: AddFn | None = None,
) -> Float[Array, "N n"]:
    """The ``2n + 1`` sigma points ``[m, m + s L_1 .. m + s L_n, m - s L_1 .. m - s L_n]``.

    ``chol`` is the lower Cholesky factor ``L`` of the covariance (columns ``L_i``); ``add_fn``
    replaces ``+`` (for angles). The order matches filterpy's ``MerweScaledSigmaPoints``.
    """
    return offset_points(mean, sigma_offsets(chol, spread), add_fn)


def weighted_mean(points: Float[Array, "N d"], weights: Float[Array, " N"], mean_fn: MeanFn | None = None):
    """Weighted mean of transformed sigma points (``mean_fn`` for angles)."""
    if mean_fn is None:
        return weighted_sum(weights, points)
    return mean_fn(points, weights)


def weighted_sum(weights: Float[Array, " N"], points: Float[Array, "N ..."]) -> Float[Array, "..."]:
    """``sum_k weights[k] * points[k]`` as a multiply and a ``reduce``.

    Measured on the 3-state localization filter (benchmarks/ukf.py): a reduce beats both a
    ``dot`` (a separate, unfused library call per product) and an unrolled sum (which XLA
    recomputes inside every consumer kernel), single and vmapped.
    """
    return jnp.sum(weights.reshape(weights.shape + (1,) * (points.ndim - 1)) * points, axis=0)


def residuals(points: Float[Array, "N d"], center: Float[Array, " d"], residual_fn: ResidualFn | None = None):
    """``points - center`` row by row (``residual_fn`` for angles)."""
    if residual_fn is None:
        return points - center
    return jax.vmap(residual_fn, in_axes=(0, None))(points, center)


def weighted_outer(weights: Float[Array, " N"], a: Float[Array, "N p"], b: Float[Array, "N q"]) -> Float[Array, "p q"]:
    """``sum_k w_k a_k b_k^T`` (unrolled, fusible; see :func:`weighted_sum`)."""
    return weighted_sum(weights, a[:, :, None] * b[:, None, :])


class UnscentedResult(NamedTuple):
    """Moments of ``y = fn(x)`` from the unscented transform."""

    mean: Float[Array, " m"]
    cov: Float[Array, "m m"]
    cross_cov: Float[Array, "n m"]  #: Cov[x, y]


def unscented_transform(
    fn: Callable[[Array], Array],
    mean: Float[Array, " n"],
    cov: Float[Array, "n n"] | None = None,
    *,
    chol: Float[Array, "n n"] | None = None,
    scheme: MerweScaled | Julier = MerweScaled(),
    noise_cov: Float[Array, "m m"] | None = None,
    mean_fn: MeanFn | None = None,
    residual_fn: ResidualFn | None = None,
    input_residual_fn: ResidualFn | None = None,
    input_add_fn: AddFn | None = None,
) -> UnscentedResult:
    """Unscented transform of ``x ~ N(mean, cov)`` through ``fn``.

    Give either ``cov`` or its lower Cholesky factor ``chol``. ``mean_fn`` and ``residual_fn``
    average and difference the outputs (angles), ``input_residual_fn`` and ``input_add_fn`` do
    the same for the inputs (used to form the sigma points and the cross-covariance).
    ``noise_cov`` is added to the output covariance (additive noise).

    Example::

        >>> import jax.numpy as jnp
        >>> r = unscented_transform(lambda x: x**2, jnp.array([1.0]), jnp.array([[0.25]]),
        ...                         scheme=MerweScaled(alpha=1.0, beta=0.0, kappa=2.0))
        >>> float(r.mean[0])  # mu^2 + sigma^2
        1.25
    """
    mean = jnp.asarray(mean)
    if mean.ndim != 1:
        raise ValueError(f"mean must have shape (n,), got {mean.shape}")
    n = mean.shape[0]
    if (cov is None) == (chol is None):
        raise ValueError("give exactly one of cov and chol")
    if chol is None:
        cov = jnp.asarray(cov)
        if cov.shape != (n, n):
            raise ValueError(f"cov must have shape ({n}, {n}) to match mean, got {cov.shape}")
        chol = linalg.cholesky(cov)
    else:
        chol = jnp.asarray(chol)
        if chol.shape != (n, n):
            raise ValueError(f"chol must have shape ({n}, {n}) to match mean, got {chol.shape}")
    w = scheme.weights(n, mean.dtype)
    x_points = sigma_points(mean, chol, w.spread, input_add_fn)
    y_points = jax.vmap(fn)(x_points)
    if y_points.ndim != 2:
        raise ValueError(f"fn must map a vector to a vector, got output shape {y_points.shape[1:]}")
    y_mean = weighted_mean(y_points, w.mean, mean_fn)
    dy = residuals(y_points, y_mean, residual_fn)
    dx = residuals(x_points, mean, input_residual_fn)
    y_cov = weighted_outer(w.cov, dy, dy)
    if noise_cov is not None:
        y_cov = y_cov + noise_cov
    return UnscentedResult(y_mean, y_cov, weighted_outer(w.cov, dx, dy))


def _angle_mask(angle_dims: Sequence[int]):
    dims = sorted({int(d) for d in angle_dims})
    if not dims or dims[0] < 0:
        raise ValueError(f"angle_dims must be non-empty non-negative indices, got {angle_dims}")

    def mask_for(size: int) -> np.ndarray:
        if dims[-1] >= size:
            raise ValueError(f"angle_dims {dims} out of range for a vector of size {size}")
        mask = np.zeros(size, dtype=bool)
        mask[dims] = True
        return mask

    return mask_for


def _wrap_where(mask: np.ndarray, v: Array) -> Array:
    # A select on a constant mask instead of a scatter: elementwise, so XLA fuses it.
    return jnp.where(mask, wrap_angle(v), v)


def wrapped_residual_fn(angle_dims: Sequence[int]) -> ResidualFn:
    """``a - b`` with the entries ``angle_dims`` wrapped to [-pi, pi)."""
    mask_for = _angle_mask(angle_dims)

    def residual(a, b):
        d = a - b
        return _wrap_where(mask_for(d.shape[-1]), d)

    return residual


def wrapped_add_fn(angle_dims: Sequence[int]) -> AddFn:
    """``x + dx`` with the entries ``angle_dims`` wrapped to [-pi, pi)."""
    mask_for = _angle_mask(angle_dims)

    def add(x, dx):
        s = x + dx
        return _wrap_where(mask_for(s.shape[-1]), s)

    return add


def circular_mean_fn(angle_dims: Sequence[int]) -> MeanFn:
    """Weighted mean with the entries ``angle_dims`` averaged on the circle.

    Angles are averaged as ``ref + sum_k w_k wrap(theta_k - ref)`` around the first (central)
    sigma point ``ref`` and wrapped. Unlike ``atan2(sum w sin, sum w cos)`` this is the exact
    weighted mean whenever the points span less than pi, so linear maps stay exact.
    """
    mask_for = _angle_mask(angle_dims)

    def mean(points, weights):
        mask = mask_for(points.shape[-1])
        ref = points[0]
        centred = _wrap_where(mask, points - ref)
        return _wrap_where(mask, ref + weighted_sum(weights, centred))

    return mean


__all__ = [
    "AddFn",
    "Julier",
    "MeanFn",
    "MerweScaled",
    "ResidualFn",
    "SigmaWeights",
    "UnscentedResult",
    "circular_mean_fn",
    "offset_points",
    "residuals",
    "sigma_offsets",
    "sigma_points",
    "unscented_transform",
    "weighted_mean",
    "weighted_outer",
    "weighted_sum",
    "wrapped_add_fn",
    "wrapped_residual_fn",
]
