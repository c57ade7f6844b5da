"""IMU simulation from a trajectory: smooth interpolation, body angular rate and specific force,
white noise, bias random walk and a turn-on bias (numpy; runs once per dataset).

Frames: world z up, body x forward, y left, z up; ZYX Euler angles (yaw, pitch, roll) with a
positive pitch nose down. Specific force is what an accelerometer reads:
``f_body = R_wb^T (a_world + (0, 0, g))`` (at rest and level: ``(0, 0, +g)``).

KITTI poses are turned into body poses in a z-up world by
:func:`jbevo.data.kitti_frames.body_poses_from_kitti`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.interpolate import CubicSpline, make_smoothing_spline

from jbevo.geometry.euler import body_rates, euler_zyx, rotation_zyx
from jbevo.inertial.kinematics import GRAVITY

# Body -> camera for KITTI camera 0 looking ahead (camera x = -body y, y = -body z, z = body x).
_R_CAM_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class ImuNoise:
    """Continuous-time noise parameters (per sqrt(Hz)) and turn-on bias std."""

    gyro_noise_density: float  # rad / s / sqrt(Hz)
    gyro_random_walk: float  # rad / s^2 / sqrt(Hz)
    accel_noise_density: float  # m / s^2 / sqrt(Hz)
    accel_random_walk: float  # m / s^3 / sqrt(Hz)
    gyro_turn_on_bias: float = 0.0  # rad / s, std per axis, drawn once per sequence
    accel_turn_on_bias: float = 0.0  # m / s^2


# EuRoC's ADIS16448 (the dataset's published IMU calibration) plus a turn-on gyro bias of
# 0.2 deg/s per axis (1 sigma), the order of a MEMS gyro's uncalibrated start-up offset.
ADIS16448 = ImuNoise(1.6968e-4, 1.9393e-5, 2.0e-3, 3.0e-3, gyro_turn_on_bias=np.radians(0.2))
NOISELESS = ImuNoise(0.0, 0.0, 0.0, 0.0)
# KITTI's OXTS RT3003 as the real KITTI odometry IMU shows it (``imu_noise`` in
# benchmarks/results/attitude_real.json, written by benchmarks/attitude_real.py; the RMS over the
# three axes): white noise from the car's stops (engine vibration included), the gyro's bias random
# walk at the upper bound its Allan deviation against the truth allows, the turn-on biases as the
# spread of the per-drive estimates; the accelerometer's bias random walk is not observable
# against the truth's twice-differentiated positions and is ADIS16448's.
KITTI_OXTS = ImuNoise(4.3e-4, 4.2e-5, 8.6e-3, 3.0e-3, gyro_turn_on_bias=1.4e-4, accel_turn_on_bias=0.011)
#: The presets by name (the commands' ``--imu-noise``).
IMU_PRESETS = {"adis16448": ADIS16448, "kitti-oxts": KITTI_OXTS, "noiseless": NOISELESS}


class ImuData(NamedTuple):
    times: np.ndarray  # (M,) seconds
    gyro: np.ndarray  # (M, 3) rad/s, body frame
    accel: np.ndarray  # (M, 3) m/s^2 specific force, body frame
    gyro_bias: np.ndarray  # (M, 3) the bias the gyro carries (turn-on + random walk)
    euler: np.ndarray  # (M, 3) true (yaw, pitch, roll) at the samples
    position: np.ndarray  # (M, 3) true position
    velocity: np.ndarray  # (M, 3) true world velocity
    frame_euler: np.ndarray  # (N, 3) true (yaw, pitch, roll) at the frame times (of the smoothed motion)
    frame_position: np.ndarray  # (N, 3) true position at the frame times (of the smoothed motion)
    accel_bias: np.ndarray  # (M, 3) the bias the accelerometer carries (turn-on + random walk)


#: The fewest poses a smoothing spline is fitted through (scipy's ``make_smoothing_spline``).
SMOOTHING_MIN_POSES = 5


def simulate_imu(
    frame_times: np.ndarray,
    body_poses: np.ndarray,
    rate_hz: float = 100.0,
    noise: ImuNoise = ADIS16448,
    seed: int = 0,
    smoothing: float | None = 0.01,
) -> ImuData:
    """IMU samples at ``rate_hz`` over ``[frame_times[0], frame_times[-1])`` from body poses.

    Positions and unwrapped ZYX Euler angles are fitted with cubic smoothing splines (penalty
    ``smoothing``; ``None`` interpolates exactly). Differentiating recorded poses twice amplifies
    their centimetre noise: on KITTI 09 an interpolating spline gives 2.5 m/s^2 RMS horizontal
    acceleration, the 0.01 smoothing spline 1.2 m/s^2 while staying within 4 mm RMS of the
    poses. The simulated motion *is* the smoothed one: ``frame_euler`` is its attitude at the
    frames (the truth to score against), ``frame_position`` its position. Their derivatives give the world acceleration and the
    Euler rates, hence the body angular rate and specific force. Noise: white (density * sqrt(rate)), bias random walk
    (random_walk * sqrt(dt) per step) and a turn-on bias, all from ``seed``.
    """
    frame_times = np.asarray(frame_times, float)
    if body_poses.shape != (len(frame_times), 4, 4):
        raise ValueError(f"body_poses must have shape ({len(frame_times)}, 4, 4), got {body_poses.shape}")
    if np.any(np.diff(frame_times) <= 0):
        raise ValueError("frame_times must increase")
    if smoothing is not None and len(frame_times) < SMOOTHING_MIN_POSES:
        raise ValueError(
            f"the smoothing spline needs at least {SMOOTHING_MIN_POSES} poses, got {len(frame_times)} "
            "(a sequence of at least 4 frames, or smoothing=None)"
        )
    euler = euler_zyx(body_poses[:, :3, :3])
    euler[:, 0] = np.unwrap(euler[:, 0])
    pos = _spline(frame_times, body_poses[:, :3, 3], smoothing)
    ang = _spline(frame_times, euler, smoothing)
    dt = 1.0 / rate_hz
    n = int(np.floor((frame_times[-1] - frame_times[0]) / dt + 1e-9))
    t = frame_times[0] + dt * np.arange(n)
    e, e_dot = ang(t), ang(t, 1)
    acc_world = pos(t, 2) + np.array([0.0, 0.0, GRAVITY])
    r = rotation_zyx(e)
    accel = np.einsum("nji,nj->ni", r, acc_world)
    gyro = body_rates(e, e_dot)

    rng = np.random.default_rng(seed)
    gyro_bias = rng.normal(0, noise.gyro_turn_on_bias, 3) + np.cumsum(
        rng.normal(0, noise.gyro_random_walk * np.sqrt(dt), (n, 3)), axis=0
    )
    accel_bias = rng.normal(0, noise.accel_turn_on_bias, 3) + np.cumsum(
        rng.normal(0, noise.accel_random_walk * np.sqrt(dt), (n, 3)), axis=0
    )
    gyro = gyro + gyro_bias + rng.normal(0, noise.gyro_noise_density * np.sqrt(rate_hz), (n, 3))
    accel = accel + accel_bias + rng.normal(0, noise.accel_noise_density * np.sqrt(rate_hz), (n, 3))
    return ImuData(
        t, gyro, accel, gyro_bias, _wrap_yaw(e), pos(t), pos(t, 1), _wrap_yaw(ang(frame_times)), pos(frame_times), accel_bias
    )


def _wrap_yaw(euler: np.ndarray) -> np.ndarray:
    out = euler.copy()
    out[:, 0] = np.mod(out[:, 0] + np.pi, 2 * np.pi) - np.pi
    return out


def planar_body_velocity(data: ImuData) -> np.ndarray:
    """``(M, 2)`` velocity in the heading frame (forward, left), as planar odometry reports it:
    the world velocity turned by minus the yaw."""
    c, s = np.cos(data.euler[:, 0]), np.sin(data.euler[:, 0])
    v = data.velocity
    return np.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]], -1)


class _Spline:
    """Per-column splines evaluated together: ``spline(t, derivative)``."""

    def __init__(self, parts):
        self.parts = parts

    def __call__(self, t, nu: int = 0):
        return np.stack([p.derivative(nu)(t) if nu else p(t) for p in self.parts], -1)


def _spline(t: np.ndarray, values: np.ndarray, smoothing: float | None):
    if smoothing is None:
        return CubicSpline(t, values)
    return _Spline([make_smoothing_spline(t, values[:, i], lam=smoothing) for i in range(values.shape[1])])


__all__ = ["ADIS16448", "IMU_PRESETS", "KITTI_OXTS", "NOISELESS", "ImuData", "ImuNoise", "planar_body_velocity", "simulate_imu"]
