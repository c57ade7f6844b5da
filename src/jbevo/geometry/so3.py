"""Rotation matrices and unit quaternions ``(qx, qy, qz, qw)`` (Hamilton, scalar last; numpy)."""

from __future__ import annotations

import numpy as np


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """``(..., 4)`` quaternions ``(qx, qy, qz, qw)`` (normalised here) to ``(..., 3, 3)``."""
    q = np.asarray(q, float)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ValueError("zero-length quaternion")
    x, y, z, w = np.moveaxis(q / norm, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def matrix_to_quaternion(r: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotations to ``(..., 4)`` quaternions ``(qx, qy, qz, qw)`` with ``qw >= 0``.

    Uses the largest of the four squared components for stability (Shepperd's method).
    """
    r = np.asarray(r, float)
    tr = np.trace(r, axis1=-2, axis2=-1)
    # m[i, j] = 4 q_i q_j for (x, y, z, w); the diagonal holds the four squares.
    m = np.empty(r.shape[:-2] + (4, 4))
    m[..., 0, 0] = 1 + 2 * r[..., 0, 0] - tr
    m[..., 1, 1] = 1 + 2 * r[..., 1, 1] - tr
    m[..., 2, 2] = 1 + 2 * r[..., 2, 2] - tr
    m[..., 3, 3] = 1 + tr
    for (i, j), v in {
        (0, 1): r[..., 0, 1] + r[..., 1, 0],
        (0, 2): r[..., 0, 2] + r[..., 2, 0],
        (1, 2): r[..., 1, 2] + r[..., 2, 1],
        (0, 3): r[..., 2, 1] - r[..., 1, 2],
        (1, 3): r[..., 0, 2] - r[..., 2, 0],
        (2, 3): r[..., 1, 0] - r[..., 0, 1],
    }.items():
        m[..., i, j] = m[..., j, i] = v
    k = np.argmax(np.diagonal(m, axis1=-2, axis2=-1), axis=-1)
    row = np.take_along_axis(m, k[..., None, None], axis=-2)[..., 0, :]  # 4 q_k q
    q = row / (2.0 * np.sqrt(np.take_along_axis(row, k[..., None], -1)))  # divide by 2 |q_k|
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0, -q, q)


__all__ = ["matrix_to_quaternion", "quaternion_to_matrix"]
