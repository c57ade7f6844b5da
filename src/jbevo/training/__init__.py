"""Training: the optimisation loop that ``train`` and ``localize train`` share, training windows,
validation, and checkpoints."""

from jbevo.training import checkpoint
from jbevo.training.loop import TrainingDiverged, make_step, run_epoch, save_epoch, start_run
from jbevo.training.validation import validate, validate_localization
from jbevo.training.windows import training_windows

__all__ = [
    "TrainingDiverged",
    "checkpoint",
    "make_step",
    "run_epoch",
    "save_epoch",
    "start_run",
    "training_windows",
    "validate",
    "validate_localization",
]
