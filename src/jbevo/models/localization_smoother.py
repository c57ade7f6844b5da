"""BEVO+'s trajectory smoothed offline: the unscented RTS smoother over the pose filter's output.

BEVO+ localizes causally: the pose at frame ``t`` knows the map fixes up to ``t``. Offline (a
recorded drive, a map survey, ground truth for another sensor) every fix can inform every pose:
:func:`smooth_localization` runs :func:`jbevo.filtering.smoother.smooth_beliefs` backwards over
:class:`jbevo.models.bevo_plus.LocalizationOutput`, with the filter's own increments and
per-frame motion noise ``Q_t`` (the odometry's confidence scales it). Rejected fixes were never
applied, so the smoother bridges them as it bridges any gap. Where the filter re-anchored on the
map after repeated rejections it had inflated its prediction's covariance; the smoother uses the
uninflated one there (it smooths the model, not the filter's one-off correction).
"""

from __future__ import annotations

from jbevo.filtering.planar import planar_pose_model
from jbevo.filtering.smoother import SmootherResult, smooth_beliefs
from jbevo.models.bevo_plus import LocalizationOutput


def smooth_localization(out: LocalizationOutput) -> SmootherResult:
    """The smoothed poses of one localized sequence (``jax.vmap`` for a batch)."""
    if out.poses.ndim != 2:
        raise ValueError(
            f"smooth_localization takes one sequence's output (poses (T, 3)), got poses {out.poses.shape}: vmap over batches"
        )
    # BEVO+'s output holds the filtered beliefs only: the smoother recomputes the predictions.
    return smooth_beliefs(planar_pose_model(), out.poses, out.covariances, out.increments, out.motion_covariances)


__all__ = ["smooth_localization"]
