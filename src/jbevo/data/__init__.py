"""Data: the :class:`Sequence` every model takes and the :class:`Map` BEVO+ localizes on, their
files, the KITTI readers and writers, the data splits, and the datasets the commands offer. The
synthetic world lives in :mod:`jbevo.data.synthetic`."""

from jbevo.data.catalog import DATASETS, load_sequences
from jbevo.data.kitti import read_odometry, read_raw, write_odometry, write_raw
from jbevo.data.map import Map
from jbevo.data.sequence import Sequence, check, stack, window, windows
from jbevo.data.sequence_file import load, save
from jbevo.data.splits import KITTI_TEST, KITTI_TRAIN, split_quarters

__all__ = [
    "DATASETS", "KITTI_TEST", "KITTI_TRAIN", "Map", "Sequence", "check", "load", "load_sequences", "read_odometry", "read_raw",
    "save", "split_quarters", "stack", "window", "windows", "write_odometry", "write_raw",
]
