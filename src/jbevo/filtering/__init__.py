"""Filtering: the unscented transform, the unscented Kalman filter (covariance and square-root
forms) and RTS smoother as pure JAX functions (``jit``, ``vmap``, ``grad``; exact missing-data
handling), the iterated posterior-linearisation smoother with its affine Kalman filter and
smoother parallel in time, batches held in the last axis (``vmap_last``), learnable noise covariances and their fitting, the planar pose model,
and the small dense linear algebra they run on.

Example::

    import jax.numpy as jnp
    from jbevo.filtering import DiagonalCovariance, GaussianState, planar_pose_model, ukf

    q = DiagonalCovariance.from_std(jnp.array([0.02, 0.01, 0.005]))
    r = DiagonalCovariance.from_std(jnp.array([0.5, 0.5, 0.05]))
    result = ukf.filter(planar_pose_model(), GaussianState(jnp.zeros(3), 0.1 * jnp.eye(3)), increments, fixes, q(), r())
"""

from jbevo.filtering import (
    batch_last,
    learning,
    linalg,
    noise,
    parallel,
    planar,
    posterior_linearisation,
    smoother,
    sqrt_ukf,
    ukf,
    unscented,
)
from jbevo.filtering.batch_last import vmap_last
from jbevo.filtering.noise import CholeskyCovariance, DiagonalCovariance
from jbevo.filtering.planar import planar_pose_model
from jbevo.filtering.smoother import SmootherResult, smooth
from jbevo.filtering.ukf import FilterResult, GaussianState, StateSpaceModel, filter_blocks, linear_update, predict, update
from jbevo.filtering.unscented import (
    Julier,
    MerweScaled,
    SigmaWeights,
    UnscentedResult,
    circular_mean_fn,
    sigma_points,
    unscented_transform,
    wrapped_add_fn,
    wrapped_residual_fn,
)

__all__ = [
    "CholeskyCovariance",
    "DiagonalCovariance",
    "FilterResult",
    "GaussianState",
    "Julier",
    "MerweScaled",
    "SigmaWeights",
    "SmootherResult",
    "StateSpaceModel",
    "UnscentedResult",
    "circular_mean_fn",
    "filter_blocks",
    "batch_last",
    "learning",
    "linalg",
    "linear_update",
    "noise",
    "parallel",
    "planar",
    "planar_pose_model",
    "posterior_linearisation",
    "predict",
    "sigma_points",
    "smooth",
    "smoother",
    "sqrt_ukf",
    "ukf",
    "unscented",
    "unscented_transform",
    "update",
    "vmap_last",
    "wrapped_add_fn",
    "wrapped_residual_fn",
]
