"""IMU calibration from drives with ground truth: the IMU's mounting, time offset, gyro scale and biases, and the
tilt of the ground truth's world against gravity (numpy, float64; runs once, before any filter).

What is estimated and how (``t`` recorded time, the clock of the frames and the IMU stamps):

* **Time offset.** An IMU sample stamped ``tau`` was taken at recorded time ``tau + time_offset_s``.
* **Mounting and gyro bias** from the gyro against the ground truth's rotation: the rotation
  between frames ``k`` and ``k + 1`` (a rotation vector in body frame ``k``) equals
  ``s R (G_k(offset) - dt_k b_g)`` with ``G_k`` the gyro's integral over the frame interval
  (trapezoid), ``R = rotation_body_imu``, ``s = gyro_scale`` (the gyro's scale factor; it also
  absorbs an error of the frame step where frame times are nominal) and ``b_g`` the gyro bias. For each
  offset, ``R`` comes from the Kabsch/Wahba SVD and ``(s, b_g)`` from linear least squares
  (alternated); the offset minimises the residual (a grid, then Brent's method). A car turns
  almost only about its z axis, so the gyro fixes the mounting's tilt well and its heading poorly.
* **Specific force, gravity and the accelerometer bias**: with ``Lambda_k`` the hat function over
  frames ``k - 1 .. k + 1`` (peak 1 at frame ``k``), the ground truth's positions give
  ``v_k+1/2 - v_k-1/2 = int a Lambda_k``, and the accelerometer gives
  ``R_wb,k R int (f - b_a) Lambda_k = int a Lambda_k + G int Lambda_k``, linear in the world's
  gravity vector ``G`` (its direction: the truth world's tilt) and the accelerometer bias ``b_a``
  (x and y; the z bias only scales the reading and is left at zero). Forward accelerations then
  fix the mounting's heading: ``R`` is re-solved from the gyro and accelerometer pairs together
  (each weighted by its residual variance) and alternated with the linear solves.
* **Uncertainty**: the delete-one-group jackknife over ``groups`` contiguous stretches of the
  frames (the offset searched again near the estimate each time): the standard deviation of each
  estimate, rotations as rotation vectors in degrees.

Apply a calibration with :func:`apply`: stamps ``tau + time_offset_s``, gyro
``s R (w - b_g)``, specific force ``R (f - b_a)`` (body frame). :func:`gravity_up` estimates, for one
drive, the direction of gravity in its ground truth's world (KITTI's world is camera 0 at frame
0, 1.3-3.2 deg off level), and :func:`level_poses` turns the ground truth into a gravity-level
world: the truth the filters' pitch and roll are scored against.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.spatial.transform import Rotation

from jbevo.data.imu_stream import ImuStream
from jbevo.inertial.kinematics import GRAVITY


class CalibrationDrive(NamedTuple):
    """One drive: frame times (recorded clock, s), ground-truth body poses ``T_world_body``
    (``(N, 4, 4)``; body x forward, y left, z up) and the IMU stream (IMU frame)."""

    frame_times: np.ndarray
    body_poses: np.ndarray
    imu: ImuStream


class CalibrationStd(NamedTuple):
    """Jackknife standard deviations of an :class:`ImuCalibration`'s estimates."""

    rotation_deg: np.ndarray  # (3,) rotation vector components
    time_offset_s: float
    gyro_scale: float
    gyro_bias: np.ndarray  # (3,) rad/s
    accel_bias: np.ndarray  # (3,) m/s^2


