"""The data splits of the experiments: KITTI odometry's train (00-08) and test (09, 10)
sequences, the training sequences split once more for checkpoint selection (fit on 00-07,
validate on 08), and the localization scenes' quarters (the first two train, the third validates, the
last tests)."""

from __future__ import annotations

from jbevo.data.sequence import Sequence, window

KITTI_TRAIN = ("00", "01", "02", "03", "04", "05", "06", "07", "08")


KITTI_TEST = ("09", "10")


#: The training sequences that fit the parameters when 08 selects the checkpoint.
KITTI_FIT = KITTI_TRAIN[:-1]


#: The training sequence that selects the checkpoint (never a test sequence).
KITTI_VALIDATION = KITTI_TRAIN[-1:]


def split_quarters(seq: Sequence) -> tuple[Sequence, Sequence, Sequence]:
    """The localization split: the first two quarters train, the third validates, the last
    tests."""
    q = seq.num_frames // 4
    if q < 1:
        raise ValueError(f"a sequence of {seq.num_frames} frames cannot be split into quarters")
    return window(seq, 0, 2 * q), window(seq, 2 * q, q), window(seq, 3 * q, seq.num_frames - 3 * q)


PARTS = ("train", "val", "test", "all")


def part_range(frames: int, part: str) -> tuple[int, int]:
    """Frames ``[start, stop)`` of ``part`` (train: the first two quarters, val: the third,
    test: the last, all) in a drive of ``frames`` frames."""
    q = frames // 4
    ranges = {"train": (0, 2 * q), "val": (2 * q, 3 * q), "test": (3 * q, frames), "all": (0, frames)}
    if part not in ranges:
        raise ValueError(f"unknown part {part!r}; known: {PARTS}")
    return ranges[part]


__all__ = ["KITTI_FIT", "KITTI_TEST", "KITTI_TRAIN", "KITTI_VALIDATION", "PARTS", "part_range", "split_quarters"]
