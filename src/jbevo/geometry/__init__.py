"""Geometry: angles, a vectorisable float64 ``sincos``, SE(2) and SE(3) poses, ZYX Euler angles,
quaternions, the pinhole camera on a vehicle and the BEV raster.

Frames: world z up; body x forward, y left, z up; camera x right, y down, z forward (KITTI
camera 0). Units: metres, seconds, radians; angles wrapped to [-pi, pi).
"""

from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import Camera, level_to_body, project_ground_points
from jbevo.geometry.euler import euler_zyx, poses_from_euler, rotation_zyx
from jbevo.geometry.se2 import se2_between, se2_compose
from jbevo.geometry.se3 import planar_to_se3, se3_to_planar
from jbevo.geometry.sincos import sincos
from jbevo.geometry.so3 import matrix_to_quaternion, quaternion_to_matrix

__all__ = [
    "BevGrid",
    "Camera",
    "euler_zyx",
    "level_to_body",
    "matrix_to_quaternion",
    "planar_to_se3",
    "poses_from_euler",
    "project_ground_points",
    "quaternion_to_matrix",
    "rotation_zyx",
    "se2_between",
    "se2_compose",
    "se3_to_planar",
    "sincos",
    "wrap_angle",
]
