"""The unscented Rauch-Tung-Striebel smoother, as a pure JAX function over a filter's result.

:func:`smooth` runs backwards over a :class:`jbevo.filtering.ukf.FilterResult` (``jax.lax.scan``
in reverse). At step ``k``, with the filtered belief ``N(m_k, P_k)`` and the smoothed one at
``k + 1``, ``N(m^s_{k+1}, P^s_{k+1})``:

* sigma points of ``N(m_k, P_k)`` go through ``motion(x, u_{k+1})``: the predicted mean ``m^-``,
  covariance ``P^- = sum_i Wc_i dy_i dy_i^T + Q_{k+1}`` and cross-covariance
  ``C = sum_i Wc_i dx_i dy_i^T`` (``dx``: the points' residuals from ``m_k``, ``dy``: the moved
  points' from ``m^-``);
* the gain ``G = C (P^-)^-1`` (a Cholesky solve, no inverse);
* ``m^s_k = m_k + G (m^s_{k+1} - m^-)`` and ``P^s_k = P_k + G (P^s_{k+1} - P^-) G^T``
  (symmetrised).

The gain needs nothing from later steps: :func:`jbevo.filtering.ukf.filter` computes it with
each prediction (``FilterResult.smoother_gains``) and :func:`smooth` then reuses it and the
filter's predictions; :func:`smooth_beliefs` (beliefs that are not one ``filter`` call) and a
result without gains recompute them as above.

This is Särkkä's unscented RTS smoother (Bayesian Filtering and Smoothing, 2013, alg. 9.3) and
filterpy's ``UnscentedKalmanFilter.rts_smoother``; for a linear model it is the Kalman RTS
smoother exactly. The step from ``k`` to ``k + 1`` uses ``controls[k + 1]`` and
``motion_cov[k + 1]``, as :func:`jbevo.filtering.ukf.filter` did. Missing measurements need
nothing here: the filter skipped them, and the smoother carries the information of the steps
around a gap into it. The last step's smoothed belief is its filtered one. States that hold
angles use the model's ``state_residual``, ``state_add`` and ``state_mean``.
"""

from __future__ import annotations

from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jbevo.filtering import linalg
from jbevo.filtering.blocked_scan import blocked_scan
from jbevo.filtering.ukf import FilterResult, Scheme, StateSpaceModel
from jbevo.filtering.unscented import MerweScaled, offset_points, residuals, sigma_offsets, weighted_mean, weighted_outer


class SmootherResult(NamedTuple):
    """Output of :func:`smooth`."""

    smoothed_mean: Float[Array, "T n"]
    smoothed_cov: Float[Array, "T n n"]
    gains: Float[Array, "T n n"]  #: G_k, from step k to k + 1 (zero at the last step)


def smooth(
    model: StateSpaceModel,
    result: FilterResult,
    controls: Any,
    motion_cov: Float[Array, "n n"] | Float[Array, "T n n"],
    *,
    scheme: Scheme = MerweScaled(),
    block: int | Literal["auto"] = 1,
    one_kernel: bool = True,
) -> SmootherResult:
    """The unscented RTS smoother (module docstring) over ``result``, the output of
    :func:`jbevo.filtering.ukf.filter` run with the same ``model``, ``controls``, ``motion_cov``
    (Q, constant or with a leading time axis) and ``scheme``.

    Where ``result`` keeps the smoother's gains (:func:`~jbevo.filtering.ukf.filter` does: each
    is known once the step's prediction is), the backward pass reuses them and the filter's
    predictions instead of pushing sigma points through the motion again: the same quantities,
    computed once. ``controls`` and ``motion_cov`` are then only checked against the result's
    shapes and ``scheme`` and the model's motion are not used (the filter's own were); to smooth
    with others, pass ``result._replace(smoother_gains=None)``, which recomputes everything with
    them. The filter's gain into step ``k + 1`` is the smoother's gain from step ``k``:
    ``gains[k] == result.smoother_gains[k + 1]``. ``block`` and ``one_kernel`` as in
    :func:`jbevo.filtering.ukf.filter` (the backward loop in blocks, as one kernel)."""
    if result.smoother_gains is None:
        return smooth_beliefs(
            model,
            result.filtered_mean,
            result.filtered_cov,
            controls,
            motion_cov,
            scheme=scheme,
            block=block,
            one_kernel=one_kernel,
        )
    means, covs = result.filtered_mean, result.filtered_cov
    steps, _ = _checked_inputs(means, covs, controls, motion_cov)
    fields = {"predicted_mean": means.shape, "predicted_cov": covs.shape, "smoother_gains": covs.shape}
    wrong = [
        f"{name} {getattr(result, name).shape}, not {shape}"
        for name, shape in fields.items()
        if getattr(result, name).shape != shape
    ]
    if wrong:
        raise ValueError(f"the result's predictions and gains must have the filtered beliefs' shapes: {'; '.join(wrong)}")
    if steps == 1:
        return SmootherResult(means, covs, jnp.zeros_like(covs))

    def back(later, inputs):
        later_mean, later_cov = later
        mean, cov, predicted_mean, predicted_cov, gain = inputs
        return _rts_step(model, mean, cov, later_mean, later_cov, predicted_mean, predicted_cov, gain)

    inputs = (means[:-1], covs[:-1], result.predicted_mean[1:], result.predicted_cov[1:], result.smoother_gains[1:])
    _, (sm, sc, gains) = blocked_scan(back, (means[-1], covs[-1]), inputs, reverse=True, block=block, one_kernel=one_kernel)
    return _with_last(sm, sc, gains, means, covs)


