"""KITTI's frames: camera 0 poses ``T_world_cam0`` (camera x right, y down, z forward; world =
camera 0 at frame 0) and jbevo's body poses in a z-up world (x forward, y left, z up), taking
KITTI's world as gravity-aligned (its y axis pointing down along gravity). Numpy."""

from __future__ import annotations

import numpy as np

#: Height of KITTI camera 0 above the road (metres).
CAMERA_HEIGHT = 1.65


# Body -> camera for KITTI camera 0 looking ahead (camera x = -body y, y = -body z, z = body x).
_R_CAM_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


# KITTI world (camera 0 at frame 0: x right, y down, z forward) -> z-up world (x forward, y left).
_R_ZUP_KITTI = _R_CAM_BODY.T


def body_poses_from_kitti(poses: np.ndarray) -> np.ndarray:
    """KITTI ``T_world_cam0`` (N, 4, 4) to body poses ``T_world_body`` in a z-up world."""
    out = np.tile(np.eye(4), (len(poses), 1, 1))
    out[:, :3, :3] = _R_ZUP_KITTI @ poses[:, :3, :3] @ _R_CAM_BODY
    out[:, :3, 3] = poses[:, :3, 3] @ _R_ZUP_KITTI.T
    return out


def body_from_camera_rotation(r_cam_x: np.ndarray) -> np.ndarray:
    """A rotation into camera 0's axes (``R_cam_x``) re-expressed into the body's: ``R_body_x``."""
    return _R_CAM_BODY.T @ np.asarray(r_cam_x, float)


def camera_poses_from_body(poses: np.ndarray) -> np.ndarray:
    """Inverse of :func:`body_poses_from_kitti`, relative to the first pose (KITTI's world is
    camera 0 at frame 0)."""
    first = np.linalg.inv(poses[0])
    rel = first @ poses
    out = rel.copy()
    out[:, :3, :3] = _R_ZUP_KITTI.T @ rel[:, :3, :3] @ _R_ZUP_KITTI
    out[:, :3, 3] = rel[:, :3, 3] @ _R_ZUP_KITTI
    return out


__all__ = ["CAMERA_HEIGHT", "body_from_camera_rotation", "body_poses_from_kitti", "camera_poses_from_body"]
