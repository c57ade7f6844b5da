"""Training: the optimisation loop that ``train`` and ``localize train`` share, training windows,
validation, and checkpoints."""

from jbevo.training import checkpoint
from jbevo.training.loop import TrainingDiverged, load_best, make_step, run_epoch, save_epoch, start_run, train_epochs
from jbevo.training.validation import validate, validate_localization
from jbevo.training.windows import training_windows

__all__ = [
    "TrainingDiverged",
    "checkpoint",
    "load_best",
    "make_step",
    "run_epoch",
    "save_epoch",
    "start_run",
    "train_epochs",
    "training_windows",
    "validate",
    "validate_localization",
]
