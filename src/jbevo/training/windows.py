"""Training windows cut from whole drives, without copying them.

A :class:`Windows` holds each drive once (host numpy arrays) and a window as a drive index and a
start frame; :meth:`Windows.batch` slices the frames of the windows asked for and stacks them, so
the training set's memory is the drives' whatever the windows' overlap (materialised windows
every half a window hold every frame twice more, and once more while they are joined)."""

from __future__ import annotations

from collections.abc import Sequence as Seq
from dataclasses import dataclass

import jax
import numpy as np

from jbevo.data import sequence as sq


@dataclass(frozen=True)
class Windows:
    """Windows of ``length`` frames: window ``i`` is frames ``[starts[i], starts[i] + length)`` of
    ``drives[drive_index[i]]`` (unbatched sequences, numpy leaves, one camera image size)."""

    drives: tuple[sq.Sequence, ...]
    drive_index: np.ndarray  #: int, one per window
    starts: np.ndarray  #: int, one per window
    length: int

    def __len__(self) -> int:
        return len(self.starts)

    def batch(self, idx: Seq[int] | np.ndarray) -> sq.Sequence:
        """Windows ``idx`` batched along a leading axis (numpy leaves; a copy of these frames only)."""
        idx = np.asarray(idx, int)
        if idx.ndim != 1 or (idx.size and not (0 <= idx.min() and idx.max() < len(self))):
            raise IndexError(f"window indices must be a 1-D list within [0, {len(self)}), got {idx.tolist()}")
        parts = [
            sq.window(self.drives[self.drive_index[i]], int(self.starts[i]), self.length)
            for i in idx  # views: sq.window slices every time-indexed leaf
        ]
        return jax.tree_util.tree_map(lambda *x: np.stack(x), *parts)

    def all(self) -> sq.Sequence:
        """Every window batched (materialised: for evaluation on short windows, not training)."""
        return self.batch(np.arange(len(self)))


def training_windows(seqs: list[sq.Sequence], window: int, stride: int | None = None) -> Windows:
    """Every window of ``window`` frames every ``stride`` frames (default: half a window) of the
    sequences long enough for one, in order of sequence then start. ``ValueError`` if none is.
    ``window`` 0 takes the whole sequences (which must then share one length)."""
    if not seqs:
        raise ValueError("training_windows needs at least one sequence")
    if window == 0:
        sq.check_stackable(seqs)
        length, stride = seqs[0].num_frames, 1
    else:
        length, stride = window, (max(1, window // 2) if stride is None else stride)
    if length < 1 or stride < 1:
        raise ValueError(f"windows need a length and stride >= 1, got {length} and {stride}")
    structure = jax.tree_util.tree_structure(seqs[0])
    drives, drive_index, starts = [], [], []
    for s in seqs:
        if s.num_frames < length:
            continue
        if jax.tree_util.tree_structure(s) != structure:
            raise ValueError("the sequences differ in camera image size or layout; windows need one")
        for start in range(0, s.num_frames - length + 1, stride):
            drive_index.append(len(drives))
            starts.append(start)
        drives.append(jax.tree_util.tree_map(np.asarray, s))
    if not drives:
        raise ValueError(f"no sequence has {window} frames for a window; lower the window")
    return Windows(tuple(drives), np.asarray(drive_index, int), np.asarray(starts, int), length)


__all__ = ["Windows", "training_windows"]
