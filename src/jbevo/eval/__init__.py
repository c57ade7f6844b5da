"""Evaluation: the KITTI devkit errors, ATE and RPE with alignment, plots, the models' scores,
and batched evaluation over many sequences (pose files are read and written by
:mod:`jbevo.data.pose_files`)."""

from jbevo.eval import plots
from jbevo.eval.alignment import align, umeyama
from jbevo.eval.batch import run_many
from jbevo.eval.devkit import SEGMENT_LENGTHS, kitti_errors, kitti_segment_errors
from jbevo.eval.scores import pose_errors, score
from jbevo.eval.trajectory_metrics import ate, evaluate, evaluate_batch, rpe, summary

__all__ = [
    "SEGMENT_LENGTHS",
    "align",
    "ate",
    "evaluate",
    "evaluate_batch",
    "kitti_errors",
    "kitti_segment_errors",
    "plots",
    "pose_errors",
    "rpe",
    "run_many",
    "score",
    "summary",
    "umeyama",
]
