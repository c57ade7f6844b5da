"""Vehicle trajectories for the simulator: procedural car-like drives and real KITTI car motion
laid onto the planar world (numpy; body poses ``T_world_body`` in a z-up world).

The body origin is the camera centre, so a pose's ``z`` is the camera height above the ground
(``z = 0``); ZYX Euler angles, positive pitch nose down, positive roll lowers the right side.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from jbevo.data.kitti_frames import CAMERA_HEIGHT, body_poses_from_kitti
from jbevo.data.synthetic.street import recorded_road_tilt
from jbevo.geometry.euler import euler_zyx, poses_from_euler


def _oscillation(rng, n, dt, frequency, damping, std):
    """A suspension mode: narrow-band motion around ``frequency`` (Hz), the sum of eight
    sinusoids with random phases and frequencies spread by the mode's ``damping`` (a lightly
    damped mode's resonance width), scaled to ``std``. Smooth, so its derivatives (the IMU's
    rates and accelerations) stay physical."""
    t = np.arange(n) * dt
    freqs = frequency * (1.0 + damping * rng.standard_normal(8))
    phases = rng.uniform(0, 2 * np.pi, 8)
    out = np.sin(2 * np.pi * freqs[:, None] * t[None, :] + phases[:, None]).sum(0)
    return out * (std / (out.std() + 1e-12))


def speed_targets(
    rng: np.random.Generator, n: int, dt: float, speed_range: tuple[float, float], stop_probability: float
) -> np.ndarray:
    """Piecewise-constant speed targets for ``n`` samples ``dt`` apart: holds of 4-12 s at a
    speed drawn from ``speed_range``, or (with ``stop_probability``, never first) stops of
    2-5 s at zero; the first second is at rest. Every sample is written: a stop longer than the
    hold drawn before it lasts its own length."""
    target = np.full(n, np.nan)
    i = 0
    while i < n:
        hold = int(rng.uniform(4.0, 12.0) / dt)
        stop = rng.random() < stop_probability and i > 0
        length = int(rng.uniform(2.0, 5.0) / dt) if stop else hold
        target[i : i + length] = 0.0 if stop else rng.uniform(*speed_range)
        i += length
    target[: int(1.0 / dt)] = 0.0  # start at rest, as a filter is initialised
    return target


def procedural_drive(
    seed: int,
    n_frames: int,
    frame_rate: float = 10.0,
    speed_range: tuple[float, float] = (4.0, 14.0),
    stop_probability: float = 0.15,
    max_lateral_accel: float = 3.0,
    suspension_std_deg: float = 0.7,
    height: float = CAMERA_HEIGHT,
) -> tuple[np.ndarray, np.ndarray]:
    """A car-like drive: ``(frame_times, body_poses)`` with ``n_frames`` frames.

    The car starts at rest (1 s) and accelerates. Speed follows piecewise-constant targets in ``speed_range`` (held 4-12 s; with
    ``stop_probability`` a stop of 2-5 s) under +-2 m/s^2 of acceleration; curvature is a smooth
    random process limited to ``max_lateral_accel`` and a 7 m turning radius. Pitch and roll are
    the suspension's quasi-static response to the longitudinal and lateral acceleration
    (0.2 and 0.4 deg per m/s^2: the nose dips when braking, the body leans out of a turn) plus
    1.2 and 1.8 Hz oscillations of ``suspension_std_deg``; the height bounces by about 1 cm.
    Integrated at 100 Hz, sampled at the frames.
    """
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames}")
    rng = np.random.default_rng(seed)
    dt = 0.01
    duration = (n_frames - 1) / frame_rate
    n = int(round(duration / dt)) + 1
    target = speed_targets(rng, n, dt, speed_range, stop_probability)
    speed = np.empty(n)
    speed[0] = 0.0
    for k in range(1, n):
        speed[k] = speed[k - 1] + np.clip(target[k] - speed[k - 1], -2.0 * dt, 2.0 * dt)
    speed = gaussian_filter1d(speed, 0.5 / dt, mode="nearest")  # smooth the jerk
    curvature = gaussian_filter1d(rng.standard_normal(n), 2.0 / dt, mode="wrap") * 0.6
    curvature = np.clip(curvature, -1 / 7.0, 1 / 7.0)
    curvature = np.clip(
        curvature, -max_lateral_accel / np.maximum(speed, 1.0) ** 2, max_lateral_accel / np.maximum(speed, 1.0) ** 2
    )
    yaw = np.cumsum(speed * curvature) * dt
    yaw -= yaw[0]
    x = np.cumsum(speed * np.cos(yaw)) * dt
    y = np.cumsum(speed * np.sin(yaw)) * dt
    a_long = np.gradient(speed, dt)
    a_lat = speed**2 * curvature
    pitch = np.radians(-0.2 * a_long + _oscillation(rng, n, dt, 1.2, 0.3, suspension_std_deg))
    roll = np.radians(0.4 * a_lat + _oscillation(rng, n, dt, 1.8, 0.3, suspension_std_deg))
    z = height + _oscillation(rng, n, dt, 1.5, 0.3, 0.01)
    step = int(round(1.0 / (frame_rate * dt)))
    idx = np.arange(n_frames) * step
    euler = np.stack([yaw, pitch, roll], -1)[idx]
    euler[:, 0] = np.mod(euler[:, 0] + np.pi, 2 * np.pi) - np.pi
    position = np.stack([x - x[0], y - y[0], z], -1)[idx]
    return idx * dt, poses_from_euler(euler, position)


def kitti_drive(
    kitti_poses: np.ndarray,
    frame_rate: float = 10.0,
    grade_window_s: float = 2.0,
    height_window_s: float = 0.5,
    height: float = CAMERA_HEIGHT,
) -> tuple[np.ndarray, np.ndarray]:
    """Real car motion from KITTI ground truth (``T_world_cam0``, ``(N, 4, 4)``) on the planar
    world: ``(frame_times, body_poses)``.

    x, y and yaw are the real ones. The road's slow grade and banking are removed: pitch and roll
    minus their Gaussian low-pass (sigma ``grade_window_s``) leave the car's motion relative to
    the local road (suspension, bumps), added to a level pose. The height keeps only what is left
    after a 0.5 s low-pass (``height_window_s``), around ``height``: KITTI's ground-truth height
    wanders by 3-7 cm RMS within any second or two (the GPS/INS's vertical error, not the
    suspension), which would bounce the BEV's scale by several per cent; the 0.5 s residual is
    1.3-2.6 cm RMS on 00, 08, 09 (0.3-0.9 cm per frame), the size of real bumps. Frames are taken
    as evenly spaced at ``frame_rate`` (KITTI's camera runs at ~10 Hz).
    """
    kitti_poses = np.asarray(kitti_poses, float)
    if kitti_poses.ndim != 3 or kitti_poses.shape[1:] != (4, 4) or len(kitti_poses) < 2:
        raise ValueError(f"kitti_poses must have shape (N >= 2, 4, 4), got {kitti_poses.shape}")
    body = body_poses_from_kitti(kitti_poses)
    euler = euler_zyx(body[:, :3, :3])
    euler[:, 1:] -= recorded_road_tilt(body, frame_rate, grade_window_s)
    z = body[:, 2, 3] - gaussian_filter1d(body[:, 2, 3], height_window_s * frame_rate, mode="nearest") + height
    position = np.stack([body[:, 0, 3], body[:, 1, 3], z], -1)
    return np.arange(len(body)) / frame_rate, poses_from_euler(euler, position)


__all__ = ["kitti_drive", "procedural_drive", "speed_targets"]
