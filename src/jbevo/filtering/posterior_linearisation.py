"""The iterated posterior-linearisation smoother (IPLS), sequential or parallel in time.

Each iteration replaces the model's motion and measurement by their statistical linear
regressions (SLR) with respect to the current smoothed beliefs, computed with sigma points, and
smooths the resulting affine model exactly (:mod:`jbevo.filtering.parallel`):

* SLR of ``g`` about ``N(m, P)``: with sigma points ``X_i`` and ``Y_i = g(X_i)``, the mean
  ``mu = sum_i Wm_i Y_i``, ``Psi = sum_i Wc_i (X_i - m)(Y_i - mu)^T`` and
  ``Phi = sum_i Wc_i (Y_i - mu)(Y_i - mu)^T``; then ``g(x) ≈ A x + (mu - A m) + e`` with
  ``A = Psi^T P^-1`` and ``e ~ N(0, Phi - A P A^T)``, the linearisation error, added to the noise;
* the motion from step ``t - 1`` is linearised about the smoothed belief of ``x_{t-1}``, the
  measurement of step ``t`` about that of ``x_t``; the affine model is filtered and smoothed,
  and the smoothed beliefs are the next iteration's linearisation points.

García-Fernández, Svensson and Särkkä (IEEE TSP 65(19), 2017) derive it; Yaghoobi, Corenflos,
Hassan and Särkkä (IEEE SPL 28, 2021) run its affine smoother with ``associative_scan``
("parallel iterated sigma-point smoother"), which ``parallel=True`` does here: ``O(log T)``
span per iteration. With ``parallel=False`` the same iteration runs the sequential Kalman filter
and RTS smoother; both give the same result to round-off. For a linear model one iteration is
the Kalman smoother exactly, whatever the linearisation points. For a nonlinear model, the
converged result is close to, but not the same as, the unscented RTS smoother's
(:mod:`jbevo.filtering.smoother`): each step is linearised about its smoothed, not its
filtered or predicted, belief.

Step indexing follows :func:`jbevo.filtering.ukf.filter`: ``initial`` is the belief before the
first prediction, step ``t`` predicts with ``controls[t]`` and updates with ``measurements[t]``;
the results have one row per step. Missing data (NaN entries, ``mask``) as in the filter.
States and measurements that hold angles use the model's residual, add and mean functions:
every affine term is expressed in coordinates near its own linearisation point (a measurement
``z`` as ``mu + residual(z, mu)``, a predicted mean near the next step's point), so wrapping
never enters the linear algebra.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from jbevo.filtering import linalg, parallel, smoother, ukf
from jbevo.filtering.ukf import GaussianState, Scheme, StateSpaceModel, _sequence_inputs
from jbevo.filtering.unscented import (
    MerweScaled,
    offset_points,
    residuals,
    sigma_offsets,
    weighted_mean,
    weighted_outer,
)


class Linearisation(NamedTuple):
    """``g(x) ≈ matrix x + offset + e``, ``e ~ N(0, cov)``: a statistical linear regression."""

    matrix: Float[Array, "d n"]
    mean: Float[Array, " d"]  #: E[g(x)] (``offset = mean - matrix m``)
    cov: Float[Array, "d d"]


class IteratedResult(NamedTuple):
    """Output of :func:`smooth`: the smoothed beliefs after the last iteration, the filtered
    ones of the last affine model, its log-likelihood, and how far the smoothed means moved in
    each iteration (the largest absolute change; it falls to round-off at convergence)."""

    smoothed_mean: Float[Array, "T n"]
    smoothed_cov: Float[Array, "T n n"]
    filtered_mean: Float[Array, "T n"]
    filtered_cov: Float[Array, "T n n"]
    log_likelihood: Float[Array, ""]
    mean_change: Float[Array, " iterations"]


def statistical_linearisation(
    fn,
    belief: GaussianState,
    scheme: Scheme = MerweScaled(),
    state_add=None,
    output_residual=None,
    output_mean=None,
) -> Linearisation:
    """The SLR of ``fn`` about ``belief`` with the sigma points of ``scheme`` (module docstring).

    ``state_add`` draws the points (angles in the state), ``output_residual`` and
    ``output_mean`` replace ``-`` and the weighted mean for ``fn``'s output.
    """
    mean, cov = belief
    w = scheme.weights(mean.shape[-1], mean.dtype)
    low = linalg.cholesky(cov)
    dx = sigma_offsets(low, w.spread)
    out = jax.vmap(fn)(offset_points(mean, dx, state_add))
    mu = weighted_mean(out, w.mean, output_mean)
    dy = residuals(out, mu, output_residual)
    matrix = linalg.cho_solve(low, weighted_outer(w.cov, dx, dy)).T  # Psi^T P^-1
    error = weighted_outer(w.cov, dy, dy) - matrix @ cov @ matrix.T
    return Linearisation(matrix, mu, linalg.symmetrize(error))


def _near(value: Array, reference: Array, residual_fn) -> Array:
    """``value`` in coordinates near ``reference`` (the identity without angles)."""
    return value if residual_fn is None else reference + residual_fn(value, reference)


def linearised_model(
    model: StateSpaceModel,
    points: GaussianState,
    controls: Any,
    measurements: Float[Array, "T m"],
    motion_cov: Float[Array, "T n n"],
    measurement_cov: Float[Array, "T m m"],
    scheme: Scheme = MerweScaled(),
) -> parallel.AffineModel:
    """The affine model of ``model`` linearised about ``points`` (``T + 1`` beliefs: before the
    first step, then after each step), every term near its own point (module docstring)."""
    before = jax.tree.map(lambda a: a[:-1], points)
    after = jax.tree.map(lambda a: a[1:], points)

    def motion(belief, control, next_mean):
        slr = statistical_linearisation(
            lambda x: model.motion(x, control), belief, scheme, model.state_add, model.state_residual, model.state_mean
        )
        offset = _near(slr.mean, next_mean, model.state_residual) - slr.matrix @ belief.mean
        return slr.matrix, offset, slr.cov

    def measurement(belief, z):
        slr = statistical_linearisation(
            model.measurement, belief, scheme, model.state_add, model.measurement_residual, model.measurement_mean
        )
        finite = jnp.isfinite(z)
        z_near = _near(jnp.where(finite, z, slr.mean), slr.mean, model.measurement_residual)
        return slr.matrix, slr.mean - slr.matrix @ belief.mean, slr.cov, jnp.where(finite, z_near, jnp.nan)

    f, b, motion_error = jax.vmap(motion)(before, controls, after.mean)
    h, c, measurement_error, z = jax.vmap(measurement)(after, measurements)
    return parallel.AffineModel(f, b, motion_cov + motion_error, h, c, measurement_cov + measurement_error, z)


def prior_linearisation(initial: GaussianState, steps: int) -> GaussianState:
    """``initial`` at all ``steps + 1`` points: a first linearisation with no sequential pass."""
    n = initial.mean.shape[-1]
    return GaussianState(jnp.broadcast_to(initial.mean, (steps + 1, n)), jnp.broadcast_to(initial.cov, (steps + 1, n, n)))


def unscented_linearisation(
    model: StateSpaceModel,
    initial: GaussianState,
    controls: Any,
    measurements: Float[Array, "T m"],
    motion_cov: Float[Array, "T n n"],
    measurement_cov: Float[Array, "T m m"],
    scheme: Scheme = MerweScaled(),
) -> GaussianState:
    """The unscented RTS smoother's beliefs (``initial`` first): the default first linearisation."""
    result = ukf.filter(model, initial, controls, measurements, motion_cov, measurement_cov, scheme=scheme, check_inputs=False)
    smoothed = smoother.smooth(model, result, controls, motion_cov, scheme=scheme)
    return GaussianState(
        jnp.concatenate([initial.mean[None], smoothed.smoothed_mean]), jnp.concatenate([initial.cov[None], smoothed.smoothed_cov])
    )


