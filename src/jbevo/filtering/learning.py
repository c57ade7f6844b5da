"""Learning a filter's noise covariances Q and R with optax, over a batch of sequences.

:func:`fit_noise` runs :func:`jbevo.filtering.ukf.filter` vmapped over a batch of sequences of
different lengths (padded to one length ``T``, with ``lengths``) and minimises, with an optax
optimizer, one of:

* ``"likelihood"``: the negative log-likelihood of the measurements per valid step (maximum
  likelihood; no ground truth needed);
* ``"supervised"``: the mean weighted squared error of the filtered means against ``targets``
  (states, e.g. poses from a reference system), differenced with the model's ``state_residual``;
* any function ``objective(result, targets, valid) -> scalar`` of one sequence's
  :class:`~jbevo.filtering.ukf.FilterResult`, its targets and its valid-step mask, averaged over
  the batch weighted by the valid steps.

Padding is exact: the measurements of a padded step are replaced by NaN (the filter skips them:
zero log-likelihood), and padded steps are left out of every loss, so a padded batch gives the
same value and gradient as the sequences run one by one at their own lengths. Q and R are
:class:`~jbevo.filtering.noise.DiagonalCovariance` or
:class:`~jbevo.filtering.noise.CholeskyCovariance` modules (unconstrained parameters: every
step of the optimizer gives valid covariances).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import optax
from jaxtyping import Array, Float, Int

from jbevo.filtering import ukf
from jbevo.filtering.noise import CholeskyCovariance, DiagonalCovariance
from jbevo.filtering.unscented import MerweScaled

Covariance = DiagonalCovariance | CholeskyCovariance
Objective = Callable[[ukf.FilterResult, Any, Array], Array]


class Noise(eqx.Module):
    """The learnable noise of a filter: motion (Q) and measurement (R) covariance modules."""

    motion: Covariance
    measurement: Covariance


class FitResult(NamedTuple):
    """Output of :func:`fit_noise`: the learned noise and the objective at every iteration
    (before its update)."""

    noise: Noise
    losses: Float[Array, " iterations"]


def valid_steps(lengths: Int[Array, " B"], steps: int) -> Array:
    """``(B, steps)`` mask: True for the first ``lengths[b]`` steps of sequence ``b``."""
    return jnp.arange(steps)[None, :] < jnp.asarray(lengths)[:, None]


def batch_objective(
    model: ukf.StateSpaceModel,
    initial: ukf.GaussianState,
    controls: Any,
    measurements: Float[Array, "B T m"],
    *,
    objective: str | Objective = "likelihood",
    targets: Any = None,
    lengths: Int[Array, " B"] | None = None,
    state_weights: Float[Array, " n"] | None = None,
    scheme: ukf.Scheme = MerweScaled(),
) -> Callable[[Noise], Array]:
    """The scalar loss ``loss(noise)`` that :func:`fit_noise` minimises (arguments as there), for
    use with one's own optimisation loop or for validation."""
    measurements = jnp.asarray(measurements)
    if measurements.ndim != 3:
        raise ValueError(f"measurements must have shape (B, T, m) (a batch of sequences), got {measurements.shape}")
    batch, steps, _ = measurements.shape
    for leaf in jax.tree.leaves(controls):
        if jnp.shape(leaf)[:2] != (batch, steps):
            raise ValueError(f"every controls leaf must have leading axes ({batch}, {steps}), got {jnp.shape(leaf)}")
    if lengths is None:
        lengths = jnp.full((batch,), steps)
    lengths = jnp.asarray(lengths)
    if lengths.shape != (batch,) or not bool(jnp.all((lengths >= 1) & (lengths <= steps))):
        raise ValueError(f"lengths must be {batch} integers in [1, {steps}], got {lengths}")
    valid = valid_steps(lengths, steps)
    measurements = jnp.where(valid[:, :, None], measurements, jnp.nan)
    mean, cov = initial
    mean, cov = jnp.asarray(mean), jnp.asarray(cov)
    n = mean.shape[-1]
    initial = ukf.GaussianState(jnp.broadcast_to(mean, (batch, n)), jnp.broadcast_to(cov, (batch, n, n)))
    if objective == "supervised":
        if targets is None:
            raise ValueError('objective "supervised" needs targets (B, T, n)')
        if jnp.shape(targets) != (batch, steps, n):
            raise ValueError(f"targets must have shape ({batch}, {steps}, {n}), got {jnp.shape(targets)}")
        weights = jnp.ones(n) if state_weights is None else jnp.asarray(state_weights)
        if weights.shape != (n,):
            raise ValueError(f"state_weights must have shape ({n},), got {weights.shape}")

        def squared_error(result, target, ok):
            if model.state_residual is None:
                err = result.filtered_mean - target
            else:
                err = jax.vmap(model.state_residual)(result.filtered_mean, target)
            return jnp.sum(jnp.where(ok, jnp.sum(weights * err**2, axis=-1), 0.0))

        per_sequence = squared_error
    elif objective == "likelihood":
        per_sequence = lambda result, target, ok: -result.log_likelihood
    elif callable(objective):
        custom = objective
        per_sequence = lambda result, target, ok: custom(result, target, ok) * jnp.sum(ok)
    else:
        raise ValueError(f'objective must be "likelihood", "supervised" or a function, got {objective!r}')
    normaliser = jnp.sum(valid)  # every loss is a sum over valid steps: the mean per step

    def loss(noise: Noise) -> Array:
        q, r = noise.motion(), noise.measurement()

        def one(start, u, z, target, ok):
            result = ukf.filter(model, start, u, z, q, r, scheme=scheme)
            return per_sequence(result, target, ok)

        return jnp.sum(jax.vmap(one)(initial, controls, measurements, targets, valid)) / normaliser

    return loss


