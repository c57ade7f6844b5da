"""KITTI and TUM pose files (numpy), readable by common tools such as evo.

* KITTI: one pose per line, the row-major top 3x4 of ``T_world_frame`` (12 numbers), or 13
  numbers with a leading frame index (as some evaluation tools write estimates that start late).
* TUM: ``timestamp tx ty tz qx qy qz qw`` per line (Hamilton quaternion, scalar last); lines
  starting with ``#`` are comments.

Planar trajectories ``(N, 3)`` of ``(x, y, yaw)`` (z up) are written as 6-DoF poses with ``z = 0``;
:func:`to_planar` reads them back. Writes are atomic: a failed write leaves the old file.
Malformed input raises ``ValueError`` naming the file, the line and what is wrong.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from jbevo.files import write_text_atomic
from jbevo.geometry.so3 import matrix_to_quaternion, quaternion_to_matrix


class Trajectory(NamedTuple):
    poses: np.ndarray  # (N, 4, 4) T_world_frame
    frame_index: np.ndarray | None  # (N,) int, KITTI files
    timestamps: np.ndarray | None  # (N,) seconds, TUM files


def planar_to_poses(xy_yaw: np.ndarray) -> np.ndarray:
    """``(N, 3)`` ``(x, y, yaw)`` (z up) to ``(N, 4, 4)`` poses with ``z = 0``."""
    xy_yaw = np.asarray(xy_yaw, float)
    c, s = np.cos(xy_yaw[:, 2]), np.sin(xy_yaw[:, 2])
    poses = np.tile(np.eye(4), (len(xy_yaw), 1, 1))
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -s, s, c
    poses[:, 0, 3], poses[:, 1, 3] = xy_yaw[:, 0], xy_yaw[:, 1]
    return poses


def to_planar(poses: np.ndarray) -> np.ndarray:
    """``(N, 4, 4)`` poses (z up) to ``(N, 3)`` ``(x, y, yaw)``."""
    return np.stack([poses[:, 0, 3], poses[:, 1, 3], np.arctan2(poses[:, 1, 0], poses[:, 0, 0])], -1)


def _as_poses(poses: np.ndarray, name: str = "poses") -> np.ndarray:
    poses = np.asarray(poses, float)
    if poses.ndim == 2 and poses.shape[1] == 3:
        poses = planar_to_poses(poses)
    if poses.ndim != 3 or poses.shape[1:] not in ((4, 4), (3, 4)):
        raise ValueError(f"{name} must have shape (N, 4, 4), (N, 3, 4) or planar (N, 3), got {poses.shape}")
    if not np.all(np.isfinite(poses)):
        raise ValueError(f"{name} contain NaN or inf")
    return poses


# ----------------------------------------------------------------------------- reading


def _parse_rows(path: str | Path) -> list[tuple[int, list[float]]]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"pose file not found: {path}")
    rows = []
    with open(path) as f:
        for number, line in enumerate(f, 1):
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            try:
                values = [float(v) for v in text.replace(",", " ").split()]
            except ValueError as err:
                raise ValueError(f"{path}:{number}: not a number ({err})") from None
            if not all(np.isfinite(values)):
                raise ValueError(f"{path}:{number}: NaN or inf in {text!r}")
            rows.append((number, values))
    if not rows:
        raise ValueError(f"{path}: no poses")
    return rows


def _kitti_rows(path: Path, rows) -> Trajectory:
    width = len(rows[0][1])
    poses, index = [], []
    for number, values in rows:
        if len(values) != width:
            raise ValueError(f"{path}:{number}: expected {width} numbers like line {rows[0][0]}, got {len(values)}")
        if width == 13:
            if values[0] != int(values[0]) or values[0] < 0:
                raise ValueError(f"{path}:{number}: frame index must be a non-negative integer, got {values[0]}")
            index.append(int(values[0]))
            values = values[1:]
        else:
            index.append(len(index))
        pose = np.eye(4)
        pose[:3, :] = np.reshape(values, (3, 4))
        poses.append(pose)
    index = np.asarray(index)
    if np.any(np.diff(index) <= 0):
        bad = int(np.argmax(np.diff(index) <= 0)) + 1
        raise ValueError(f"{path}:{rows[bad][0]}: frame indices must increase, got {index[bad - 1]} then {index[bad]}")
    return Trajectory(np.stack(poses), index, None)


def read_kitti(path: str | Path) -> Trajectory:
    """A KITTI pose file (12 numbers per line, or 13 with a leading frame index)."""
    rows = _parse_rows(path)
    if len(rows[0][1]) not in (12, 13):
        raise ValueError(f"{path}:{rows[0][0]}: a KITTI pose line has 12 or 13 numbers, got {len(rows[0][1])}")
    return _kitti_rows(Path(path), rows)


def read_tum(path: str | Path) -> Trajectory:
    """A TUM pose file (``timestamp tx ty tz qx qy qz qw``)."""
    path = Path(path)
    rows = _parse_rows(path)
    data = []
    for number, values in rows:
        if len(values) != 8:
            raise ValueError(f"{path}:{number}: a TUM pose line has 8 numbers, got {len(values)}")
        if np.linalg.norm(values[4:]) < 1e-12:
            raise ValueError(f"{path}:{number}: zero-length quaternion")
        data.append(values)
    data = np.asarray(data)
    if np.any(np.diff(data[:, 0]) <= 0):
        bad = int(np.argmax(np.diff(data[:, 0]) <= 0)) + 1
        raise ValueError(f"{path}:{rows[bad][0]}: timestamps must increase")
    poses = np.tile(np.eye(4), (len(data), 1, 1))
    poses[:, :3, :3] = quaternion_to_matrix(data[:, 4:])
    poses[:, :3, 3] = data[:, 1:4]
    return Trajectory(poses, None, data[:, 0])


def read_poses(path: str | Path) -> Trajectory:
    """KITTI (12/13 columns) or TUM (8 columns), told apart by the column count."""
    rows = _parse_rows(path)
    width = len(rows[0][1])
    if width in (12, 13):
        return _kitti_rows(Path(path), rows)
    if width == 8:
        return read_tum(path)
    raise ValueError(f"{path}:{rows[0][0]}: expected 12 or 13 (KITTI) or 8 (TUM) numbers, got {width}")


def match_frames(gt: Trajectory, est: Trajectory, tolerance_s: float = 1e-3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pair an estimate with its ground truth: by frame index (KITTI) or timestamp (TUM).

    Returns ``(gt (N, 4, 4), est (N, 4, 4), valid (N,))`` over the ground-truth frames, the estimate
    filled with the identity where it has no pose. An estimate frame missing from the ground truth
    is an error.
    """
    n = len(gt.poses)
    if gt.frame_index is not None and est.frame_index is not None:
        missing = est.frame_index[~np.isin(est.frame_index, gt.frame_index)]
        if missing.size:
            raise ValueError(f"the ground truth has no frame {missing[0]} of the estimate ({missing.size} such frames)")
        pos = np.searchsorted(gt.frame_index, est.frame_index)
    elif gt.timestamps is not None and est.timestamps is not None:
        pos = np.clip(np.searchsorted(gt.timestamps, est.timestamps), 1, n - 1)
        pos = np.where(
            np.abs(gt.timestamps[pos - 1] - est.timestamps) < np.abs(gt.timestamps[pos] - est.timestamps), pos - 1, pos
        )
        far = np.abs(gt.timestamps[pos] - est.timestamps) > tolerance_s
        if np.any(far):
            raise ValueError(f"estimate timestamp {est.timestamps[np.argmax(far)]} has no ground truth within {tolerance_s} s")
        if np.any(np.diff(pos) == 0):
            raise ValueError("two estimate poses match the same ground-truth timestamp")
    else:
        raise ValueError("cannot match a KITTI file (frame indices) with a TUM file (timestamps)")
    est_full = np.tile(np.eye(4), (n, 1, 1))
    est_full[pos] = est.poses
    valid = np.zeros(n, bool)
    valid[pos] = True
    return gt.poses, est_full, valid


