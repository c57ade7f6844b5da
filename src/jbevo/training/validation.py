"""Validation of BEVO during training: a model's scores over validation drives, run the way they
are scored (jitted once: every epoch's model has the same structure, so the compiled recursion is
reused)."""

from __future__ import annotations

import numpy as np

from jbevo.data.map import Map
from jbevo.data.sequence import Sequence
from jbevo.eval.scores import pose_errors, score
from jbevo.models.bevo import Bevo
from jbevo.models.bevo_plus import BevoPlus
from jbevo.models.runners import run_bevo, run_bevo_batch, run_bevo_plus
from jbevo.training.windows import training_windows


def validate(model: Bevo, seqs: list[Sequence], lengths: tuple[float, ...], window: int = 0, warm_start: bool = False) -> dict:
    """:func:`jbevo.eval.scores.score` of ``model`` over ``seqs``: the whole sequences
    (``window`` 0; from a cold start, or from the truth's attitude and speed with
    ``warm_start``), or windows of ``window`` frames, each warm-started (as training runs them)."""
    if window:
        batch = training_windows(seqs, window, stride=window).all()
        return score(run_bevo_batch(model, batch, True), batch, lengths)
    return score([run_bevo(model, s, warm_start) for s in seqs], seqs, lengths)


def validate_localization(model: BevoPlus, seq: Sequence, map_: Map) -> dict:
    """:func:`jbevo.eval.scores.pose_errors` of BEVO+ localizing the whole ``seq`` on ``map_``
    (warm start at the true first pose), and the fraction of accepted map fixes."""
    out = run_bevo_plus(model, seq, map_, True)
    return pose_errors(out.poses, seq.planar) | {"accepted": float(np.mean(np.asarray(out.accepted)))}


__all__ = ["validate", "validate_localization"]
