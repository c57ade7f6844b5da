"""Synthetic sequences: a trajectory, the world rendered by the camera along it under an imaging
condition, and the IMU simulated from the same motion (``python -m jbevo.render`` writes one to
disk).

The built-in dataset of :func:`builtin_dataset` (what ``python -m jbevo.train`` uses with no
arguments) is small procedural drives with a 128x416 camera (a KITTI camera 0 scaled by 1/3).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jbevo.data.sequence import Sequence, check
from jbevo.data.synthetic.conditions import CONDITIONS, Condition, draw_obstacles, expose, place_obstacles
from jbevo.data.synthetic.imu import ADIS16448, ImuNoise, simulate_imu
from jbevo.data.synthetic.render import render
from jbevo.data.synthetic.street import (
    Street,
    exposure_gains,
    mounted_camera,
    recorded_road_tilt,
    road_relative,
    street_tilt,
    tilt_onto_road,
    vignette,
)
from jbevo.data.synthetic.structures import Boxes, nearest_boxes, place_structures
from jbevo.data.synthetic.trajectories import kitti_drive, procedural_drive
from jbevo.data.synthetic.world import World
from jbevo.geometry.camera import Camera
from jbevo.geometry.euler import rotation_zyx
from jbevo.inertial.kitti_imu import CalibratedImuDrive


def small_camera(scale: float = 1 / 3, height: float = 1.65) -> Camera:
    """KITTI camera 0 scaled by ``scale``, its size rounded up to multiples of 8 about the same
    principal point (1/3: 128 x 416 pixels, the same field of view)."""
    k = Camera.kitti()
    full_h, full_w = k.image_shape
    h, w = int(np.ceil(full_h * scale / 8) * 8), int(np.ceil(full_w * scale / 8) * 8)
    fx, fy, cx, cy = (float(k.intrinsics[i, j]) * scale for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)))
    return Camera(fx, fy, cx + (w - full_w * scale) / 2, cy + (h - full_h * scale) / 2, (h, w), height)


@functools.partial(jax.jit, static_argnames=("condition", "ground_contrast"))
def _frames(
    world, camera, poses, times, obstacles, keys, condition: Condition, boxes=None, gains=None, falloff=None, ground_contrast=1.0
):
    def one(args):
        pose, time, key, frame_boxes, gain = args
        image = render(world, camera, pose, condition.haze_distance, condition.sheen, frame_boxes, ground_contrast)
        if obstacles is not None:
            image = draw_obstacles(image, camera, pose, obstacles, time)
        if gain is not None:
            image = image * gain * falloff
        return expose(image, condition, key)

    return jax.lax.map(one, (poses, times, keys, boxes, gains), batch_size=2)


def _half_fov(camera: Camera, margin: float = np.radians(5.0)) -> float:
    """Half the camera's horizontal field of view (the wider side), plus ``margin``."""
    k = np.asarray(camera.intrinsics, float)
    width = camera.image_shape[1]
    return float(max(np.arctan(k[0, 2] / k[0, 0]), np.arctan((width - 1 - k[0, 2]) / k[0, 0])) + margin)


def _condition(condition: Condition | str) -> Condition:
    if isinstance(condition, str):
        if condition not in CONDITIONS:
            raise ValueError(f"unknown condition {condition!r}; known: {sorted(CONDITIONS)}")
        return CONDITIONS[condition]
    return condition