# ----------------------------------------------------------------------------- writing


def write_kitti(path: str | Path, poses: np.ndarray, frame_index: np.ndarray | None = None) -> None:
    """KITTI pose file; with ``frame_index`` the 13-column form. ``poses`` may be planar ``(N, 3)``."""
    poses = _as_poses(poses)
    flat = poses[:, :3, :4].reshape(len(poses), 12)
    if frame_index is not None:
        frame_index = np.asarray(frame_index)
        if frame_index.shape != (len(poses),):
            raise ValueError(f"frame_index must have shape ({len(poses)},), got {frame_index.shape}")
        lines = [f"{int(i)} " + " ".join(f"{v:.9e}" for v in row) for i, row in zip(frame_index, flat)]
    else:
        lines = [" ".join(f"{v:.9e}" for v in row) for row in flat]
    write_text_atomic(path, "\n".join(lines) + "\n")


def write_tum(path: str | Path, timestamps: np.ndarray, poses: np.ndarray) -> None:
    """TUM pose file. ``poses`` may be planar ``(N, 3)``."""
    poses = _as_poses(poses)
    timestamps = np.asarray(timestamps, float)
    if timestamps.shape != (len(poses),):
        raise ValueError(f"timestamps must have shape ({len(poses)},), got {timestamps.shape}")
    q = matrix_to_quaternion(poses[:, :3, :3])
    t = poses[:, :3, 3]
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    lines += [" ".join(f"{v:.9f}" for v in (ts, *ti, *qi)) for ts, ti, qi in zip(timestamps, t, q)]
    write_text_atomic(path, "\n".join(lines) + "\n")


__all__ = [
    "Trajectory",
    "match_frames",
    "planar_to_poses",
    "read_kitti",
    "read_poses",
    "read_tum",
    "to_planar",
    "write_kitti",
    "write_tum",
]
