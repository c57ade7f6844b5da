"""KITTI odometry and raw layouts: readers that give a :class:`~jbevo.data.sequence.Sequence`
and writers for the same layouts (a synthetic sequence exported and read back is the test).

Odometry layout (``root/sequences/NN/{image_0/*.png, times.txt, calib.txt}``,
``root/poses/NN.txt``): images, times, ``P0`` intrinsics and, where the pose file exists, the
ground truth (camera 0 poses, turned into body poses in a z-up world). It carries no IMU: the
Sequence's IMU arrays are NaN (one sample per frame), which the attitude filter skips.

Raw layout (``root/DATE/DATE_drive_NNNN_sync/{image_00/data/*.png, image_00/timestamps.txt,
oxts/data/*.txt, oxts/timestamps.txt}``, ``root/DATE/calib_cam_to_cam.txt``): the IMU is OXTS's
``wx, wy, wz`` and ``ax, ay, az`` (body x forward, y left, z up, as jbevo's), grouped into the
frames' blocks by timestamp (a sample at time tau belongs to frame k if
``t_k-1 < tau <= t_k``, padded with NaN rows to a common length: the synced 10 Hz data gives one
sample per frame, the 100 Hz extract about ten). Ground truth is the OXTS GPS/INS pose at the
sample nearest each frame, projected with the Mercator scale of the first fix
(``scale = cos(lat0)``, ``x = scale R lon``, ``y = scale R log tan((90 + lat) / 2)``, ``R`` the
WGS84 equatorial radius) and ``R = Rz(yaw) Ry(pitch) Rx(roll)``, relative to the first pose, as
KITTI's devkit does.

Errors name the file: missing folders and files, truncated or malformed lines, frame counts that
disagree, timestamps that do not increase. Writers write every file atomically.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from pathlib import Path

import cv2
import jax.numpy as jnp
import numpy as np

from jbevo.data.kitti_frames import CAMERA_HEIGHT, body_poses_from_kitti, camera_poses_from_body
from jbevo.data.sequence import Sequence, check
from jbevo.files import write_atomic, write_text_atomic
from jbevo.geometry.camera import Camera
from jbevo.geometry.euler import rotation_zyx

EARTH_RADIUS = 6378137.0
_EPOCH = datetime(2011, 9, 26, 13, 0, 0)


def _numbers(path: Path, count: int | None = None) -> list[np.ndarray]:
    if not path.is_file():
        raise FileNotFoundError(f"missing file {path}")
    rows = []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            values = np.array([float(v) for v in line.split()])
        except ValueError as error:
            raise ValueError(f"{path}:{i}: not a line of numbers ({error})") from None
        if count is not None and len(values) != count:
            raise ValueError(f"{path}:{i}: expected {count} numbers, got {len(values)} (truncated?)")
        rows.append(values)
    if not rows:
        raise ValueError(f"{path} is empty")
    return rows


def _images(folder: Path) -> np.ndarray:
    if not folder.is_dir():
        raise FileNotFoundError(f"missing image folder {folder}")
    files = sorted(folder.glob("*.png"))
    if not files:
        raise ValueError(f"no PNG images in {folder}")
    images = []
    for f in files:
        image = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise ValueError(f"{f} is not a readable image")
        if images and image.shape != images[0].shape:
            raise ValueError(f"{f} has size {image.shape}, the first image {images[0].shape}")
        images.append(image)
    return np.stack(images)


def _camera(p: np.ndarray, shape, height: float) -> Camera:
    return Camera(p[0, 0], p[1, 1], p[0, 2], p[1, 2], shape, height)


def _sequence(images, frame_times, imu_times, gyro, accel, camera, poses) -> Sequence:
    return check(
        Sequence(
            images=jnp.asarray(images),
            frame_times=jnp.asarray(frame_times),
            imu_times=jnp.asarray(imu_times),
            gyro=jnp.asarray(gyro),
            accel=jnp.asarray(accel),
            camera=camera,
            poses=jnp.asarray(poses, jnp.float32),
        )
    )


def read_odometry(root: str | Path, sequence: str, camera_height: float = CAMERA_HEIGHT) -> Sequence:
    """Sequence ``sequence`` (e.g. ``"09"``) of a KITTI odometry folder; IMU arrays are NaN."""
    root = Path(root)
    folder = root / "sequences" / sequence
    if not folder.is_dir():
        raise FileNotFoundError(f"missing sequence folder {folder}")
    images = _images(folder / "image_0")
    times = np.concatenate(_numbers(folder / "times.txt", 1))
    calib = {}
    for line in (folder / "calib.txt").read_text().splitlines() if (folder / "calib.txt").is_file() else []:
        key, _, rest = line.partition(":")
        calib[key.strip()] = rest
    if "P0" not in calib:
        raise ValueError(f"{folder / 'calib.txt'} is missing or has no P0 line")
    p0 = np.array([float(v) for v in calib["P0"].split()]).reshape(3, 4)
    n = len(images)
    if len(times) != n:
        raise ValueError(f"{folder}: {n} images but {len(times)} times")
    pose_file = root / "poses" / f"{sequence}.txt"
    if pose_file.is_file():
        rows = _numbers(pose_file, 12)
        if len(rows) != n:
            raise ValueError(f"{pose_file}: {len(rows)} poses for {n} images")
        cam = np.tile(np.eye(4), (n, 1, 1))
        cam[:, :3, :] = np.stack(rows).reshape(n, 3, 4)
        poses = body_poses_from_kitti(cam)
    else:
        poses = np.full((n, 4, 4), np.nan)
    nan = np.full((n, 1, 3), np.nan, np.float32)
    return _sequence(
        images,
        times.astype(np.float32),
        times[:, None].astype(np.float32),
        nan,
        nan,
        _camera(p0, images.shape[1:], camera_height),
        poses,
    )


def write_odometry(seq: Sequence, root: str | Path, sequence: str) -> None:
    """Write ``seq`` in the odometry layout (images, times, calib with P0-P3 and Tr, poses)."""
    root = Path(root)
    folder = root / "sequences" / sequence
    (folder / "image_0").mkdir(parents=True, exist_ok=True)
    (root / "poses").mkdir(parents=True, exist_ok=True)
    for i, image in enumerate(np.asarray(seq.images)):
        _write_png(folder / "image_0" / f"{i:06d}.png", image)
    write_text_atomic(folder / "times.txt", "".join(f"{t:.6e}\n" for t in np.asarray(seq.frame_times, float)))
    p = np.concatenate([np.asarray(seq.camera.intrinsics, float), np.zeros((3, 1))], 1)
    line = " ".join(f"{v:.12e}" for v in p.ravel())
    tr = " ".join(f"{v:.12e}" for v in np.eye(4)[:3].ravel())
    write_text_atomic(folder / "calib.txt", "".join(f"P{i}: {line}\n" for i in range(4)) + f"Tr: {tr}\n")
    poses = np.asarray(seq.poses, float)
    if np.all(np.isfinite(poses)):
        cam = camera_poses_from_body(poses)
        write_text_atomic(
            root / "poses" / f"{sequence}.txt", "".join(" ".join(f"{v:.12e}" for v in c[:3].ravel()) + "\n" for c in cam)
        )


def _write_png(path: Path, image: np.ndarray) -> None:
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"could not encode {path}")
    write_atomic(path, lambda f: f.write(data.tobytes()), mode="wb")


def _timestamps(path: Path) -> np.ndarray:
    if not path.is_file():
        raise FileNotFoundError(f"missing file {path}")
    out = []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            day, clock = line.split()
            whole, _, frac = clock.partition(".")
            stamp = datetime.strptime(f"{day} {whole}", "%Y-%m-%d %H:%M:%S")
        except ValueError:
            raise ValueError(f"{path}:{i}: not a KITTI timestamp: {line!r}") from None
        out.append((stamp - _EPOCH).total_seconds() + float(f"0.{frac or 0}"))
    t = np.array(out)
    if len(t) == 0 or np.any(np.diff(t) <= 0):
        raise ValueError(f"{path}: timestamps must be present and increasing")
    return t


def _format_time(seconds: float) -> str:
    whole = int(np.floor(seconds))
    stamp = _EPOCH + timedelta(seconds=whole)
    return f"{stamp:%Y-%m-%d %H:%M:%S}.{int(round((seconds - whole) * 1e9)):09d}"


def _mercator(lat, lon, scale):
    return scale * EARTH_RADIUS * np.radians(lon), scale * EARTH_RADIUS * np.log(np.tan(np.radians(90.0 + lat) / 2))


def oxts_poses(oxts: np.ndarray) -> np.ndarray:
    """Body poses (z-up world, relative to the first) from OXTS records ``(N, >= 6)``."""
    scale = np.cos(np.radians(oxts[0, 0]))
    x, y = _mercator(oxts[:, 0], oxts[:, 1], scale)
    poses = np.tile(np.eye(4), (len(oxts), 1, 1))
    poses[:, :3, :3] = rotation_zyx(oxts[:, [5, 4, 3]])
    poses[:, :3, 3] = np.stack([x, y, oxts[:, 2]], -1)
    return np.linalg.inv(poses[0]) @ poses


def read_raw(drive_folder: str | Path, camera_height: float = CAMERA_HEIGHT) -> Sequence:
    """A KITTI raw drive folder (``.../DATE_drive_NNNN_sync``; calibration in its parent)."""
    drive = Path(drive_folder)
    if not drive.is_dir():
        raise FileNotFoundError(f"missing drive folder {drive}")
    images = _images(drive / "image_00" / "data")
    frame_times = _timestamps(drive / "image_00" / "timestamps.txt")
    if len(frame_times) != len(images):
        raise ValueError(f"{drive / 'image_00'}: {len(images)} images but {len(frame_times)} timestamps")
    oxts_times = _timestamps(drive / "oxts" / "timestamps.txt")
    files = sorted((drive / "oxts" / "data").glob("*.txt"))
    if len(files) != len(oxts_times):
        raise ValueError(f"{drive / 'oxts'}: {len(files)} records but {len(oxts_times)} timestamps")
    oxts = np.stack([_numbers(f, 30)[0] for f in files])
    calib_file = drive.parent / "calib_cam_to_cam.txt"
    rows = (
        {k.strip(): v for k, _, v in (line.partition(":") for line in calib_file.read_text().splitlines())}
        if calib_file.is_file()
        else {}
    )
    if "P_rect_00" not in rows:
        raise ValueError(f"{calib_file} is missing or has no P_rect_00 line")
    p = np.array([float(v) for v in rows["P_rect_00"].split()]).reshape(3, 4)
    # Samples per frame: t_k-1 < tau <= t_k (2 ms tolerance for the synced data's jitter).
    block = np.searchsorted(frame_times + 2e-3, oxts_times, side="left")
    keep = block < len(frame_times)
    counts = np.bincount(block[keep], minlength=len(frame_times))
    s = max(1, int(counts.max()))
    gyro = np.full((len(frame_times), s, 3), np.nan)
    accel = np.full_like(gyro, np.nan)
    imu_times = frame_times[:, None] - (s - 1 - np.arange(s))[None, :] * 1e-6
    slot = np.zeros(len(frame_times), int)
    for i in np.flatnonzero(keep):
        k = block[i]
        j = s - counts[k] + slot[k]
        gyro[k, j], accel[k, j], imu_times[k, j] = oxts[i, 17:20], oxts[i, 11:14], oxts_times[i]
        slot[k] += 1
    nearest = np.abs(oxts_times[None, :] - frame_times[:, None]).argmin(1)
    poses = oxts_poses(oxts)[nearest]
    poses = np.linalg.inv(poses[0]) @ poses
    return _sequence(
        images,
        frame_times.astype(np.float32),
        imu_times.astype(np.float32),
        gyro.astype(np.float32),
        accel.astype(np.float32),
        _camera(p, images.shape[1:], camera_height),
        poses,
    )


def write_raw(seq: Sequence, drive_folder: str | Path, lat0: float = 49.0, lon0: float = 8.4) -> None:
    """Write ``seq`` as a synced raw drive: one OXTS record per frame (the block's last IMU
    sample, as the synced data holds the sample nearest the frame), the pose placed at
    ``lat0, lon0`` and projected back with the Mercator scale of ``lat0``."""
    drive = Path(drive_folder)
    (drive / "image_00" / "data").mkdir(parents=True, exist_ok=True)
    (drive / "oxts" / "data").mkdir(parents=True, exist_ok=True)
    times = np.asarray(seq.frame_times, float)
    for i, image in enumerate(np.asarray(seq.images)):
        _write_png(drive / "image_00" / "data" / f"{i:010d}.png", image)
    stamps = "".join(_format_time(t) + "\n" for t in times)
    write_text_atomic(drive / "image_00" / "timestamps.txt", stamps)
    write_text_atomic(drive / "oxts" / "timestamps.txt", stamps)
    poses = np.asarray(seq.poses, float)
    scale = np.cos(np.radians(lat0))
    x0, y0 = _mercator(lat0, lon0, scale)
    lon = np.degrees((x0 + poses[:, 0, 3]) / (scale * EARTH_RADIUS))
    lat = np.degrees(2 * np.arctan(np.exp((y0 + poses[:, 1, 3]) / (scale * EARTH_RADIUS)))) - 90.0
    r = poses[:, :3, :3]
    yaw, pitch, roll = (
        np.arctan2(r[:, 1, 0], r[:, 0, 0]),
        -np.arcsin(np.clip(r[:, 2, 0], -1, 1)),
        np.arctan2(r[:, 2, 1], r[:, 2, 2]),
    )
    gyro, accel = np.asarray(seq.gyro, float)[:, -1], np.asarray(seq.accel, float)[:, -1]
    for i in range(len(times)):
        record = np.zeros(30)
        record[:6] = lat[i], lon[i], poses[i, 2, 3], roll[i], pitch[i], yaw[i]
        record[11:14], record[17:20] = accel[i], gyro[i]
        write_text_atomic(drive / "oxts" / "data" / f"{i:010d}.txt", " ".join(f"{v:.15g}" for v in record) + "\n")
    p = np.concatenate([np.asarray(seq.camera.intrinsics, float), np.zeros((3, 1))], 1)
    write_text_atomic(drive.parent / "calib_cam_to_cam.txt", "P_rect_00: " + " ".join(f"{v:.12e}" for v in p.ravel()) + "\n")


__all__ = ["EARTH_RADIUS", "oxts_poses", "read_odometry", "read_raw", "write_odometry", "write_raw"]