def make_sequence(
    world: World,
    camera: Camera,
    frame_times: np.ndarray,
    body_poses: np.ndarray,
    condition: Condition | str = "day",
    imu_noise: ImuNoise = ADIS16448,
    seed: int = 0,
    imu_rate: float = 100.0,
    smoothing: float | None = None,
    street: Street | None = None,
    road_tilt: np.ndarray | None = None,
    structures: Boxes | None = None,
) -> Sequence:
    """Render and simulate a drive given at evenly spaced ``frame_times`` (``T + 1`` poses,
    ``T_world_body``). The first frame only starts the IMU (block 0 of the result holds the
    samples between it and the second); the result has ``T`` frames. ``smoothing`` is the IMU
    simulator's spline penalty (``None`` for smooth procedural motion, 0.01 for recorded poses);
    the ground truth and the images follow the (smoothed) simulated motion.

    With a ``street`` (:mod:`jbevo.data.synthetic.street`) the poses are taken on a level road and
    carried onto a sloped one (``road_tilt``, ``(T + 1, 2)`` grade and banking, or the street's
    random profile): the IMU and the truth have the whole attitude, the images the attitude
    against the road, seen by the street's mounted camera among its structures (``structures``,
    or placed along the drive).
    """
    frame_times = np.asarray(frame_times, float)
    body_poses = np.asarray(body_poses, float)
    condition = _condition(condition)
    if len(frame_times) < 2 or body_poses.shape != (len(frame_times), 4, 4):
        raise ValueError(f"need >= 2 frame times and poses of shape (N, 4, 4); got {frame_times.shape}, {body_poses.shape}")
    interval = np.diff(frame_times)
    samples = interval[0] * imu_rate
    if not np.allclose(interval, interval[0], rtol=1e-6) or abs(samples - round(samples)) > 1e-6:
        raise ValueError("frame_times must be evenly spaced by a whole number of IMU samples")
    s = int(round(samples))
    render_poses = None
    tilt, climb = np.zeros((len(frame_times), 2)), np.zeros(len(frame_times))
    if street is not None:
        tilt = street_tilt(street, road_tilt, body_poses, seed)
        if tilt.shape != (len(frame_times), 2):
            raise ValueError(f"road_tilt must have shape ({len(frame_times)}, 2), got {tilt.shape}")
        level = body_poses
        body_poses = tilt_onto_road(level, tilt)
        climb = body_poses[:, 2, 3] - level[:, 2, 3]
    imu = simulate_imu(frame_times, body_poses, imu_rate, imu_noise, seed, smoothing)
    t = len(frame_times) - 1
    poses = np.tile(np.eye(4), (t, 1, 1))
    poses[:, :3, :3] = rotation_zyx(imu.frame_euler[1:])
    poses[:, :3, 3] = imu.frame_position[1:]
    if street is not None:
        render_poses = road_relative(poses, tilt[1:], poses[:, 2, 3] - climb[1:])
    block = (t, s)
    return render_sequence(
        world,
        camera,
        frame_times,
        poses,
        imu.times.reshape(block),
        imu.gyro.reshape(*block, 3),
        imu.accel.reshape(*block, 3),
        condition,
        seed,
        street,
        render_poses,
        structures,
    )