def fit_noise(
    model: ukf.StateSpaceModel,
    initial: ukf.GaussianState,
    controls: Any,
    measurements: Float[Array, "B T m"],
    noise: Noise,
    *,
    objective: str | Objective = "likelihood",
    targets: Any = None,
    lengths: Int[Array, " B"] | None = None,
    state_weights: Float[Array, " n"] | None = None,
    optimizer: optax.GradientTransformation | None = None,
    iterations: int = 200,
    scheme: ukf.Scheme = MerweScaled(),
) -> FitResult:
    """Fit ``noise`` (Q and R) to a batch of sequences by gradient descent through the filter.

    ``initial`` is the belief before the first step (one for all sequences, or with a leading
    batch axis); ``controls`` (a pytree of ``(B, T, ...)`` leaves, or None) and ``measurements``
    ``(B, T, m)`` are padded to a common ``T``, ``lengths`` ``(B,)`` gives each sequence's steps
    (default: all ``T``). ``objective`` as in the module docstring; ``targets`` ``(B, T, n)``
    for ``"supervised"`` (or any pytree a custom objective reads, with leading axes ``(B, T)``),
    weighted per state entry by ``state_weights`` (default ones). ``optimizer`` defaults to
    ``optax.adam(0.05)``; ``iterations`` jitted steps over the whole batch."""
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    loss = batch_objective(
        model,
        initial,
        controls,
        measurements,
        objective=objective,
        targets=targets,
        lengths=lengths,
        state_weights=state_weights,
        scheme=scheme,
    )
    optimizer = optax.adam(0.05) if optimizer is None else optimizer
    opt_state = optimizer.init(eqx.filter(noise, eqx.is_inexact_array))

    @eqx.filter_jit
    def step(noise, opt_state):
        value, grads = eqx.filter_value_and_grad(loss)(noise)
        updates, opt_state = optimizer.update(grads, opt_state, eqx.filter(noise, eqx.is_inexact_array))
        return eqx.apply_updates(noise, updates), opt_state, value

    losses = []
    for _ in range(iterations):
        noise, opt_state, value = step(noise, opt_state)
        losses.append(value)
    return FitResult(noise, jnp.stack(losses))


__all__ = ["FitResult", "Noise", "batch_objective", "fit_noise", "valid_steps"]