class ImuCalibration(NamedTuple):
    """An IMU's mounting (IMU -> body), time offset, gyro scale and biases (IMU frame)."""

    rotation_body_imu: np.ndarray  # (3, 3)
    time_offset_s: float
    gyro_scale: float
    gyro_bias: np.ndarray  # (3,) rad/s
    accel_bias: np.ndarray  # (3,) m/s^2 (z held at 0)
    std: CalibrationStd | None = None
    gyro_residual_deg: float = float("nan")  #: RMS per frame and axis of the rotation fit
    accel_residual: float = float("nan")  #: RMS per frame and axis of the specific-force fit (m/s^2)

    @property
    def rotation_deg(self) -> np.ndarray:
        """The mounting as a rotation vector (degrees)."""
        return np.degrees(Rotation.from_matrix(self.rotation_body_imu).as_rotvec())

    @classmethod
    def identity(cls) -> ImuCalibration:
        return cls(np.eye(3), 0.0, 1.0, np.zeros(3), np.zeros(3))

    def summary(self) -> dict:
        """JSON-ready values (degrees for the rotation, deg/s for the gyro bias)."""
        out = {
            "rotation_body_imu_deg": self.rotation_deg.tolist(),
            "time_offset_s": self.time_offset_s,
            "gyro_scale": self.gyro_scale,
            "gyro_bias_deg_s": np.degrees(self.gyro_bias).tolist(),
            "accel_bias_m_s2": self.accel_bias.tolist(),
            "gyro_residual_deg_per_frame": self.gyro_residual_deg,
            "accel_residual_m_s2": self.accel_residual,
        }
        if self.std is not None:
            out["std"] = {
                "rotation_body_imu_deg": self.std.rotation_deg.tolist(),
                "time_offset_s": self.std.time_offset_s,
                "gyro_scale": self.std.gyro_scale,
                "gyro_bias_deg_s": np.degrees(self.std.gyro_bias).tolist(),
                "accel_bias_m_s2": self.std.accel_bias.tolist(),
            }
        return out


def _cumulative(stream: ImuStream, values: np.ndarray) -> np.ndarray:
    """Trapezoidal integral of ``values`` over the stream's stamps, from its first sample."""
    steps = np.diff(stream.times)[:, None] * 0.5 * (values[1:] + values[:-1])
    return np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(steps, 0)])