def render_sequence(
    world: World,
    camera: Camera,
    frame_times: np.ndarray,
    poses: np.ndarray,
    imu_times: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    condition: Condition | str = "day",
    seed: int = 0,
    street: Street | None = None,
    render_poses: np.ndarray | None = None,
    structures: Boxes | None = None,
) -> Sequence:
    """A Sequence whose images are rendered at ``poses`` (``T``, the frames of ``frame_times[1:]``;
    ``frame_times[0]`` is the time the IMU starts) with the given IMU blocks ``(T, S)``; the
    images at ``render_poses`` where given (the camera against the road, where the truth
    ``poses`` are against gravity). A ``street`` renders with its mounted camera, ``height_error``
    higher, among its structures (``structures``, or placed along the drive from ``seed``), with
    its exposure and vignetting; the sequence keeps ``camera``."""
    condition = _condition(condition)
    t = len(poses)
    view = np.array(poses if render_poses is None else render_poses, float)
    if view.shape != (t, 4, 4):
        raise ValueError(f"render_poses must have shape {(t, 4, 4)}, got {view.shape}")
    obstacles = place_obstacles(view, condition.obstacles, seed) if condition.obstacles else None
    keys = jax.random.split(jax.random.PRNGKey(seed), t)
    times = jnp.asarray(frame_times[1:] - frame_times[0], jnp.float32)
    look, boxes, gains, falloff = camera, None, None, None
    if street is not None:
        look = mounted_camera(camera, street)
        view[:, 2, 3] += street.height_error
        placed = place_structures(view, street, seed) if structures is None else structures
        boxes = jax.tree_util.tree_map(jnp.asarray, nearest_boxes(placed, view, _half_fov(camera)))
        gains = jnp.asarray(exposure_gains(t, street, seed, frame_rate(frame_times)))
        falloff = vignette(camera, street.vignetting)
    contrast = 1.0 if street is None else street.ground_contrast
    images = _frames(
        world, look, jnp.asarray(view, jnp.float32), times, obstacles, keys, condition, boxes, gains, falloff, contrast
    )
    seq = Sequence(
        images=images,
        frame_times=jnp.asarray(frame_times[1:], jnp.float32),
        imu_times=jnp.asarray(imu_times, jnp.float32),
        gyro=jnp.asarray(gyro, jnp.float32),
        accel=jnp.asarray(accel, jnp.float32),
        camera=camera,
        poses=jnp.asarray(poses, jnp.float32),
    )
    return check(seq)


def procedural_sequence(
    seed: int,
    frames: int,
    town: str = "town01",
    camera: Camera | None = None,
    condition: Condition | str = "day",
    imu_noise: ImuNoise = ADIS16448,
    world: World | None = None,
    street: Street | None = None,
) -> Sequence:
    """A procedural drive of ``frames`` frames (10 Hz) in ``town`` (on a ``street``: slopes,
    structures, mounting and exposure of :mod:`jbevo.data.synthetic.street`)."""
    world = World.create(town) if world is None else world
    camera = small_camera() if camera is None else camera
    times, poses = procedural_drive(seed, frames + 1)
    return make_sequence(world, camera, times, poses, condition, imu_noise, seed, street=street)


def kitti_sequence(
    kitti_poses: np.ndarray,
    start: int = 0,
    frames: int | None = None,
    town: str = "town01",
    camera: Camera | None = None,
    condition: Condition | str = "day",
    imu_noise: ImuNoise = ADIS16448,
    seed: int = 0,
    world: World | None = None,
    real_imu: CalibratedImuDrive | None = None,
    street: Street | None = None,
) -> Sequence:
    """The synthetic world driven by real KITTI motion (``T_world_cam0`` poses, e.g. read with
    :func:`jbevo.data.pose_files.read_kitti`): frames ``[start, start + frames)`` (all by default).

    With ``real_imu`` (the same sequence's real IMU, calibrated and levelled:
    :func:`jbevo.inertial.kitti_imu.calibrated_drive`) the IMU is the real one and the frames are
    rendered at the attitude it sees: the levelled ground truth's pitch and roll (the road's grade
    and banking included) and heading, the x, y of the truth and :func:`kitti_drive`'s height, on
    the real frame times; without it the IMU is simulated (``imu_noise``) from the level-road
    motion of :func:`kitti_drive`.

    On a ``street`` the road's grade and banking are the street's random profiles (a pose file's
    pitch and roll are against its first camera pose, not gravity: their low-pass swings by
    several degrees with the heading and is not the road's grade); with ``real_imu`` they are the
    levelled truth's own (its low-pass). The truth and the IMU keep them, the images are rendered
    against the road (see :func:`make_sequence`)."""
    world = World.create(town) if world is None else world
    camera = Camera.kitti() if camera is None else camera
    times, poses = kitti_drive(kitti_poses)
    stop = len(poses) if frames is None else start + frames + 1
    if start < 0 or stop > len(poses) or stop - start < 2:
        raise ValueError(f"frames [{start}, {stop - 1}) do not fit a trajectory of {len(poses)} poses (one extra starts the IMU)")
    if real_imu is None:
        return make_sequence(
            world, camera, times[start:stop], poses[start:stop], condition, imu_noise, seed, smoothing=0.01, street=street
        )
    if len(real_imu.frame_times) != len(poses):
        raise ValueError(f"the real IMU drive has {len(real_imu.frame_times)} frames, the poses {len(poses)}")
    rendered = np.array(real_imu.body_poses)
    rendered[:, 2, 3] = poses[:, 2, 3]
    frames_kept = slice(start + 1, stop)
    against_road = None
    if street is not None:
        recorded = recorded_road_tilt(real_imu.body_poses, frame_rate(real_imu.frame_times))
        tilt = street_tilt(street, recorded, rendered, seed)
        against_road = road_relative(rendered, tilt, poses[:, 2, 3])[frames_kept]
    return render_sequence(
        world,
        camera,
        real_imu.frame_times[start:stop],
        rendered[frames_kept],
        real_imu.imu_times[frames_kept],
        real_imu.gyro[frames_kept],
        real_imu.accel[frames_kept],
        condition,
        seed,
        street,
        against_road,
    )


