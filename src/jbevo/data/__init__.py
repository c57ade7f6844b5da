"""Data: the :class:`Sequence` every model takes and the :class:`Map` BEVO+ localizes on, their
files, KITTI and TUM pose files, the KITTI readers and writers, and the data splits. The
synthetic world lives in :mod:`jbevo.data.synthetic`, the datasets the commands offer in
:mod:`jbevo.data.catalog`."""

from jbevo.data.kitti import read_odometry, read_raw, read_run, write_odometry, write_raw
from jbevo.data.map import Map
from jbevo.data.pose_files import Trajectory, match_frames, read_kitti, read_poses, read_tum, write_kitti, write_tum
from jbevo.data.sequence import Sequence, check, stack, window, windows
from jbevo.data.sequence_file import load, save
from jbevo.data.splits import KITTI_TEST, KITTI_TRAIN, split_quarters

__all__ = [
    "KITTI_TEST",
    "KITTI_TRAIN",
    "Map",
    "Sequence",
    "Trajectory",
    "check",
    "load",
    "match_frames",
    "read_kitti",
    "read_odometry",
    "read_poses",
    "read_raw",
    "read_run",
    "read_tum",
    "save",
    "split_quarters",
    "stack",
    "window",
    "windows",
    "write_kitti",
    "write_odometry",
    "write_raw",
    "write_tum",
]
