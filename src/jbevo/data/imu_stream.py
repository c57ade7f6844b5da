"""An IMU as it was recorded (one time-ordered stream of samples) and its frame blocks.

A :class:`~jbevo.data.sequence.Sequence` holds the IMU in blocks: block ``t`` has the samples taken
in ``[frame_times[t-1], frame_times[t])``. A real IMU does not give the same number of samples
in every frame interval (the synced KITTI raw data has 0-2, a shifted 100 Hz stream 9-11), so
there are two ways from a stream to blocks:

* :func:`group_blocks` keeps every sample as recorded and pads each block *after* its real
  samples with NaN rows to the largest count (the filters fill a block's missing rows with the
  mean of its valid ones, so a block always integrates the whole frame interval);
* :func:`resample_blocks` interpolates the stream (linearly) at ``S`` evenly spaced instants per
  frame interval, at the midpoints of ``S`` equal sub-intervals: what a calibrated stream, whose
  time offset moved its samples off the frame grid, is turned into.

Times are float64 seconds; arrays are numpy (this runs once per drive, before any model).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

#: Spacing of the NaN padding rows after a block's last real sample (seconds).
PAD_SPACING = 1e-6


class ImuStream(NamedTuple):
    """``M`` IMU samples: times (s, float64, increasing), body angular rate (rad/s) and specific
    force (m/s^2), IMU frame (x forward, y left, z up for KITTI's OXTS)."""

    times: np.ndarray  # (M,)
    gyro: np.ndarray  # (M, 3)
    accel: np.ndarray  # (M, 3)

    def check(self, what: str = "IMU stream") -> ImuStream:
        """Raise ``ValueError`` naming ``what`` if shapes disagree, values are not finite or the
        times do not increase."""
        m = len(self.times)
        if m == 0:
            raise ValueError(f"{what} has no samples")
        for name in ("gyro", "accel"):
            shape = np.shape(getattr(self, name))
            if shape != (m, 3):
                raise ValueError(f"{what}: {name} must have shape ({m}, 3), got {shape}")
        for name in ("times", "gyro", "accel"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f"{what}: {name} holds NaN or infinite values")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError(f"{what}: times must increase strictly")
        return self

    def between(self, start: float, stop: float) -> ImuStream:
        """The samples with ``start <= time < stop``."""
        keep = (self.times >= start) & (self.times < stop)
        return ImuStream(self.times[keep], self.gyro[keep], self.accel[keep])


def group_blocks(stream: ImuStream, frame_times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(imu_times (T, S), gyro (T, S, 3), accel (T, S, 3))``: every sample in the block of the
    frame interval it falls in (``frame_times[t-1] <= time < frame_times[t]``; block 0 takes the
    samples in the frame interval before the first frame, at the median frame step), padded after
    its real samples with NaN rows (times ``PAD_SPACING`` apart) to the largest count ``S``; a block
    without samples is all NaN. Samples outside the drive are dropped."""
    frame_times = np.asarray(frame_times, float)
    step = float(np.median(np.diff(frame_times))) if len(frame_times) > 1 else 0.1
    edges = np.concatenate([[frame_times[0] - step], frame_times])
    block = np.searchsorted(edges, stream.times, side="right") - 1
    keep = (block >= 0) & (block < len(frame_times))
    counts = np.bincount(block[keep], minlength=len(frame_times))
    s = max(1, int(counts.max()))
    gyro = np.full((len(frame_times), s, 3), np.nan)
    accel = np.full_like(gyro, np.nan)
    times = np.empty((len(frame_times), s))
    first = np.searchsorted(block, np.arange(len(frame_times)), side="left")
    for t in range(len(frame_times)):
        n = counts[t]
        rows = slice(first[t], first[t] + n)
        gyro[t, :n], accel[t, :n], times[t, :n] = stream.gyro[rows], stream.accel[rows], stream.times[rows]
        last = times[t, n - 1] if n else edges[t]
        times[t, n:] = last + PAD_SPACING * np.arange(1, s - n + 1)
    return times, gyro, accel


def resample_blocks(
    stream: ImuStream, frame_times: np.ndarray, samples_per_frame: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(imu_times (T, S), gyro (T, S, 3), accel (T, S, 3))`` with ``S = samples_per_frame``: the
    stream interpolated linearly at the midpoints of ``S`` equal parts of each frame interval
    (block 0: the interval before the first frame, at the first step). Instants outside the
    stream's time span are NaN rows."""
    frame_times = np.asarray(frame_times, float)
    if samples_per_frame < 1:
        raise ValueError(f"samples_per_frame must be >= 1, got {samples_per_frame}")
    step = np.diff(frame_times)
    first_step = step[0] if len(step) else 0.1
    starts = np.concatenate([[frame_times[0] - first_step], frame_times[:-1]])
    widths = np.concatenate([[first_step], step])
    times = starts[:, None] + widths[:, None] * (np.arange(samples_per_frame) + 0.5)[None, :] / samples_per_frame
    flat = times.reshape(-1)
    inside = (flat >= stream.times[0]) & (flat <= stream.times[-1])

    def interp(values):
        out = np.stack([np.interp(flat, stream.times, values[:, i]) for i in range(3)], -1)
        out[~inside] = np.nan
        return out.reshape(*times.shape, 3)

    return times, interp(stream.gyro), interp(stream.accel)


def stream_from_blocks(imu_times: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> ImuStream:
    """The valid (NaN-free) samples of ``(T, S)`` blocks as one stream."""
    times = np.asarray(imu_times, float).reshape(-1)
    g = np.asarray(gyro, float).reshape(-1, 3)
    a = np.asarray(accel, float).reshape(-1, 3)
    ok = np.all(np.isfinite(g), -1) & np.all(np.isfinite(a), -1)
    return ImuStream(times[ok], g[ok], a[ok])


__all__ = ["PAD_SPACING", "ImuStream", "group_blocks", "resample_blocks", "stream_from_blocks"]