def frame_rate(frame_times: np.ndarray, default: float = 10.0) -> float:
    """Frames per second of ``frame_times`` (the median step's inverse; ``default`` for fewer than
    two frames)."""
    times = np.asarray(frame_times, float)
    if len(times) < 2:
        return default
    step = float(np.median(np.diff(times)))
    if not step > 0:
        raise ValueError(f"frame times must increase, got a median step of {step} s")
    return 1.0 / step


def synthetic_copy(
    seq: Sequence, world: World, street: Street | None = None, condition: Condition | str = "day", seed: int = 0
) -> Sequence:
    """``seq`` (e.g. a real drive) with its images replaced by the synthetic world's: the same
    frame times, IMU, camera and truth (``seq.poses``, against gravity; NaN poses are refused).
    In the flat world (``street=None``) the camera is rendered at the truth's attitude over a
    level plane at the camera's nominal height; on a ``street`` at the attitude against the road
    (the truth's pitch and roll less the road's grade and banking: their 2 s low-pass less its
    mean over the drive, the mean being taken as the camera's own mounting), with the street's
    structures, mounting and exposure."""
    truth = np.asarray(seq.poses, float)
    if not np.all(np.isfinite(truth)):
        raise ValueError("synthetic_copy needs a sequence whose every pose is known (seq.poses has NaN)")
    times = np.asarray(seq.frame_times, float)
    rate = frame_rate(times)
    height = float(seq.camera.height)
    recorded = recorded_road_tilt(truth, rate)
    recorded = recorded - recorded.mean(0)  # the run's mean attitude is the camera's own (its mounting)
    tilt = np.zeros((len(truth), 2)) if street is None else street_tilt(street, recorded, truth, seed)
    view = road_relative(truth, tilt, height)
    return render_sequence(
        world,
        seq.camera,
        np.r_[times[0] - 1.0 / rate, times],
        truth,
        np.asarray(seq.imu_times),
        np.asarray(seq.gyro),
        np.asarray(seq.accel),
        condition,
        seed,
        street,
        view,
    )


def builtin_dataset(
    frames: int = 120, sequences: int = 6, town: str = "town01", seed: int = 0, street: Street | None = None
) -> list[Sequence]:
    """The embedded default dataset: ``sequences`` procedural drives of ``frames`` frames, small
    camera, ADIS16448 IMU, day; seeds ``seed, seed + 1, ...`` (on a ``street`` where given)."""
    world = World.create(town)
    return [procedural_sequence(seed + i, frames, town, world=world, street=street) for i in range(sequences)]


__all__ = [
    "builtin_dataset",
    "frame_rate",
    "kitti_sequence",
    "make_sequence",
    "procedural_sequence",
    "render_sequence",
    "small_camera",
    "synthetic_copy",
]
