"""ZYX Euler angles ``(yaw, pitch, roll)`` (numpy): ``R_wb = Rz(yaw) Ry(pitch) Rx(roll)``, world z
up, body x forward, y left, z up; a positive pitch turns the nose down, a positive roll lowers
the right side."""

from __future__ import annotations

import numpy as np


def euler_zyx(r: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotations ``R_wb`` to ``(yaw, pitch, roll)``."""
    yaw = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    pitch = -np.arcsin(np.clip(r[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    return np.stack([yaw, pitch, roll], -1)


def rotation_zyx(euler: np.ndarray) -> np.ndarray:
    """``(..., 3)`` ``(yaw, pitch, roll)`` to ``R_wb = Rz(yaw) Ry(pitch) Rx(roll)``."""
    y, p, r = np.moveaxis(np.asarray(euler, float), -1, 0)
    cy, sy, cp, sp, cr, sr = np.cos(y), np.sin(y), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
    return np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
            np.stack([-sp, cp * sr, cp * cr], -1),
        ],
        -2,
    )


def body_rates(euler: np.ndarray, euler_dot: np.ndarray) -> np.ndarray:
    """Body angular rate from ZYX Euler angles and their time derivatives."""
    _, p, r = np.moveaxis(euler, -1, 0)
    yd, pd, rd = np.moveaxis(euler_dot, -1, 0)
    return np.stack(
        [
            rd - np.sin(p) * yd,
            np.cos(r) * pd + np.sin(r) * np.cos(p) * yd,
            -np.sin(r) * pd + np.cos(r) * np.cos(p) * yd,
        ],
        -1,
    )


def poses_from_euler(euler: np.ndarray, position: np.ndarray) -> np.ndarray:
    """``(N, 4, 4)`` poses from ``(yaw, pitch, roll)`` and positions."""
    out = np.tile(np.eye(4), (len(euler), 1, 1))
    out[:, :3, :3] = rotation_zyx(euler)
    out[:, :3, 3] = position
    return out


__all__ = ["body_rates", "euler_zyx", "poses_from_euler", "rotation_zyx"]