def _checked_inputs(means, covs, controls, motion_cov) -> tuple[int, Array]:
    """Raise on beliefs, controls or Q that do not fit together; ``(T, Q per step)``."""
    if means.ndim != 2 or covs.shape != (*means.shape, means.shape[-1]):
        raise ValueError(
            f"the filtered beliefs must be means (T, n) and covariances (T, n, n), got {means.shape} and {covs.shape}"
        )
    steps, n = means.shape
    motion_cov = jnp.asarray(motion_cov, means.dtype)
    if motion_cov.shape not in ((n, n), (steps, n, n)):
        raise ValueError(f"motion_cov must have shape ({n}, {n}) or ({steps}, {n}, {n}), got {motion_cov.shape}")
    for leaf in jax.tree.leaves(controls):
        if jnp.shape(leaf)[:1] != (steps,):
            raise ValueError(f"every controls leaf must have leading axis {steps} (the filter's steps), got {jnp.shape(leaf)}")
    return steps, jnp.broadcast_to(motion_cov, (steps, n, n))


def _rts_step(model, mean, cov, later_mean, later_cov, predicted_mean, predicted_cov, gain):
    """One backward step given the gain: the smoothed belief at ``k`` (carry and output)."""
    if model.state_residual is None:
        innovation = later_mean - predicted_mean
    else:
        innovation = model.state_residual(later_mean, predicted_mean)
    correction = linalg.matvec(gain, innovation)
    new_mean = mean + correction if model.state_add is None else model.state_add(mean, correction)
    new_cov = linalg.symmetrize(cov + linalg.matmul(linalg.matmul(gain, later_cov - predicted_cov), gain.T))
    return (new_mean, new_cov), (new_mean, new_cov, gain)


def _with_last(sm, sc, gains, means, covs) -> SmootherResult:
    """The backward pass's steps ``0 .. T - 2`` and the last step's filtered belief."""
    return SmootherResult(
        jnp.concatenate([sm, means[-1:]]), jnp.concatenate([sc, covs[-1:]]), jnp.concatenate([gains, jnp.zeros_like(gains[:1])])
    )


def smooth_beliefs(
    model: StateSpaceModel,
    means: Float[Array, "T n"],
    covs: Float[Array, "T n n"],
    controls: Any,
    motion_cov: Float[Array, "n n"] | Float[Array, "T n n"],
    *,
    scheme: Scheme = MerweScaled(),
    block: int | Literal["auto"] = 1,
    one_kernel: bool = True,
) -> SmootherResult:
    """:func:`smooth` over filtered beliefs given as arrays (``means[t]``, ``covs[t]``: the belief
    after step ``t``'s motion with ``controls[t]`` and its updates), for filters that are not one
    :func:`jbevo.filtering.ukf.filter` call (several updates per step, robust or linear ones);
    ``block`` and ``one_kernel`` as there."""
    steps, q_seq = _checked_inputs(means, covs, controls, motion_cov)
    if steps == 1:
        return SmootherResult(means, covs, jnp.zeros_like(covs))
    w = scheme.weights(means.shape[-1], means.dtype)

    def back(later, inputs):
        later_mean, later_cov = later
        mean, cov, control, q = inputs
        dx = sigma_offsets(linalg.cholesky(cov), w.spread)
        moved = jax.vmap(model.motion, in_axes=(0, None))(offset_points(mean, dx, model.state_add), control)
        predicted_mean = weighted_mean(moved, w.mean, model.state_mean)
        dy = residuals(moved, predicted_mean, model.state_residual)
        predicted_cov = linalg.symmetrize(weighted_outer(w.cov, dy, dy) + q)
        cross = weighted_outer(w.cov, dx, dy)
        gain = linalg.cho_solve(linalg.cholesky(predicted_cov), cross.T).T
        return _rts_step(model, mean, cov, later_mean, later_cov, predicted_mean, predicted_cov, gain)

    later_controls = jax.tree.map(lambda a: a[1:], controls)
    _, (sm, sc, gains) = blocked_scan(
        back,
        (means[-1], covs[-1]),
        (means[:-1], covs[:-1], later_controls, q_seq[1:]),
        reverse=True,
        block=block,
        one_kernel=one_kernel,
    )
    return _with_last(sm, sc, gains, means, covs)


__all__ = ["SmootherResult", "smooth", "smooth_beliefs"]
