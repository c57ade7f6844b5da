"""Kalman filtering and RTS smoothing of an affine Gaussian model in parallel over time.

The model, for steps ``t = 1 .. T`` after a prior on ``x_0``::

    x_t = F_t x_{t-1} + b_t + q_t,   q_t ~ N(0, Q_t)
    z_t = H_t x_t + c_t + r_t,       r_t ~ N(0, R_t)

is an :class:`AffineModel` (every term with a leading time axis). :func:`filter` and
:func:`smooth` compute the same posteriors as the sequential Kalman filter and RTS smoother
(:func:`sequential_filter`, :func:`sequential_smoother`, ``lax.scan``) with
``jax.lax.associative_scan``: ``O(log T)`` span instead of ``O(T)``, for ``O(T)`` more work (about
twice the matrix products of the sequential recursion, each with a small solve). This is Särkkä and
García-Fernández's temporal parallelisation (IEEE TAC 66(1), 2021, "Temporal parallelization of
Bayesian smoothers", eqs. 10-15 and 21-23):

* filtering element ``t``: ``(A, b, C, eta, J)``, the conditional ``p(x_t | x_{t-1}, z_t) =
  N(A x_{t-1} + b, C)`` and the likelihood ``p(z_t | x_{t-1}) ∝ N_I(x_{t-1}; eta, J)`` in
  information form; the first element holds the prior (``A = 0``);
* smoothing element ``t``: ``(E, g, L)``, the backward conditional ``p(x_t | x_{t+1}, z_{1:t})
  = N(E x_{t+1} + g, L)``; the last element holds the last filtered belief (``E = 0``).

The prefix products of the filtering elements are the filtered beliefs, the suffix products of
the smoothing elements the smoothed ones.

Missing data, as in :mod:`jbevo.filtering.ukf`: entries of ``z_t`` that are not observed (the
``observed`` mask, NaN entries) have their rows of ``H`` and ``c`` replaced by zero, of ``z`` by
zero and of ``R`` by the identity, which removes them exactly; a step with nothing observed is a
prediction. These functions need no sigma points: they are the linear core of the iterated
posterior-linearisation smoother (:mod:`jbevo.filtering.posterior_linearisation`), and a Kalman
filter and smoother in their own right for linear models.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from jbevo.filtering import linalg
from jbevo.filtering.blocked_scan import blocked_scan
from jbevo.filtering.ukf import GaussianState

_LOG_2PI = 1.8378770664093453


class AffineModel(NamedTuple):
    """An affine Gaussian state-space model over ``T`` steps (module docstring)."""

    transition: Float[Array, "T n n"]  #: F_t, from x_{t-1} to x_t
    transition_offset: Float[Array, "T n"]  #: b_t
    transition_cov: Float[Array, "T n n"]  #: Q_t
    observation: Float[Array, "T m n"]  #: H_t
    observation_offset: Float[Array, "T m"]  #: c_t
    observation_cov: Float[Array, "T m m"]  #: R_t
    measurements: Float[Array, "T m"]  #: z_t (NaN where missing)


class AffineFilterResult(NamedTuple):
    """The filtered beliefs of steps ``1 .. T``, the predictions before each update and the
    log-likelihood ``log p(z_t | z_<t)`` of each step."""

    filtered_mean: Float[Array, "T n"]
    filtered_cov: Float[Array, "T n n"]
    predicted_mean: Float[Array, "T n"]
    predicted_cov: Float[Array, "T n n"]
    log_likelihoods: Float[Array, " T"]


def observed_model(model: AffineModel, mask: Bool[Array, "T m"] | None = None) -> AffineModel:
    """``model`` with its unobserved entries (NaN in ``measurements`` or ``mask`` False)
    removed exactly: zero rows of ``H``, ``c`` and ``z``, identity rows and columns of ``R``."""
    z = model.measurements
    observed = jnp.isfinite(z) if mask is None else jnp.isfinite(z) & mask
    both = observed[..., :, None] & observed[..., None, :]
    eye = jnp.eye(z.shape[-1], dtype=z.dtype)
    return model._replace(
        observation=jnp.where(observed[..., :, None], model.observation, 0.0),
        observation_offset=jnp.where(observed, model.observation_offset, 0.0),
        observation_cov=jnp.where(both, model.observation_cov, eye),
        measurements=jnp.where(observed, z, 0.0),
    )


# ------------------------------------------------------------------------------ filtering


class _FilterElement(NamedTuple):
    a: Array
    b: Array
    c: Array
    eta: Array
    j: Array


def _filter_elements(model: AffineModel, prior: GaussianState) -> _FilterElement:
    f, u, q = model.transition, model.transition_offset, model.transition_cov
    h, d, r, z = model.observation, model.observation_offset, model.observation_cov, model.measurements
    n = f.shape[-1]
    # Step 1 starts from the prior (A = 0): its prediction is N(F m0 + b, F P0 F^T + Q).
    m1 = f[0] @ prior.mean + u[0]
    p1 = f[0] @ prior.cov @ f[0].T + q[0]
    start = jnp.concatenate([p1[None], q[1:]])  # the covariance each element conditions
    mean = jnp.concatenate([m1[None], u[1:]])
    ht = jnp.swapaxes(h, -1, -2)
    s = linalg.symmetrize(h @ start @ ht + r)
    low = linalg.cholesky(s)
    gain_t = linalg.cho_solve(low, h @ start)  # K^T = S^-1 H P
    gain = jnp.swapaxes(gain_t, -1, -2)
    innovation = z - jnp.einsum("tmn,tn->tm", h, mean) - d
    i_kh = jnp.eye(n, dtype=f.dtype) - gain @ h
    a = i_kh @ f
    b = mean + jnp.einsum("tnm,tm->tn", gain, innovation)
    c = linalg.symmetrize(i_kh @ start)
    ft = jnp.swapaxes(f, -1, -2)
    s_inv_h = linalg.cho_solve(low, h)
    eta = jnp.einsum("tnk,tk->tn", ft @ ht, linalg.cho_solve(low, innovation[..., None])[..., 0])
    j = linalg.symmetrize(ft @ ht @ s_inv_h @ f)
    # The first element conditions on the prior, not on x_0: no dependence, no information.
    first = jnp.arange(f.shape[0]) == 0
    a = jnp.where(first[:, None, None], 0.0, a)
    eta = jnp.where(first[:, None], 0.0, eta)
    j = jnp.where(first[:, None, None], 0.0, j)
    return _FilterElement(a, b, c, eta, j)


def _combine_filter(early: _FilterElement, late: _FilterElement) -> _FilterElement:
    """``early ⊗ late`` (Särkkä and García-Fernández, lemma 8), batched over leading axes."""
    eye = jnp.eye(early.a.shape[-1], dtype=early.a.dtype)
    t = lambda x: jnp.swapaxes(x, -1, -2)
    mv = lambda m, v: jnp.einsum("...ij,...j->...i", m, v)
    # A2 (I + C1 J2)^-1 and A1^T (I + J2 C1)^-1, by solves (C1 and J2 are symmetric).
    a2_m = t(linalg.solve(eye + late.j @ early.c, t(late.a)))
    a1t_n = t(linalg.solve(eye + early.c @ late.j, early.a))
    return _FilterElement(
        a=a2_m @ early.a,
        b=mv(a2_m, early.b + mv(early.c, late.eta)) + late.b,
        c=linalg.symmetrize(a2_m @ early.c @ t(late.a) + late.c),
        eta=mv(a1t_n, late.eta - mv(late.j, early.b)) + early.eta,
        j=linalg.symmetrize(a1t_n @ late.j @ early.a + early.j),
    )


def _predictions(model: AffineModel, prior: GaussianState, means: Array, covs: Array) -> GaussianState:
    """The prediction of every step from the previous filtered belief (all steps at once)."""
    previous_mean = jnp.concatenate([prior.mean[None], means[:-1]])
    previous_cov = jnp.concatenate([prior.cov[None], covs[:-1]])
    f = model.transition
    mean = jnp.einsum("tij,tj->ti", f, previous_mean) + model.transition_offset
    cov = linalg.symmetrize(f @ previous_cov @ jnp.swapaxes(f, -1, -2) + model.transition_cov)
    return GaussianState(mean, cov)


def _log_likelihoods(model: AffineModel, predicted: GaussianState, observed: Array) -> Array:
    h = model.observation
    s = linalg.symmetrize(h @ predicted.cov @ jnp.swapaxes(h, -1, -2) + model.observation_cov)
    y = model.measurements - jnp.einsum("tmn,tn->tm", h, predicted.mean) - model.observation_offset
    low = linalg.cholesky(s)
    e = linalg.solve_lower(low, y[..., None])[..., 0]
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(low, axis1=-2, axis2=-1)), axis=-1)
    n_obs = jnp.sum(observed, axis=-1).astype(y.dtype)
    return -0.5 * (jnp.sum(e * e, axis=-1) + logdet + n_obs * _LOG_2PI)


def _result(model: AffineModel, prior: GaussianState, means: Array, covs: Array, observed: Array) -> AffineFilterResult:
    predicted = _predictions(model, prior, means, covs)
    return AffineFilterResult(means, covs, predicted.mean, predicted.cov, _log_likelihoods(model, predicted, observed))


def _observed(model: AffineModel, mask: Array | None) -> Array:
    observed = jnp.isfinite(model.measurements)
    return observed if mask is None else observed & mask


def filter(model: AffineModel, prior: GaussianState, mask: Bool[Array, "T m"] | None = None) -> AffineFilterResult:
    """The Kalman filter of ``model`` from ``prior`` (the belief of ``x_0``) by
    ``associative_scan``: the beliefs of ``x_1 .. x_T`` (module docstring)."""
    observed = _observed(model, mask)
    model = observed_model(model, mask)
    elements = jax.lax.associative_scan(_combine_filter, _filter_elements(model, prior))
    return _result(model, prior, elements.b, elements.c, observed)


def sequential_filter(
    model: AffineModel, prior: GaussianState, mask: Bool[Array, "T m"] | None = None, *, one_kernel: bool = True
) -> AffineFilterResult:
    """The same Kalman filter as :func:`filter`, one step after the other (``lax.scan``). The
    step's products are elementwise (:func:`jbevo.filtering.linalg.matmul`), so that with
    ``one_kernel`` its loop compiles as one XLA:CPU kernel
    (:func:`jbevo.filtering.cpu_kernel.one_kernel`; the same results to round-off)."""
    observed = _observed(model, mask)
    model = observed_model(model, mask)
    mm, mv = linalg.matmul, linalg.matvec

    def step(belief, inputs):
        f, u, q, h, d, r, z = inputs
        ft, ht = f.T, h.T
        mean = mv(f, belief.mean) + u
        cov = linalg.symmetrize(mm(mm(f, belief.cov), ft) + q)
        h_cov = mm(h, cov)
        s = linalg.symmetrize(mm(h_cov, ht) + r)
        gain = linalg.cho_solve(linalg.cholesky(s), h_cov).T
        new_mean = mean + mv(gain, z - mv(h, mean) - d)
        new = GaussianState(new_mean, linalg.symmetrize(cov - mm(mm(gain, s), gain.T)))
        return new, new

    _, beliefs = blocked_scan(step, prior, tuple(model), block=1, one_kernel=one_kernel)
    return _result(model, prior, beliefs.mean, beliefs.cov, observed)


# ------------------------------------------------------------------------------ smoothing


class _SmootherElement(NamedTuple):
    e: Array
    g: Array
    l: Array  # noqa: E741 (the paper's L)


def _smoother_elements(model: AffineModel, filtered: AffineFilterResult) -> _SmootherElement:
    means, covs = filtered.filtered_mean, filtered.filtered_cov
    # The gain from t to t + 1 uses the transition into t + 1: E_t = P_t F^T (F P_t F^T + Q)^-1.
    f, u, q = model.transition[1:], model.transition_offset[1:], model.transition_cov[1:]
    p, m = covs[:-1], means[:-1]
    pf = p @ jnp.swapaxes(f, -1, -2)
    predicted = linalg.symmetrize(f @ pf + q)
    e = jnp.swapaxes(linalg.cho_solve(linalg.cholesky(predicted), jnp.swapaxes(pf, -1, -2)), -1, -2)
    g = m - jnp.einsum("tij,tj->ti", e, jnp.einsum("tij,tj->ti", f, m) + u)
    l = linalg.symmetrize(p - e @ f @ p)  # noqa: E741
    last = _SmootherElement(jnp.zeros_like(covs[-1:]), means[-1:], covs[-1:])
    return _SmootherElement(jnp.concatenate([e, last.e]), jnp.concatenate([g, last.g]), jnp.concatenate([l, last.l]))


def _combine_smoother(late: _SmootherElement, early: _SmootherElement) -> _SmootherElement:
    """``early ⊗ late`` (the paper's lemma 10); ``associative_scan(reverse=True)`` passes the
    later suffix first."""
    e = early.e @ late.e
    g = jnp.einsum("...ij,...j->...i", early.e, late.g) + early.g
    l = linalg.symmetrize(early.e @ late.l @ jnp.swapaxes(early.e, -1, -2) + early.l)  # noqa: E741
    return _SmootherElement(e, g, l)


def smooth(model: AffineModel, filtered: AffineFilterResult) -> GaussianState:
    """The RTS smoother of ``model`` over its filtered beliefs (:func:`filter` or
    :func:`sequential_filter`) by ``associative_scan``: the smoothed beliefs of ``x_1 .. x_T``."""
    elements = jax.lax.associative_scan(_combine_smoother, _smoother_elements(model, filtered), reverse=True)
    return GaussianState(elements.g, elements.l)


def sequential_smoother(model: AffineModel, filtered: AffineFilterResult, *, one_kernel: bool = True) -> GaussianState:
    """The same RTS smoother as :func:`smooth`, one step after the other (``lax.scan``; its
    loop as one XLA:CPU kernel with ``one_kernel``, as in :func:`sequential_filter`)."""
    elements = _smoother_elements(model, filtered)

    def back(later, element):
        mean = linalg.matvec(element.e, later.mean) + element.g
        cov = linalg.symmetrize(linalg.matmul(linalg.matmul(element.e, later.cov), element.e.T) + element.l)
        new = GaussianState(mean, cov)
        return new, new

    last = GaussianState(filtered.filtered_mean[-1], filtered.filtered_cov[-1])
    inner = jax.tree.map(lambda a: a[:-1], elements)
    _, beliefs = blocked_scan(back, last, inner, block=1, reverse=True, one_kernel=one_kernel)
    return GaussianState(jnp.concatenate([beliefs.mean, last.mean[None]]), jnp.concatenate([beliefs.cov, last.cov[None]]))


__all__ = [
    "AffineFilterResult",
    "AffineModel",
    "filter",
    "observed_model",
    "sequential_filter",
    "sequential_smoother",
    "smooth",
]
