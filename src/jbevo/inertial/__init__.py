"""Inertial: IMU kinematics for pitch and roll, the pitch/roll DUKF (gyro integration as motion,
accelerometer tilt as measurement; learnable noise) and the speed-aided filter BEVO runs."""

from jbevo.inertial.attitude_filter import AttitudeFilter
from jbevo.inertial.kinematics import (
    GRAVITY,
    accel_tilt,
    body_acceleration,
    euler_rates,
    forward_acceleration,
    gyro_yaw_increment,
    tilt_measurements,
)
from jbevo.inertial.speed_aided import AttitudeState, SpeedAidedAttitude

__all__ = [
    "GRAVITY",
    "AttitudeFilter",
    "AttitudeState",
    "SpeedAidedAttitude",
    "accel_tilt",
    "body_acceleration",
    "euler_rates",
    "forward_acceleration",
    "gyro_yaw_increment",
    "tilt_measurements",
]
