"""KITTI odometry and raw layouts: readers that give a :class:`~jbevo.data.sequence.Sequence`
and writers for the same layouts (a synthetic sequence exported and read back is the test).

Odometry layout (``root/sequences/NN/{image_0/*.png, times.txt, calib.txt}``,
``root/poses/NN.txt``): images, times, ``P0`` intrinsics and, where the pose file exists, the
ground truth (camera 0 poses, turned into body poses in a z-up world). The layout carries no IMU:
without ``imu`` the Sequence's IMU arrays are NaN (one sample per frame) and a model that needs
the IMU refuses it (:func:`has_imu`). With ``imu`` (a KITTI odometry IMU file ``NN.mat`` or the
folder holding it, as published with the KITTI odometry IMU: the car's OXTS RT3003,
``imu_data_interp`` of shape ``(10 (N - 1) + 1, 6)``, rows ``ax ay az wx wy wz`` in the IMU frame
x forward, y left, z up, row ``10 k + j`` at ``j / 10`` of the way from frame ``k`` to ``k + 1``:
:func:`read_kitti_imu`) block ``t`` holds rows ``10 (t - 1) .. 10 t - 1`` and block 0 is NaN.

Raw layout (``root/DATE/DATE_drive_NNNN_sync/{image_00/data/*.png, image_00/timestamps.txt,
oxts/data/*.txt, oxts/timestamps.txt}``, ``root/DATE/calib_cam_to_cam.txt``, or the calibration
files in the drive's own ``calib/`` folder): the IMU is OXTS's ``wx, wy, wz`` and ``ax, ay, az``
(body x forward, y left, z up, as jbevo's), grouped into the frames' blocks by timestamp
(:func:`jbevo.data.imu_stream.group_blocks`: a sample at time tau belongs to frame ``t`` if
``t_t-1 <= tau < t_t``, NaN rows padded after the real ones: the synced 10 Hz data gives 0-2
samples per frame, the 100 Hz extract about ten), or resampled at ``samples_per_frame`` instants
per frame (:func:`jbevo.data.imu_stream.resample_blocks`). Times are float64 seconds relative to
the first camera frame. Ground truth is the OXTS GPS/INS pose at the sample nearest each frame,
projected with the Mercator scale of the first fix (``scale = cos(lat0)``,
``x = scale R lon``, ``y = scale R log tan((90 + lat) / 2)``, ``R`` the WGS84 equatorial radius)
and ``R = Rz(yaw) Ry(pitch) Rx(roll)``; positions and heading relative to the first pose, pitch
and roll as the INS gives them (against gravity).

Errors name the file: missing folders and files, truncated or malformed lines, frame counts that
disagree, timestamps that do not increase. Writers write every file atomically.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from pathlib import Path

import cv2
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jbevo.data.imu_stream import ImuStream, group_blocks, resample_blocks
from jbevo.data.kitti_frames import CAMERA_HEIGHT, body_poses_from_kitti, camera_poses_from_body
from jbevo.data.sequence import Sequence, check
from jbevo.files import write_atomic, write_text_atomic
from jbevo.geometry.camera import Camera
from jbevo.geometry.euler import euler_zyx, rotation_zyx

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


def read_kitti_imu(path: str | Path, frame_times: np.ndarray, rows_per_frame: int = 10) -> ImuStream:
    """The KITTI odometry IMU file ``path`` (``NN.mat``, variable ``imu_data_interp``) as a stream
    timed by the sequence's ``frame_times``: ``rows_per_frame`` rows per frame interval (10 as
    published), row ``R k + j`` at ``t_k + j (t_k+1 - t_k) / R``, row ``R (N - 1)`` at the last
    frame. A file longer than the ``N`` frames (a folder holding a drive's first frames) is cut to
    them; a shorter one is an error."""
    from scipy.io import loadmat

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"missing IMU file {path}")
    try:
        rows = np.asarray(loadmat(str(path))["imu_data_interp"], float)
    except (KeyError, ValueError, TypeError, OSError) as error:
        raise ValueError(f"{path} is not a KITTI odometry IMU file with imu_data_interp ({error})") from None
    frame_times = np.asarray(frame_times, float)
    n = len(frame_times)
    needed = rows_per_frame * (n - 1) + 1
    if rows.ndim != 2 or rows.shape[1] != 6 or n < 2 or len(rows) < needed:
        raise ValueError(f"{path}: imu_data_interp has shape {rows.shape}; {n} frames need at least ({needed}, 6)")
    rows = rows[:needed]
    fraction = np.arange(rows_per_frame) / rows_per_frame
    times = (frame_times[:-1, None] + np.diff(frame_times)[:, None] * fraction[None, :]).reshape(-1)
    stream = ImuStream(np.append(times, frame_times[-1]), rows[:, 3:6], rows[:, 0:3])
    return stream.check(str(path))


#: The largest second difference (over the six channels, m/s^2 and rad/s) of three successive
#: frame-time samples below which the middle one counts as interpolated: the recorded samples'
#: own noise keeps it far above this, a straight line puts it at the file's storage precision
#: (``tests/data/test_kitti_real.py`` checks both sides on sequences 06 and 07).
INTERPOLATION_TOLERANCE = 1e-3


def frame_curvature(stream: ImuStream, rows_per_frame: int = 10) -> np.ndarray:
    """The second difference of a KITTI odometry IMU stream at each interior frame.

    Per frame ``1 .. N-2``, the largest absolute value over the six channels (gyro, specific
    force) of ``s[k-1] - 2 s[k] + s[k+1]``, ``s[k]`` the stream's row at frame ``k``. Zero, to the
    precision the values are stored with, where the sample lies on the straight line through its
    neighbours'."""
    if rows_per_frame < 1:
        raise ValueError(f"rows_per_frame must be at least 1, got {rows_per_frame}")
    if (len(stream.times) - 1) % rows_per_frame:
        raise ValueError(f"the stream has {len(stream.times)} rows, not {rows_per_frame} per frame plus one")
    at_frames = np.concatenate([stream.gyro, stream.accel], axis=1)[::rows_per_frame]
    return np.abs(at_frames[:-2] - 2 * at_frames[1:-1] + at_frames[2:]).max(axis=1)


def interpolated_frames(stream: ImuStream, rows_per_frame: int = 10, tolerance: float = INTERPOLATION_TOLERANCE) -> np.ndarray:
    """Which frames of a KITTI odometry IMU stream (:func:`read_kitti_imu`) were not recorded.

    The published file fills the OXTS unit's dropouts by straight lines between the samples
    recorded around them. A frame whose :func:`frame_curvature` (second difference over all six
    channels) is below ``tolerance`` lies on such a line. Returns a boolean per frame; only
    interior frames can be flagged, so the recorded samples at both ends of a gap (the line's
    knots) are not: a gap flagged at frames ``a .. b`` is one line from frame ``a - 1`` to
    ``b + 1``."""
    curvature = frame_curvature(stream, rows_per_frame)
    frames = (len(stream.times) - 1) // rows_per_frame + 1
    return np.concatenate([[False], curvature < tolerance, [False]])[:frames]


def dropout_frames(flags: np.ndarray) -> np.ndarray:
    """The runs of flagged frames (:func:`interpolated_frames`), each as its first and last frame,
    shape ``(G, 2)`` (integers)."""
    edges = np.diff(np.concatenate([[0], np.asarray(flags).astype(np.int8), [0]]))
    return np.stack([np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1], -1)


def dropout_spans(stream: ImuStream, rows_per_frame: int = 10, tolerance: float = INTERPOLATION_TOLERANCE) -> np.ndarray:
    """The time spans ``(start, end)`` (the stream's clock, shape ``(G, 2)``) of the straight lines
    over which a KITTI odometry IMU stream's dropouts were filled: a gap flagged at frames
    ``a .. b`` (:func:`interpolated_frames`, :func:`dropout_frames`) runs from frame ``a - 1``'s
    recorded sample to frame ``b + 1``'s; every row strictly inside is on the line."""
    runs = dropout_frames(interpolated_frames(stream, rows_per_frame, tolerance))
    knots = np.asarray(stream.times, float)[::rows_per_frame]
    return np.stack([knots[runs[:, 0] - 1], knots[runs[:, 1] + 1]], -1) if len(runs) else np.zeros((0, 2))


#: Seconds within which a row's stamp counts as a dropout line's knot (a recorded sample), not
#: as inside the line: a sequence's float32 stamps of a long drive are that far off the float64
#: knots (IMU rows are 10 ms apart).
KNOT_TOLERANCE_S = 1e-4


def on_dropout_lines(imu_times: np.ndarray, spans: np.ndarray, time_offset_s: float = 0.0) -> np.ndarray:
    """Which IMU rows, stamped ``imu_times`` (any shape), lie on a dropout's straight line
    (:func:`dropout_spans`): those whose ``t - time_offset_s`` lies inside a span by more than
    :data:`KNOT_TOLERANCE_S` (``time_offset_s`` as in :func:`without_dropouts`). A boolean array of
    ``imu_times``' shape."""
    spans = np.asarray(spans, float)
    if spans.ndim != 2 or spans.shape[1] != 2 or not np.all(spans[:, 1] > spans[:, 0]):
        raise ValueError(f"spans must be (start, end) pairs with end > start, shape (G, 2); got {spans.tolist()}")
    t = np.asarray(imu_times, float) - time_offset_s
    on_line = np.zeros(t.shape, bool)
    for start, end in spans:
        on_line |= (t > start + KNOT_TOLERANCE_S) & (t < end - KNOT_TOLERANCE_S)
    return on_line


def blank_dropout_rows(
    imu_times: np.ndarray, gyro: np.ndarray, accel: np.ndarray, spans: np.ndarray, time_offset_s: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """``gyro`` and ``accel`` (``imu_times``' shape plus 3) with the rows on a dropout's line
    (:func:`on_dropout_lines`) NaN."""
    on_line = on_dropout_lines(imu_times, spans, time_offset_s)[..., None]
    return np.where(on_line, np.nan, gyro), np.where(on_line, np.nan, accel)


def without_dropouts(seq: Sequence, spans: np.ndarray, time_offset_s: float = 0.0) -> Sequence:
    """``seq`` with the IMU rows that lie on a dropout's straight line (:func:`dropout_spans`)
    marked missing (NaN), so that a filter treats them as unmeasured instead of as a measured
    straight line (:attr:`jbevo.inertial.speed_aided.SpeedAidedAttitude.gap_rate_std`).

    A row stamped ``t`` in ``seq.imu_times`` is on a line if ``t - time_offset_s`` lies inside one
    of ``spans`` (:func:`on_dropout_lines`): ``time_offset_s`` is what a calibration added to the
    stream's stamps (:attr:`jbevo.inertial.calibration.ImuCalibration.time_offset_s`; zero for a
    sequence read as published), so that the rows of a calibrated, resampled sequence are marked
    where they took their values from the line."""
    gyro, accel = blank_dropout_rows(np.asarray(seq.imu_times), np.asarray(seq.gyro), np.asarray(seq.accel), spans, time_offset_s)
    return check(eqx.tree_at(lambda q: (q.gyro, q.accel), seq, (jnp.asarray(gyro), jnp.asarray(accel))))


def _imu_file(imu: str | Path, sequence: str) -> Path:
    imu = Path(imu)
    return imu / f"{sequence}.mat" if imu.is_dir() else imu


def read_odometry(
    root: str | Path,
    sequence: str,
    camera_height: float = CAMERA_HEIGHT,
    imu: str | Path | None = None,
    imu_dropouts: str = "published",
) -> Sequence:
    """Sequence ``sequence`` (e.g. ``"09"``) of a KITTI odometry folder. ``imu``: the sequence's
    KITTI odometry IMU file, or the folder holding ``NN.mat`` (:func:`read_kitti_imu`); without it
    the IMU arrays are NaN. ``imu_dropouts``: ``published`` keeps the rows the file fills its
    dropouts with, ``missing`` marks them NaN (:func:`without_dropouts`)."""
    root = Path(root)
    folder = root / "sequences" / sequence
    if not folder.is_dir():
        raise FileNotFoundError(f"missing sequence folder {folder}")
    images = _images(folder / "image_0")
    times = np.concatenate(_numbers(folder / "times.txt", 1))
    p0 = _p0(folder / "calib.txt")
    n = len(images)
    if len(times) != n:
        raise ValueError(f"{folder}: {n} images but {len(times)} times")
    pose_file = root / "poses" / f"{sequence}.txt"
    poses = _body_poses(pose_file, n) if pose_file.is_file() else np.full((n, 4, 4), np.nan)
    blocks = _imu_blocks(None if imu is None else _imu_file(imu, sequence), times, imu_dropouts)
    return _sequence(images, times, *blocks, _camera(p0, images.shape[1:], camera_height), poses)


def _p0(calib_file: Path) -> np.ndarray:
    """The ``P0`` projection ``(3, 4)`` of a KITTI odometry ``calib.txt``."""
    calib = _calibration_rows(calib_file) if calib_file.is_file() else {}
    if calib.get("P0", np.array([])).size != 12:
        raise ValueError(f"{calib_file} is missing or has no P0 line")
    return calib["P0"].reshape(3, 4)


def _body_poses(pose_file: Path, n: int) -> np.ndarray:
    """The body poses of a KITTI pose file that must have ``n`` lines."""
    rows = _numbers(pose_file, 12)
    if len(rows) != n:
        raise ValueError(f"{pose_file}: {len(rows)} poses for {n} images")
    cam = np.tile(np.eye(4), (n, 1, 1))
    cam[:, :3, :] = np.stack(rows).reshape(n, 3, 4)
    return body_poses_from_kitti(cam)


#: How the readers take the published IMU's dropouts (:func:`interpolated_frames`): as published
#: (the straight lines), or ``missing`` (the rows on the lines NaN, :func:`on_dropout_lines`).
IMU_DROPOUTS = ("published", "missing")


def check_imu_dropouts(imu_dropouts: str) -> None:
    """``ValueError`` unless ``imu_dropouts`` is one of :data:`IMU_DROPOUTS`."""
    if imu_dropouts not in IMU_DROPOUTS:
        raise ValueError(f"imu_dropouts must be one of {', '.join(IMU_DROPOUTS)}; got {imu_dropouts!r}")


def _imu_blocks(
    imu_file: Path | str | None, times: np.ndarray, imu_dropouts: str = "published"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frame blocks of a KITTI odometry IMU file (with ``imu_dropouts`` ``missing``, the rows on
    a dropout's line NaN), or NaN blocks of one sample without it."""
    check_imu_dropouts(imu_dropouts)
    if imu_file is None:
        nan = np.full((len(times), 1, 3), np.nan)
        return times[:, None], nan, nan
    stream = read_kitti_imu(imu_file, times)
    block_times, gyro, accel = group_blocks(stream, times)
    if imu_dropouts == "missing":
        gyro, accel = blank_dropout_rows(block_times, gyro, accel, dropout_spans(stream))
    return block_times, gyro, accel


def read_run(
    folder: str | Path, imu: str | Path | None = None, camera_height: float = CAMERA_HEIGHT, imu_dropouts: str = "published"
) -> Sequence:
    """One KITTI odometry run kept in a single folder: ``image_0/*.png``, ``times.txt``,
    ``calib.txt`` (with ``P0``) and ``poses.txt`` (the ground truth of these frames), as the first
    frames of a sequence are often shipped. ``times.txt`` may be the whole sequence's (longer than
    the images: its first lines are these frames'); ``poses.txt`` must have one line per image.
    ``imu``: the sequence's KITTI odometry IMU file ``NN.mat`` (:func:`read_kitti_imu`; cut to
    these frames); without it the IMU arrays are NaN. ``imu_dropouts`` as in
    :func:`read_odometry`."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"missing run folder {folder}")
    images = _images(folder / "image_0")
    n = len(images)
    times = np.concatenate(_numbers(folder / "times.txt", 1))
    if len(times) < n:
        raise ValueError(f"{folder / 'times.txt'}: {len(times)} times for {n} images")
    times = times[:n]
    poses = _body_poses(folder / "poses.txt", n)
    camera = _camera(_p0(folder / "calib.txt"), images.shape[1:], camera_height)
    return _sequence(images, times, *_imu_blocks(imu, times, imu_dropouts), camera, poses)


def has_imu(seq: Sequence) -> bool:
    """Whether ``seq`` holds any IMU sample (a KITTI odometry folder read without its IMU file
    holds none)."""
    return bool(np.any(np.isfinite(np.asarray(seq.gyro))) and np.any(np.isfinite(np.asarray(seq.accel))))


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
    """float64 seconds since a fixed origin (to be taken relative to the first frame)."""
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
    """Body poses (z-up world: Mercator east, north, altitude; attitude as the INS gives it)
    from OXTS records ``(N, >= 6)``."""
    scale = np.cos(np.radians(oxts[0, 0]))
    x, y = _mercator(oxts[:, 0], oxts[:, 1], scale)
    poses = np.tile(np.eye(4), (len(oxts), 1, 1))
    poses[:, :3, :3] = rotation_zyx(oxts[:, [5, 4, 3]])
    poses[:, :3, 3] = np.stack([x, y, oxts[:, 2]], -1)
    return poses


def _calibration_file(drive: Path) -> Path:
    for candidate in (drive.parent / "calib_cam_to_cam.txt", drive / "calib" / "calib_cam_to_cam.txt"):
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f"missing calib_cam_to_cam.txt beside {drive} or in {drive / 'calib'}")


def _calibration_rows(path: Path) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise FileNotFoundError(f"missing calibration file {path}")
    rows = {}
    for line in path.read_text().splitlines():
        key, sep, rest = line.partition(":")
        if not sep:
            continue
        try:
            rows[key.strip()] = np.array([float(v) for v in rest.split()])
        except ValueError:
            rows[key.strip()] = np.array([])  # text fields (calib_time)
    return rows


def imu_to_rectified_camera(calib_folder: str | Path) -> np.ndarray:
    """KITTI's published IMU -> rectified camera 0 transform ``(4, 4)`` from a day's calibration
    files: ``R_rect_00 T_cam_velo T_velo_imu`` (``calib_imu_to_velo.txt``,
    ``calib_velo_to_cam.txt``, ``calib_cam_to_cam.txt``)."""
    folder = Path(calib_folder)

    def transform(name: str) -> np.ndarray:
        rows = _calibration_rows(folder / name)
        if rows.get("R", np.array([])).size != 9 or rows.get("T", np.array([])).size != 3:
            raise ValueError(f"{folder / name} needs R (9 numbers) and T (3 numbers)")
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = rows["R"].reshape(3, 3), rows["T"]
        return out

    cam = _calibration_rows(folder / "calib_cam_to_cam.txt")
    if cam.get("R_rect_00", np.array([])).size != 9:
        raise ValueError(f"{folder / 'calib_cam_to_cam.txt'} has no R_rect_00 (9 numbers)")
    rect = np.eye(4)
    rect[:3, :3] = cam["R_rect_00"].reshape(3, 3)
    return rect @ transform("calib_velo_to_cam.txt") @ transform("calib_imu_to_velo.txt")


def read_oxts(drive_folder: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The OXTS records of a raw drive: ``(times (M,) float64 seconds, records (M, 30))`` (fields
    as KITTI's ``oxts/dataformat.txt``: lat, lon, alt, roll, pitch, yaw, ..., ax, ay, az at 11-13,
    wx, wy, wz at 17-19)."""
    drive = Path(drive_folder)
    times = _timestamps(drive / "oxts" / "timestamps.txt")
    files = sorted((drive / "oxts" / "data").glob("*.txt"))
    if len(files) != len(times):
        raise ValueError(f"{drive / 'oxts'}: {len(files)} records but {len(times)} timestamps")
    return times, np.stack([_numbers(f, 30)[0] for f in files])


def read_raw(drive_folder: str | Path, camera_height: float = CAMERA_HEIGHT, samples_per_frame: int | None = None) -> Sequence:
    """A KITTI raw drive folder (``.../DATE_drive_NNNN_sync``; calibration in its parent or its
    ``calib/``). ``samples_per_frame``: None keeps the OXTS samples as recorded (padded blocks),
    an integer resamples the stream at that many instants per frame interval."""
    drive = Path(drive_folder)
    if not drive.is_dir():
        raise FileNotFoundError(f"missing drive folder {drive}")
    images = _images(drive / "image_00" / "data")
    frame_times = _timestamps(drive / "image_00" / "timestamps.txt")
    if len(frame_times) != len(images):
        raise ValueError(f"{drive / 'image_00'}: {len(images)} images but {len(frame_times)} timestamps")
    oxts_times, oxts = read_oxts(drive)
    calib_file = _calibration_file(drive)
    rows = _calibration_rows(calib_file)
    if rows.get("P_rect_00", np.array([])).size != 12:
        raise ValueError(f"{calib_file} has no P_rect_00 line")
    p = rows["P_rect_00"].reshape(3, 4)
    origin = frame_times[0]
    frame_times, oxts_times = frame_times - origin, oxts_times - origin
    stream = ImuStream(oxts_times, oxts[:, 17:20], oxts[:, 11:14]).check(str(drive / "oxts"))
    if samples_per_frame is None:
        imu_times, gyro, accel = group_blocks(stream, frame_times)
    else:
        imu_times, gyro, accel = resample_blocks(stream, frame_times, samples_per_frame)
    nearest = np.abs(oxts_times[None, :] - frame_times[:, None]).argmin(1)
    poses = oxts_poses(oxts)[nearest]
    # Position and heading relative to the first frame; pitch and roll stay the INS's own.
    first = np.eye(4)
    first[:3, :3] = rotation_zyx(np.array([[euler_zyx(poses[:1, :3, :3])[0, 0], 0.0, 0.0]]))[0]
    first[:3, 3] = poses[0, :3, 3]
    poses = np.linalg.inv(first) @ poses
    return _sequence(images, frame_times, imu_times, gyro, accel, _camera(p, images.shape[1:], camera_height), poses)


def write_raw(seq: Sequence, drive_folder: str | Path, lat0: float = 49.0, lon0: float = 8.4) -> None:
    """Write ``seq`` as a synced raw drive: one OXTS record per frame (the block's last IMU
    sample at its time, as the synced data holds the sample nearest the frame; the frame's pose),
    the pose placed at
    ``lat0, lon0`` and projected back with the Mercator scale of ``lat0``."""
    drive = Path(drive_folder)
    (drive / "image_00" / "data").mkdir(parents=True, exist_ok=True)
    (drive / "oxts" / "data").mkdir(parents=True, exist_ok=True)
    times = np.asarray(seq.frame_times, float)
    for i, image in enumerate(np.asarray(seq.images)):
        _write_png(drive / "image_00" / "data" / f"{i:010d}.png", image)
    write_text_atomic(drive / "image_00" / "timestamps.txt", "".join(_format_time(t) + "\n" for t in times))
    # Each record at its own sample's time, inside its frame's interval.
    sample_times = np.asarray(seq.imu_times, float)[:, -1]
    write_text_atomic(drive / "oxts" / "timestamps.txt", "".join(_format_time(t) + "\n" for t in sample_times))
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


__all__ = [
    "EARTH_RADIUS",
    "IMU_DROPOUTS",
    "INTERPOLATION_TOLERANCE",
    "KNOT_TOLERANCE_S",
    "blank_dropout_rows",
    "check_imu_dropouts",
    "dropout_frames",
    "dropout_spans",
    "frame_curvature",
    "has_imu",
    "imu_to_rectified_camera",
    "interpolated_frames",
    "on_dropout_lines",
    "oxts_poses",
    "read_kitti_imu",
    "read_odometry",
    "read_oxts",
    "read_raw",
    "read_run",
    "without_dropouts",
    "write_odometry",
    "write_raw",
]