def _at(stream: ImuStream, cumulative: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A cumulative integral over the stream's stamps at the times ``x`` (linear in between)."""
    return np.stack([np.interp(x, stream.times, cumulative[:, i]) for i in range(3)], -1)


class _Prepared(NamedTuple):
    """What of a drive does not depend on the time offset, computed once: the gyro's integral
    over the stamps, the specific force's integral integrated again, the truth's rotations."""

    drive: CalibrationDrive
    gyro_integral: np.ndarray  # (M, 3)
    force_integral_twice: np.ndarray  # (M, 3)
    rotation: np.ndarray  # (N - 1, 3) truth rotation vector over each frame interval


def _prepare(drive: CalibrationDrive) -> _Prepared:
    stream = drive.imu
    r = drive.body_poses[:, :3, :3]
    rotation = Rotation.from_matrix(np.einsum("nji,njk->nik", r[:-1], r[1:])).as_rotvec()
    force = _cumulative(stream, stream.accel)
    return _Prepared(drive, _cumulative(stream, stream.gyro), _cumulative(stream, force), rotation)


class _Pairs(NamedTuple):
    """What one set of frames contributes: gyro integrals and truth rotations per frame interval,
    specific-force and truth-velocity terms per interior frame."""

    gyro_integral: np.ndarray  # (K, 3) int w dtau (stamp clock), IMU frame
    interval: np.ndarray  # (K,) frame interval (recorded clock)
    rotation: np.ndarray  # (K, 3) truth rotation vector, body frame k
    force_integral: np.ndarray  # (J, 3) int f Lambda dtau, IMU frame
    hat_area: np.ndarray  # (J,) int Lambda dtau (recorded clock)
    velocity_change: np.ndarray  # (J, 3) world: v_k+1/2 - v_k-1/2
    attitude: np.ndarray  # (J, 3, 3) R_wb at the interior frames


def _pairs(prepared: _Prepared, offset: float, frames: np.ndarray | None = None) -> _Pairs:
    """Pairs of a drive for a time offset; ``frames`` (a boolean mask over frames) selects the
    intervals and interior frames kept (the jackknife)."""
    drive = prepared.drive
    t = np.asarray(drive.frame_times, float)
    stream = drive.imu
    lo, hi = stream.times[0] + offset, stream.times[-1] + offset
    inside = (t[:-1] >= lo) & (t[1:] <= hi)
    if frames is not None:
        inside &= frames[:-1] & frames[1:]
    g = _at(stream, prepared.gyro_integral, t[1:][inside] - offset) - _at(stream, prepared.gyro_integral, t[:-1][inside] - offset)
    k = np.arange(1, len(t) - 1)
    ok = (t[k - 1] >= lo) & (t[k + 1] <= hi)
    if frames is not None:
        ok &= frames[k - 1] & frames[k] & frames[k + 1]
    k = k[ok]
    before, after = t[k] - t[k - 1], t[k + 1] - t[k]
    # int f Lambda, Lambda rising from 0 at t_k-1 to 1 at t_k and falling to 0 at t_k+1, with FF
    # the twice-integrated force: by parts, int_a^m f (x - a) / (m - a) = F(m) - (FF(m) - FF(a)) / (m - a)
    # and int_m^b f (b - x) / (b - m) = (FF(b) - FF(m)) / (b - m) - F(m); their sum.
    cc_a, cc_m, cc_b = (_at(stream, prepared.force_integral_twice, x - offset) for x in (t[k - 1], t[k], t[k + 1]))
    force = (cc_b - cc_m) / after[:, None] - (cc_m - cc_a) / before[:, None]
    p = drive.body_poses[:, :3, 3]
    velocity_change = (p[k + 1] - p[k]) / after[:, None] - (p[k] - p[k - 1]) / before[:, None]
    return _Pairs(
        g,
        (t[1:] - t[:-1])[inside],
        prepared.rotation[inside],
        force,
        0.5 * (before + after),
        velocity_change,
        drive.body_poses[k, :3, :3],
    )


def _kabsch(body: np.ndarray, imu: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The rotation ``R`` minimising ``sum w |body - R imu|^2``."""
    h = (imu * weight[:, None]).T @ body
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


class _Fit(NamedTuple):
    rotation: np.ndarray
    scale: float
    gyro_bias: np.ndarray
    gravity: list  # per drive (3,)
    accel_bias: np.ndarray
    gyro_rms: float
    accel_rms: float


def _solve(pairs: list[_Pairs], iterations: int = 12, use_accel: bool = True) -> _Fit:
    """``R``, gyro scale, biases and per-drive gravity for fixed time offsets (alternating)."""
    g = np.concatenate([p.gyro_integral for p in pairs])
    dt = np.concatenate([p.interval for p in pairs])
    rot = np.concatenate([p.rotation for p in pairs])
    r, scale, bias = np.eye(3), 1.0, np.zeros(3)
    accel_bias = np.zeros(3)
    gravity = [np.array([0.0, 0.0, GRAVITY]) for _ in pairs]
    w_g, w_a = 1.0, 0.0
    gyro_rms = accel_rms = float("nan")
    for it in range(iterations):
        imu_vec = g - dt[:, None] * bias
        body_vecs, imu_vecs, weights = [rot], [imu_vec], [np.full(len(rot), w_g)]
        if use_accel and it > 0:
            for p, grav in zip(pairs, gravity):
                target = np.einsum("nji,nj->ni", p.attitude, p.velocity_change / p.hat_area[:, None] + grav)
                body_vecs.append(target)
                imu_vecs.append(p.force_integral / p.hat_area[:, None] - accel_bias)
                weights.append(np.full(len(target), w_a))
        r = _kabsch(np.concatenate(body_vecs), np.concatenate(imu_vecs), np.concatenate(weights))
        # (s, s b) from rot' = R^T rot = s g - dt (s b): linear least squares.
        local = rot @ r
        a = np.zeros((3 * len(g), 4))
        a[:, 0] = g.reshape(-1)
        for i in range(3):
            a[i::3, 1 + i] = -dt
        x, *_ = np.linalg.lstsq(a, local.reshape(-1), rcond=None)
        scale, bias = float(x[0]), x[1:] / x[0]
        gyro_res = local - (scale * (g - dt[:, None] * bias))
        gyro_rms = float(np.sqrt(np.mean(gyro_res**2)))
        if not use_accel:
            continue
        # Gravity per drive and the accelerometer bias (x, y): y_k = G_d + R_wb,k R b_a.
        rows, rhs = [], []
        for d, p in enumerate(pairs):
            m = np.einsum("nij,jk->nik", p.attitude, r)
            y = np.einsum("nij,nj->ni", m, p.force_integral / p.hat_area[:, None]) - p.velocity_change / p.hat_area[:, None]
            block = np.zeros((len(y), 3, 3 * len(pairs) + 2))
            block[:, :, 3 * d : 3 * d + 3] = np.eye(3)
            block[:, :, 3 * len(pairs) :] = m[:, :, :2]
            rows.append(block.reshape(-1, block.shape[-1]))
            rhs.append(y.reshape(-1))
        x, *_ = np.linalg.lstsq(np.concatenate(rows), np.concatenate(rhs), rcond=None)
        gravity = [x[3 * d : 3 * d + 3] for d in range(len(pairs))]
        accel_bias = np.array([x[-2], x[-1], 0.0])
        accel_res = np.concatenate(rhs) - np.concatenate(rows) @ x
        accel_rms = float(np.sqrt(np.mean(accel_res**2)))
        # Weights: inverse residual variances of the two kinds of pair (in their own units).
        w_g, w_a = 1.0 / max(gyro_rms, 1e-12) ** 2, 1.0 / max(accel_rms, 1e-12) ** 2
    return _Fit(r, scale, bias, gravity, accel_bias, gyro_rms, accel_rms)


def _gyro_residual(drives: list[_Prepared], offset, masks) -> float:
    pairs = [_pairs(d, offset, m) for d, m in zip(drives, masks)]
    return _solve(pairs, iterations=3, use_accel=False).gyro_rms


def _estimate(drives: list[_Prepared], masks, search: tuple[float, float], grid: float) -> tuple[float, _Fit]:
    lo, hi = search
    offsets = np.arange(lo, hi + grid / 2, grid)
    costs = [_gyro_residual(drives, o, masks) for o in offsets]
    best = int(np.argmin(costs))
    bracket = (offsets[max(best - 1, 0)], offsets[min(best + 1, len(offsets) - 1)])
    result = minimize_scalar(
        lambda o: _gyro_residual(drives, o, masks), bounds=bracket, method="bounded", options={"xatol": 1e-5}
    )
    offset = float(result.x)  # pyright: ignore[reportAttributeAccessIssue]
    return offset, _solve([_pairs(d, offset, m) for d, m in zip(drives, masks)])


def calibrate(
    drives: list[CalibrationDrive],
    max_offset_s: float = 0.3,
    groups: int = 8,
) -> ImuCalibration:
    """One :class:`ImuCalibration` for an IMU on several drives with ground truth (the method
    and its uncertainty: the module docstring). ``max_offset_s`` bounds the time-offset search;
    ``groups`` stretches for the jackknife (0: no uncertainty)."""
    if not drives:
        raise ValueError("calibrate needs at least one drive")
    for i, d in enumerate(drives):
        n = len(d.frame_times)
        if np.shape(d.body_poses) != (n, 4, 4) or n < 4:
            raise ValueError(f"drive {i}: body_poses must have shape ({n}, 4, 4) with at least 4 frames")
        if not np.all(np.isfinite(d.body_poses)):
            raise ValueError(f"drive {i}: the ground truth holds NaN (calibration needs it everywhere)")
        d.imu.check(f"drive {i} IMU")
    prepared = [_prepare(d) for d in drives]
    full = [None] * len(drives)
    offset, fit = _estimate(prepared, full, (-max_offset_s, max_offset_s), 0.01)
    std = None
    if groups >= 2:
        sizes = [len(d.frame_times) for d in drives]
        index = np.concatenate([np.arange(n) for n in sizes])
        owner = np.concatenate([np.full(n, i) for i, n in enumerate(sizes)])
        group = np.floor(np.arange(len(index)) * groups / len(index)).astype(int)
        reps = []
        for g in range(groups):
            masks = [group[owner == i] != g for i in range(len(drives))]
            o, f = _estimate(prepared, masks, (offset - 0.02, offset + 0.02), 0.005)
            rel = Rotation.from_matrix(f.rotation @ fit.rotation.T).as_rotvec()
            reps.append(np.concatenate([np.degrees(rel), [o, f.scale], f.gyro_bias, f.accel_bias]))
        reps = np.array(reps)
        jk = np.sqrt((groups - 1) / groups * np.sum((reps - reps.mean(0)) ** 2, 0))
        std = CalibrationStd(jk[:3], float(jk[3]), float(jk[4]), jk[5:8], jk[8:11])
    return ImuCalibration(
        fit.rotation,
        offset,
        fit.scale,
        fit.gyro_bias,
        fit.accel_bias,
        std,
        float(np.degrees(fit.gyro_rms)),
        fit.accel_rms,
    )


def apply(stream: ImuStream, calibration: ImuCalibration) -> ImuStream:
    """The stream in the body frame on the frames' clock: stamps ``tau + offset``, gyro
    ``s R (w - b_g)``, specific force ``R (f - b_a)``."""
    r = calibration.rotation_body_imu
    return ImuStream(
        stream.times + calibration.time_offset_s,
        calibration.gyro_scale * (stream.gyro - calibration.gyro_bias) @ r.T,
        (stream.accel - calibration.accel_bias) @ r.T,
    )


def gyro_residual_rates(drive: CalibrationDrive, calibration: ImuCalibration) -> tuple[np.ndarray, np.ndarray]:
    """``(mid-interval times (K,), residual rates (K, 3))``: the truth's rotation over each frame
    interval minus the calibrated gyro's, over the interval (rad/s, body frame): the gyro's noise
    and bias drift and the truth's own noise, for :func:`jbevo.inertial.noise_fit.allan_deviation`."""
    p = _pairs(_prepare(drive), calibration.time_offset_s)
    c = calibration
    predicted = c.gyro_scale * (p.gyro_integral - p.interval[:, None] * c.gyro_bias) @ c.rotation_body_imu.T
    t = np.asarray(drive.frame_times, float)
    mid = 0.5 * (t[:-1] + t[1:])
    inside = (t[:-1] >= drive.imu.times[0] + c.time_offset_s) & (t[1:] <= drive.imu.times[-1] + c.time_offset_s)
    return mid[inside], (p.rotation - predicted) / p.interval[:, None]


class Gravity(NamedTuple):
    """The direction of gravity in a drive's ground-truth world."""

    up: np.ndarray  # (3,) unit vector: where a level accelerometer at rest points
    magnitude: float  # m/s^2 (the accelerometer's scale included)
    tilt_deg: float  # angle between ``up`` and the world's z axis
    tilt_std_deg: float  # jackknife over ``groups`` stretches of the drive


def gravity_up(drive: CalibrationDrive, calibration: ImuCalibration, groups: int = 8) -> Gravity:
    """Gravity in ``drive``'s ground-truth world from the calibrated specific force against the
    truth's acceleration (the linear solve of :func:`calibrate` with the mounting and biases held
    fixed): the mean over the interior frames of ``R_wb R (f - b_a) - a``."""
    n = len(drive.frame_times)
    prepared = _prepare(drive)

    def estimate(mask):
        p = _pairs(prepared, calibration.time_offset_s, mask)
        m = np.einsum("nij,jk->nik", p.attitude, calibration.rotation_body_imu)
        force = p.force_integral / p.hat_area[:, None] - calibration.accel_bias
        y = np.einsum("nij,nj->ni", m, force) - p.velocity_change / p.hat_area[:, None]
        return y.mean(0)

    g = estimate(None)
    tilts = []
    for k in range(groups):
        mask = np.floor(np.arange(n) * groups / n).astype(int) != k
        v = estimate(mask)
        tilts.append(np.degrees(np.arccos(np.clip(v[2] / np.linalg.norm(v), -1, 1))))
    tilts = np.array(tilts)
    std = float(np.sqrt((groups - 1) / groups * np.sum((tilts - tilts.mean()) ** 2))) if groups >= 2 else float("nan")
    up = g / np.linalg.norm(g)
    return Gravity(up, float(np.linalg.norm(g)), float(np.degrees(np.arccos(np.clip(up[2], -1, 1)))), std)


def level_rotation(up: np.ndarray) -> np.ndarray:
    """The smallest rotation that turns ``up`` into ``(0, 0, 1)`` (it keeps the heading)."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    axis = np.cross(up, [0.0, 0.0, 1.0])
    s = np.linalg.norm(axis)
    if s < 1e-15:
        return np.eye(3)
    return Rotation.from_rotvec(axis / s * np.arctan2(s, up[2])).as_matrix()


def level_poses(poses: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Poses ``T_world_body`` re-expressed in the gravity-level world (:func:`level_rotation`)."""
    out = np.array(poses, float)
    lv = np.eye(4)
    lv[:3, :3] = level_rotation(up)
    return lv @ out


__all__ = [
    "CalibrationDrive",
    "CalibrationStd",
    "Gravity",
    "ImuCalibration",
    "apply",
    "calibrate",
    "gravity_up",
    "gyro_residual_rates",
    "level_poses",
    "level_rotation",
]
