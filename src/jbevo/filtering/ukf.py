"""Unscented Kalman filter with additive noise, as pure JAX functions.

A model is a :class:`StateSpaceModel`: pure functions ``motion(x, u) -> x'`` and
``measurement(x) -> z``, plus optional functions for states or measurements that hold angles.
:func:`predict` and :func:`update` are single steps; :func:`filter` composes them with
``jax.lax.scan`` (each step: predict with ``controls[t]``, then update with
``measurements[t]``, as filterpy does); :func:`filter_blocks` runs several predict/update steps
per output (the attitude filter's ~10 IMU samples per camera frame) as a nested scan.

Numerics (float32-safe):

* Small matrices are factorised by unrolled code (:mod:`jbevo.filtering.linalg`), fused by XLA.
* Update: with ``L = chol(S)``, ``W = L^-1 Pxz^T`` and ``e = L^-1 y``, the posterior is
  ``x + W^T e`` and ``P - W^T W``: one forward substitution, no inverse, and the subtracted
  term is symmetric positive semi-definite by construction. Predicted and filtered covariances
  are symmetrised, and Cholesky pivots are floored relative to the diagonal (jitter), so
  covariances stay positive definite over long float32 runs (tested over 100,000 steps).
* Sigma points are redrawn from the predicted Gaussian before the update.

Missing data: entries of a measurement that are NaN, or where ``mask`` is False, are skipped
exactly. The missing rows/columns of ``S`` are replaced by the identity, the matching columns
of ``Pxz`` and entries of the innovation by zero: the result equals an update with the observed
entries only, and an all-missing measurement equals a predict-only step with zero
log-likelihood. NaNs never enter the arithmetic (double-where), so gradients stay finite.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from jbevo.filtering import linalg
from jbevo.filtering.blocked_scan import blocked_scan
from jbevo.filtering.noise import CholeskyCovariance, DiagonalCovariance
from jbevo.filtering.unscented import (
    AddFn,
    Julier,
    MeanFn,
    MerweScaled,
    ResidualFn,
    offset_points,
    residuals,
    sigma_offsets,
    weighted_mean,
    weighted_outer,
    weighted_sum,
)

_LOG_2PI = 1.8378770664093453


class StateSpaceModel(eqx.Module):
    """The pure functions of a nonlinear model with additive Gaussian noise.

    ``motion(x, u) -> x'`` and ``measurement(x) -> z`` (or ``measurement(x, r) -> z`` when the
    filter is given per-step ``measurement_inputs`` r, data the prediction of z depends on besides
    the state); the optional functions replace ``-``,
    ``+`` and the weighted mean for states (``state_*``) and measurements (``measurement_*``)
    that hold angles (see :mod:`jbevo.unscented`). All are static: a model holds no arrays, its
    learnable noise is passed to the filter separately.
    """

    motion: Callable[[Array, Any], Array] = eqx.field(static=True)
    measurement: Callable[..., Array] = eqx.field(static=True)
    state_residual: ResidualFn | None = eqx.field(static=True, default=None)
    state_add: AddFn | None = eqx.field(static=True, default=None)
    state_mean: MeanFn | None = eqx.field(static=True, default=None)
    measurement_residual: ResidualFn | None = eqx.field(static=True, default=None)
    measurement_mean: MeanFn | None = eqx.field(static=True, default=None)


class GaussianState(NamedTuple):
    """A Gaussian belief: mean ``(n,)`` and covariance ``(n, n)``."""

    mean: Float[Array, " n"]
    cov: Float[Array, "n n"]


class FilterResult(NamedTuple):
    """Output of :func:`filter` (and, per block, of :func:`filter_blocks`)."""

    filtered_mean: Float[Array, "T n"]
    filtered_cov: Float[Array, "T n n"]
    predicted_mean: Float[Array, "T n"]  #: before the update of step t
    predicted_cov: Float[Array, "T n n"]
    log_likelihoods: Float[Array, " T"]  #: log p(z_t | z_<t) per step (0 where nothing observed)
    log_likelihood: Float[Array, ""]  #: sum over all steps
    #: The RTS smoother's gain into step t, ``Cov(x_{t-1}, x_t^-) (P_t^-)^-1`` (the belief before
    #: step t's prediction against the predicted one); ``None`` where not kept
    #: (:func:`filter_blocks`, results assembled by hand): the smoother then recomputes it.
    smoother_gains: Float[Array, "T n n"] | None = None


Scheme = MerweScaled | Julier


def predict(
    model: StateSpaceModel,
    state: GaussianState,
    control: Any,
    motion_cov: Float[Array, "n n"],
    scheme: Scheme = MerweScaled(),
) -> GaussianState:
    """Propagate ``state`` through ``model.motion(x, control)`` and add ``motion_cov`` (Q)."""
    return predict_with_cross(model, state, control, motion_cov, scheme)[0]


def predict_with_cross(
    model: StateSpaceModel,
    state: GaussianState,
    control: Any,
    motion_cov: Float[Array, "n n"],
    scheme: Scheme = MerweScaled(),
) -> tuple[GaussianState, Float[Array, "n n"]]:
    """:func:`predict`, and the cross-covariance ``Cov(x, x')`` of the state before and after
    the motion (``sum_i Wc_i dx_i dy_i^T``), which an RTS smoother's gain needs."""
    mean, cov = state
    w = scheme.weights(mean.shape[-1], mean.dtype)
    dx = sigma_offsets(linalg.cholesky(cov), w.spread)
    moved = jax.vmap(model.motion, in_axes=(0, None))(offset_points(mean, dx, model.state_add), control)
    new_mean = weighted_mean(moved, w.mean, model.state_mean)
    d = residuals(moved, new_mean, model.state_residual)
    predicted = GaussianState(new_mean, linalg.symmetrize(weighted_outer(w.cov, d, d) + motion_cov))
    return predicted, weighted_outer(w.cov, dx, d)


def update(
    model: StateSpaceModel,
    state: GaussianState,
    measurement: Float[Array, " m"],
    measurement_cov: Float[Array, "m m"],
    scheme: Scheme = MerweScaled(),
    mask: Bool[Array, " m"] | None = None,
    measurement_input: Any = None,
) -> tuple[GaussianState, Float[Array, ""]]:
    """Condition ``state`` on ``measurement`` (noise ``measurement_cov``, R).

    Entries that are NaN or where ``mask`` is False are skipped exactly (module docstring).
    With ``measurement_input`` r, the model's measurement is called as ``measurement(x, r)``.
    Returns the posterior and ``log p(measurement)`` under the predictive distribution.
    """
    mean, cov = state
    w = scheme.weights(mean.shape[-1], mean.dtype)
    dx = sigma_offsets(linalg.cholesky(cov), w.spread)  # = residuals of the points from the mean
    points = offset_points(mean, dx, model.state_add)
    if measurement_input is None:
        z_points = jax.vmap(model.measurement)(points)
    else:
        z_points = jax.vmap(model.measurement, in_axes=(0, None))(points, measurement_input)
    z_pred = weighted_mean(z_points, w.mean, model.measurement_mean)
    dz = residuals(z_points, z_pred, model.measurement_residual)
    s = weighted_outer(w.cov, dz, dz) + measurement_cov
    cross = weighted_outer(w.cov, dx, dz)

    observed = jnp.isfinite(measurement)
    if mask is not None:
        observed = observed & mask
    z_safe = jnp.where(observed, measurement, z_pred)
    if model.measurement_residual is None:
        innovation = z_safe - z_pred
    else:
        innovation = model.measurement_residual(z_safe, z_pred)
    innovation = jnp.where(observed, innovation, 0.0)
    both = observed[:, None] & observed[None, :]
    s = jnp.where(both, s, jnp.eye(s.shape[-1], dtype=s.dtype))
    cross = jnp.where(observed[None, :], cross, 0.0)

    # W = L^-1 Pxz^T and e = L^-1 y for L = chol(S), in one pass (no inverse, no division).
    solved, logdet = linalg.whiten(s, jnp.concatenate([cross.T, innovation[:, None]], axis=1))
    gain_t, e = solved[:, :-1], solved[:, -1]
    correction = weighted_sum(e, gain_t)  # W^T e
    new_mean = correction + mean if model.state_add is None else model.state_add(mean, correction)
    new_cov = linalg.symmetrize(cov - weighted_sum(jnp.ones_like(e), gain_t[:, :, None] * gain_t[:, None, :]))
    n_obs = jnp.sum(observed).astype(mean.dtype)
    log_lik = -0.5 * (weighted_sum(e, e) + logdet + n_obs * _LOG_2PI)
    return GaussianState(new_mean, new_cov), log_lik


def linear_update(
    state: GaussianState,
    h: Float[ArrayLike, " n"],
    innovation: Float[ArrayLike, ""],
    variance: Float[ArrayLike, ""],
    use: Bool[ArrayLike, ""] | bool = True,
) -> GaussianState:
    """Kalman update with one scalar linear measurement ``z = h x + v``, ``v ~ N(0, variance)``,
    given its ``innovation`` ``z - h mean``; the covariance is symmetrised, and the belief is left
    unchanged where ``use`` is False. For measurements that are linear in the state (no sigma
    points needed), as the attitude filters' pitch measurements from the BEV are."""
    mean, cov = state
    h = jnp.asarray(h, mean.dtype)
    ph = cov @ h
    gain = ph / (h @ ph + variance)
    new = GaussianState(mean + gain * innovation, linalg.symmetrize(cov - jnp.outer(gain, ph)))
    return jax.tree_util.tree_map(lambda a, b: jnp.where(use, a, b), new, state)


def _noise_at(noise: Array | None, t_noise: Array | None) -> Array:
    """Per-step noise: the scanned slice if the noise has a time axis, else the constant."""
    chosen = noise if t_noise is None else t_noise
    assert chosen is not None  # filter() passes one of the two
    return chosen


def _step(model, scheme, q_const, r_const, state, inputs):
    control, z, mask, q_t, r_t, z_input = inputs
    predicted, cross = predict_with_cross(model, state, control, _noise_at(q_const, q_t), scheme)
    filtered, ll = update(model, predicted, z, _noise_at(r_const, r_t), scheme, mask, z_input)
    # The RTS smoother's gain from the belief before this step to this step (the update already
    # factorised the predicted covariance: XLA computes the factor once).
    gain = linalg.cho_solve(linalg.cholesky(predicted.cov), cross.T).T
    return filtered, (filtered, predicted, ll, gain)


def filter(
    model: StateSpaceModel,
    initial: GaussianState,
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
) -> FilterResult:
    """Run the UKF over a sequence with ``jax.lax.scan``.

    Step ``t`` predicts with ``controls[t]`` (any pytree whose leaves have leading axis ``T``;
    ``None`` for no control) and ``motion_cov`` (Q), then updates with ``measurements[t]`` and
    ``measurement_cov`` (R). Q and R are constant or have a leading time axis ``T``.
    ``initial`` is the belief before the first prediction. NaN measurement entries and
    ``mask == False`` are skipped. ``check_inputs`` raises (via ``equinox.error_if``, also
    under ``jit``) on non-finite controls or initial state, and on Q, R or the initial
    covariance that are not finite symmetric positive definite. ``unroll`` is passed to
    ``lax.scan``. ``measurement_inputs`` (a pytree with leading axis ``T``, or ``None``) is
    passed to the model as ``measurement(x, measurement_inputs[t])``. ``block`` runs the loop in
    blocks of that many steps (:func:`jbevo.filtering.blocked_scan.blocked_scan`; the same
    results): ``"auto"`` makes a forward run of one sequence of a small model faster on the CPU
    (docs/filtering.md); keep 1 (one ``lax.scan``) under ``vmap`` or differentiation, where it
    is slower. ``one_kernel`` compiles the loop as one XLA:CPU kernel where the model allows
    (:func:`jbevo.filtering.cpu_kernel.one_kernel`; the same results to round-off, faster);
    ``False`` keeps XLA's plain loop.
    """
    initial, controls, measurements, motion_cov, measurement_cov, mask = _sequence_inputs(
        model, initial, controls, measurements, motion_cov, measurement_cov, mask, check_inputs, measurement_inputs
    )

    q_const, q_seq = constant_or_sequence(motion_cov)
    r_const, r_seq = constant_or_sequence(measurement_cov)

    def body(state, inputs):
        return _step(model, scheme, q_const, r_const, state, inputs)

    _, (filtered, predicted, lls, gains) = blocked_scan(
        body,
        initial,
        (controls, measurements, mask, q_seq, r_seq, measurement_inputs),
        block=block,
        unroll=unroll,
        one_kernel=one_kernel,
    )
    return FilterResult(filtered.mean, filtered.cov, predicted.mean, predicted.cov, lls, jnp.sum(lls), gains)


def filter_blocks(
    model: StateSpaceModel,
    initial: GaussianState,
    controls: Any,
    measurements: Float[Array, "T K m"],
    motion_cov: Float[Array, "n n"],
    measurement_cov: Float[Array, "m m"],
    *,
    scheme: Scheme = MerweScaled(),
    mask: Bool[Array, "T K m"] | None = None,
    check_inputs: bool = True,
    checkpoint: bool = True,
) -> FilterResult:
    """Run ``K`` predict/update steps per output step, as a nested ``lax.scan``.

    For filters that run faster than their outputs, e.g. the attitude filter with ~10 IMU
    samples per camera frame: ``controls`` leaves and ``measurements`` have leading axes
    ``(T, K)``; a block with no measurement uses NaN rows. Returns one row per block: the
    belief after its last update, the prediction before its first update, and the block's
    summed log-likelihood. ``checkpoint`` wraps each block in ``jax.checkpoint`` so reverse-mode
    memory grows with ``T``, not ``T * K``.
    """
    measurements = jnp.asarray(measurements)
    if measurements.ndim != 3:
        raise ValueError(f"measurements must have shape (T, K, m), got {measurements.shape}")
    steps, block, m = measurements.shape
    _check_controls(controls, steps, "controls", "T", block)
    if mask is not None:
        mask = jnp.asarray(mask, dtype=bool)
        if mask.shape != measurements.shape:
            raise ValueError(f"mask must have the shape of measurements {measurements.shape}, got {mask.shape}")
    initial, measurements, motion_cov, measurement_cov = _promoted(initial, measurements, motion_cov, measurement_cov)
    n = _check_state(initial)
    _check_noise(motion_cov, n, None, "motion_cov")
    _check_noise(measurement_cov, m, None, "measurement_cov")
    _check_model(model, initial, jax.tree.map(lambda a: a[0, 0], controls), m)
    if check_inputs:
        initial, controls, motion_cov, measurement_cov = _checked(initial, controls, motion_cov, measurement_cov)

    def inner(state, inputs):
        return _step(model, scheme, motion_cov, measurement_cov, state, (*inputs, None, None, None))

    def run_block(state, inputs):
        last, (_, predicted, lls, _) = jax.lax.scan(inner, state, inputs)
        first_prediction = jax.tree.map(lambda a: a[0], predicted)
        return last, (last, first_prediction, jnp.sum(lls))

    if checkpoint:
        run_block = jax.checkpoint(run_block)
    _, (filtered, predicted, lls) = jax.lax.scan(run_block, initial, (controls, measurements, mask))
    return FilterResult(filtered.mean, filtered.cov, predicted.mean, predicted.cov, lls, jnp.sum(lls))


# ----------------------------------------------------------------------------- input checks


def _sequence_inputs(model, initial, controls, measurements, motion_cov, measurement_cov, mask, check_inputs, measurement_inputs):
    """The checks and promotions :func:`filter` (and the square-root filter) apply to a
    sequence's inputs: ``(initial, controls, measurements, motion_cov, measurement_cov, mask)``,
    of one dtype, shapes checked (``ValueError`` naming the argument), values checked at run
    time with ``check_inputs``."""
    initial, measurements, motion_cov, measurement_cov = _promoted(initial, measurements, motion_cov, measurement_cov)
    n = _check_state(initial)
    if measurements.ndim != 2:
        raise ValueError(f"measurements must have shape (T, m), got {measurements.shape}")
    steps, m = measurements.shape
    _check_controls(controls, steps, "controls", "T")
    if measurement_inputs is not None:
        _check_controls(measurement_inputs, steps, "measurement_inputs", "T")
    _check_noise(motion_cov, n, steps, "motion_cov")
    _check_noise(measurement_cov, m, steps, "measurement_cov")
    if mask is not None:
        mask = jnp.asarray(mask, dtype=bool)
        if mask.shape != measurements.shape:
            raise ValueError(f"mask must have the shape of measurements {measurements.shape}, got {mask.shape}")
    control0 = jax.tree.map(lambda a: a[0], controls)
    z_input0 = None if measurement_inputs is None else jax.tree.map(lambda a: a[0], measurement_inputs)
    _check_model(model, initial, control0, m, z_input0)
    if check_inputs:
        initial, controls, motion_cov, measurement_cov = _checked(initial, controls, motion_cov, measurement_cov)
    return initial, controls, measurements, motion_cov, measurement_cov, mask


def constant_or_sequence(noise: Array) -> tuple[Array | None, Array | None]:
    """``(noise, None)`` for a constant ``(d, d)`` noise, ``(None, noise)`` for one with a
    leading time axis (the scanned slice): the two forms :func:`filter` takes."""
    return (noise, None) if noise.ndim == 2 else (None, noise)


def _promoted(initial, measurements, motion_cov, measurement_cov):
    """The belief, measurements and noise as arrays of one floating dtype (the widest of them):
    the scan's carry keeps its type from step to step."""
    arrays = [jnp.asarray(a) for a in (*initial, measurements, motion_cov, measurement_cov)]
    dtype = jnp.result_type(*arrays, jnp.float32)
    mean, cov, measurements, motion_cov, measurement_cov = (a.astype(dtype) for a in arrays)
    return GaussianState(mean, cov), measurements, motion_cov, measurement_cov


def _check_state(initial: GaussianState) -> int:
    mean, cov = initial
    if mean.ndim != 1:
        raise ValueError(f"initial mean must have shape (n,), got {mean.shape}")
    n = mean.shape[0]
    if cov.shape != (n, n):
        raise ValueError(f"initial cov must have shape ({n}, {n}) to match the mean, got {cov.shape}")
    return n


def _check_noise(noise: Array, dim: int, steps: int | None, name: str) -> None:
    ok = noise.shape == (dim, dim) or (steps is not None and noise.shape == (steps, dim, dim))
    if not ok:
        timed = f" or ({steps}, {dim}, {dim})" if steps is not None else ""
        raise ValueError(f"{name} must have shape ({dim}, {dim}){timed}, got {noise.shape}")


def _check_controls(controls: Any, steps: int, name: str, axis: str, block: int | None = None) -> None:
    for leaf in jax.tree.leaves(controls):
        shape = jnp.shape(leaf)
        lead = (steps,) if block is None else (steps, block)
        if shape[: len(lead)] != lead:
            raise ValueError(f"every {name} leaf must have leading axes {lead} matching measurements ({axis}), got {shape}")


def _check_model(model: StateSpaceModel, initial: GaussianState, control: Any, m: int, z_input: Any = None) -> None:
    n = initial.mean.shape[0]
    x = jax.ShapeDtypeStruct((n,), initial.mean.dtype)
    moved = jax.eval_shape(model.motion, x, control)
    if getattr(moved, "shape", None) != (n,):
        raise ValueError(f"model.motion must return a state of shape ({n},), got {getattr(moved, 'shape', moved)}")
    z = jax.eval_shape(model.measurement, x) if z_input is None else jax.eval_shape(model.measurement, x, z_input)
    if getattr(z, "shape", None) != (m,):
        raise ValueError(f"model.measurement must return shape ({m},) to match the measurements, got {getattr(z, 'shape', z)}")


def _checked(initial, controls, motion_cov, measurement_cov):
    """Runtime checks that also work under jit (equinox.error_if)."""
    bad_controls = jnp.array(False)
    for leaf in jax.tree.leaves(controls):
        bad_controls = bad_controls | ~jnp.all(jnp.isfinite(leaf))
    controls = jax.tree.map(lambda a: eqx.error_if(a, bad_controls, "controls contain NaN or inf"), controls)
    mean = eqx.error_if(initial.mean, ~jnp.all(jnp.isfinite(initial.mean)), "initial mean is not finite")
    cov = eqx.error_if(
        initial.cov, ~linalg.is_positive_definite(initial.cov), "initial cov is not finite symmetric positive definite"
    )
    motion_cov = eqx.error_if(
        motion_cov,
        ~jnp.all(linalg.is_positive_definite(motion_cov)),
        "motion_cov (Q) is not finite symmetric positive definite",
    )
    measurement_cov = eqx.error_if(
        measurement_cov,
        ~jnp.all(linalg.is_positive_definite(measurement_cov)),
        "measurement_cov (R) is not finite symmetric positive definite",
    )
    return GaussianState(mean, cov), controls, motion_cov, measurement_cov


__all__ = [
    "CholeskyCovariance",
    "DiagonalCovariance",
    "FilterResult",
    "GaussianState",
    "Scheme",
    "StateSpaceModel",
    "filter",
    "filter_blocks",
    "linear_update",
    "predict",
    "predict_with_cross",
    "update",
]
