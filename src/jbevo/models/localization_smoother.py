"""BEVO+'s trajectory smoothed offline: the unscented RTS smoother over the pose filter's output.

BEVO+ localizes causally: the pose at frame ``t`` knows the map fixes up to ``t``. Offline (a
recorded drive, a map survey, ground truth for another sensor) every fix can inform every pose:
:func:`smooth_localization` runs :func:`jbevo.filtering.smoother.smooth` backwards over
:class:`jbevo.models.bevo_plus.LocalizationOutput`, with the filter's own increments and
per-frame motion noise ``Q_t`` (the odometry's confidence scales it). Rejected fixes were never
applied, so the smoother bridges them as it bridges any gap. Where the filter re-anchored on the
map after repeated rejections it had inflated its prediction's covariance; the smoother uses the
uninflated one there (it smooths the model, not the filter's one-off correction).
"""

from __future__ import annotations

import jax.numpy as jnp

from jbevo.filtering.planar import planar_pose_model
from jbevo.filtering.smoother import SmootherResult, smooth
from jbevo.filtering.ukf import FilterResult
from jbevo.models.bevo_plus import LocalizationOutput


def smooth_localization(out: LocalizationOutput) -> SmootherResult:
    """The smoothed poses of one localized sequence (``jax.vmap`` for a batch)."""
    if out.poses.ndim != 2:
        raise ValueError(
            f"smooth_localization takes one sequence's output (poses (T, 3)), got poses {out.poses.shape}: vmap over batches"
        )
    zeros = jnp.zeros(out.poses.shape[:1], out.poses.dtype)
    # The smoother reads the filtered beliefs only; the predicted ones are not part of BEVO+'s output.
    filtered = FilterResult(out.poses, out.covariances, out.poses, out.covariances, zeros, jnp.sum(zeros))
    return smooth(planar_pose_model(), filtered, out.increments, out.motion_covariances)


__all__ = ["smooth_localization"]
