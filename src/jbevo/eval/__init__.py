"""Evaluation: the KITTI devkit errors, ATE and RPE with alignment, KITTI and TUM pose files,
plots, the models' scores, and batched evaluation over many sequences."""

from jbevo.eval import plots
from jbevo.eval.alignment import align, umeyama
from jbevo.eval.batch import run_many
from jbevo.eval.devkit import SEGMENT_LENGTHS, kitti_errors, kitti_segment_errors
from jbevo.eval.pose_files import match_frames, read_kitti, read_poses, read_tum, write_kitti, write_tum
from jbevo.eval.scores import pose_errors, score
from jbevo.eval.trajectory_metrics import ate, evaluate, evaluate_batch, rpe, summary

__all__ = [
    "SEGMENT_LENGTHS", "align", "ate", "evaluate", "evaluate_batch", "kitti_errors", "kitti_segment_errors", "match_frames",
    "plots", "pose_errors", "read_kitti", "read_poses", "read_tum", "rpe", "run_many", "score", "summary", "umeyama",
    "write_kitti", "write_tum",
]