def smooth(
    model: StateSpaceModel,
    initial: GaussianState,
    controls: Any,
    measurements: Float[Array, "T m"],
    motion_cov: Float[Array, "n n"] | Float[Array, "T n n"],
    measurement_cov: Float[Array, "m m"] | Float[Array, "T m m"],
    *,
    iterations: int = 10,
    parallel_in_time: bool = True,
    linearisation: GaussianState | None = None,
    scheme: Scheme = MerweScaled(),
    mask: Bool[Array, "T m"] | None = None,
    check_inputs: bool = True,
) -> IteratedResult:
    """The iterated posterior-linearisation smoother (module docstring), ``iterations`` times.

    Arguments as for :func:`jbevo.filtering.ukf.filter`. ``linearisation``: the first
    iteration's points, ``T + 1`` beliefs (before the first step, then one per step); by default
    :func:`unscented_linearisation` (one sequential UKF and RTS pass). :func:`prior_linearisation`
    (``initial`` at every step) needs no sequential pass, but far from a linear model it can
    converge to a wrong fixed point: on the planar pose model over 500 steps it ends metres off
    (``tests/filtering/test_posterior_linearisation.py``). ``parallel_in_time`` selects the
    ``associative_scan`` filter and smoother (else ``lax.scan``).
    """
    if iterations < 1:
        raise ValueError(f"iterations must be at least 1, got {iterations}")
    initial, controls, measurements, motion_cov, measurement_cov, mask = _sequence_inputs(
        model, initial, controls, measurements, motion_cov, measurement_cov, mask, check_inputs, None
    )
    steps, n = measurements.shape[0], initial.mean.shape[0]
    q = jnp.broadcast_to(motion_cov, (steps, n, n))
    r = jnp.broadcast_to(measurement_cov, (steps, *measurement_cov.shape[-2:]))
    if mask is not None:
        measurements = jnp.where(mask, measurements, jnp.nan)
    if linearisation is None:
        linearisation = unscented_linearisation(model, initial, controls, measurements, q, r, scheme)
    else:
        linearisation = GaussianState(*(jnp.asarray(a, initial.mean.dtype) for a in linearisation))
        if linearisation.mean.shape != (steps + 1, n) or linearisation.cov.shape != (steps + 1, n, n):
            raise ValueError(
                f"linearisation must hold {steps + 1} beliefs (before the first step, then one per step) of size {n}, "
                f"got means {linearisation.mean.shape} and covariances {linearisation.cov.shape}"
            )
    run_filter = parallel.filter if parallel_in_time else parallel.sequential_filter
    run_smoother = parallel.smooth if parallel_in_time else parallel.sequential_smoother
    add = model.state_add
    wrap = (lambda m: m) if add is None else jax.vmap(lambda m: add(m, jnp.zeros_like(m)))

    def iteration(points):
        affine = linearised_model(model, points, controls, measurements, q, r, scheme)
        prior = GaussianState(_near(initial.mean, points.mean[0], model.state_residual), initial.cov)
        filtered = run_filter(affine, prior)
        later = run_smoother(affine, filtered)
        # x_0 (before the first step) by one RTS step back from step 1.
        predicted = GaussianState(filtered.predicted_mean[0], filtered.predicted_cov[0])
        gain = linalg.cho_solve(linalg.cholesky(predicted.cov), affine.transition[0] @ prior.cov).T
        first = GaussianState(
            prior.mean + gain @ (later.mean[0] - predicted.mean),
            linalg.symmetrize(prior.cov + gain @ (later.cov[0] - predicted.cov) @ gain.T),
        )
        new = GaussianState(wrap(jnp.concatenate([first.mean[None], later.mean])), jnp.concatenate([first.cov[None], later.cov]))
        moved = new.mean - points.mean if model.state_residual is None else jax.vmap(model.state_residual)(new.mean, points.mean)
        return new, jnp.max(jnp.abs(moved)), filtered

    def body(carry, _):
        new, change, filtered = iteration(carry[0])
        last = (filtered.filtered_mean, filtered.filtered_cov, jnp.sum(filtered.log_likelihoods))
        return (new, *last), change

    # One scan for all iterations (the last one's filtered beliefs in the carry): one compiled
    # loop, also when called without jit.
    empty = (
        jnp.zeros((steps, n), initial.mean.dtype),
        jnp.zeros((steps, n, n), initial.mean.dtype),
        jnp.zeros((), initial.mean.dtype),
    )
    (points, filtered_mean, filtered_cov, log_likelihood), changes = jax.lax.scan(
        body, (linearisation, *empty), None, length=iterations
    )
    return IteratedResult(points.mean[1:], points.cov[1:], wrap(filtered_mean), filtered_cov, log_likelihood, changes)


__all__ = [
    "IteratedResult",
    "Linearisation",
    "linearised_model",
    "prior_linearisation",
    "smooth",
    "statistical_linearisation",
    "unscented_linearisation",
]
