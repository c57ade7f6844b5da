"""Learnable noise covariances: unconstrained parameters that always give a symmetric positive
definite matrix, as ``equinox`` modules (their arrays are the leaves ``jax.grad`` and optax see).

Example::

    >>> import jax.numpy as jnp
    >>> q = DiagonalCovariance.from_std(jnp.array([0.02, 0.01, 0.005]))
    >>> q().shape
    (3, 3)
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo.filtering import linalg


class DiagonalCovariance(eqx.Module):
    """Diagonal covariance ``diag(exp(2 log_std))`` from unconstrained log standard deviations."""

    log_std: Float[Array, " d"]

    @classmethod
    def from_std(cls, std) -> DiagonalCovariance:
        std = jnp.asarray(std)
        if std.ndim != 1 or not bool(jnp.all(std > 0)):
            raise ValueError(f"std must be a vector of positive values, got {std}")
        return cls(jnp.log(std))

    def __call__(self) -> Float[Array, "d d"]:
        return jnp.diag(jnp.exp(2.0 * self.log_std))


class CholeskyCovariance(eqx.Module):
    """Full covariance ``L L^T`` from a log-Cholesky parameterisation.

    ``L`` is lower triangular with ``exp(log_diag)`` on its diagonal and ``lower`` (the strictly
    lower entries, row-major) below it: every real parameter vector gives a positive definite
    matrix, and the map is one to one.
    """

    log_diag: Float[Array, " d"]
    lower: Float[Array, " k"]

    @classmethod
    def from_matrix(cls, cov) -> CholeskyCovariance:
        cov = jnp.asarray(cov)
        if cov.ndim != 2 or cov.shape[0] != cov.shape[1] or not bool(linalg.is_positive_definite(cov)):
            raise ValueError("cov must be a finite symmetric positive definite matrix")
        low = jnp.linalg.cholesky(cov)
        rows, cols = jnp.tril_indices(cov.shape[0], -1)
        return cls(jnp.log(jnp.diagonal(low)), low[rows, cols])

    def __check_init__(self):
        d = jnp.shape(self.log_diag)[0]
        if jnp.shape(self.lower) != (d * (d - 1) // 2,):
            raise ValueError(f"lower must have {d * (d - 1) // 2} entries for d = {d}, got {jnp.shape(self.lower)}")

    def cholesky(self) -> Float[Array, "d d"]:
        d = self.log_diag.shape[0]
        rows, cols = jnp.tril_indices(d, -1)
        low = jnp.zeros((d, d), self.log_diag.dtype).at[rows, cols].set(self.lower)
        return low + jnp.diag(jnp.exp(self.log_diag))

    def __call__(self) -> Float[Array, "d d"]:
        low = self.cholesky()
        return low @ low.T


__all__ = ["CholeskyCovariance", "DiagonalCovariance"]
