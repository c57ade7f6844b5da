"""What a real street adds to the flat synthetic world: a camera mounted off the body's axes and at
a height other than the nominal one, a road that is not level under gravity, auto-exposure and
vignetting, and vertical structure beside the road (:mod:`jbevo.data.synthetic.structures`).

A :class:`Street` holds these settings; ``None`` (or :data:`FLAT`) is the flat world, where the
camera sits exactly as its :class:`~jbevo.geometry.camera.Camera` says on a level plane.

* **Mounting.** The rendering camera is pitched by ``mount_pitch_deg`` (positive: looking further
  down) and rolled by ``mount_roll_deg`` against the body, and sits ``height_error`` metres above
  the nominal height; the sequence records the nominal camera, as a user would.
* **Slopes.** The road's grade and banking (:func:`road_tilt_profile`: smooth random profiles
  over the distance driven, or the low-pass of a recorded drive's attitude) tilt the vehicle
  against gravity. The IMU and the ground truth see the whole attitude; the image sees the road
  as level under the car (the renderer's ground is one plane, taken here as the road's local
  tangent plane, the grade changing slowly over a BEV's 25 m).
* **Exposure.** A log-gain that wanders per frame (``exposure_std``, correlated over
  ``exposure_time_s``) and a radial vignetting ``1 - vignetting * r^2`` (``r`` = 1 in the
  image's corners).
"""

from __future__ import annotations

from dataclasses import dataclass

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from scipy.ndimage import gaussian_filter1d

from jbevo.geometry.camera import FORWARD, Camera, level_to_body
from jbevo.geometry.euler import euler_zyx, poses_from_euler


@dataclass(frozen=True)
class Street:
    """The settings of a street world (angles in degrees, lengths in metres).

    Structure beside the road (``facades`` etc.) is placed along the drive by
    :func:`jbevo.data.synthetic.structures.place_structures`; offsets are lateral distances from
    the vehicle's path.
    """

    name: str = "street"
    # vertical structure
    facades: bool = True
    facade_offset: tuple[float, float] = (7.0, 13.0)
    facade_height: tuple[float, float] = (5.0, 14.0)
    facade_gap: float = 0.25  # share of facade segments left open (side streets, yards)
    parked_car_probability: float = 0.6  # per 6.5 m slot and side
    parked_car_offset: tuple[float, float] = (2.7, 3.5)
    poles_per_metre: float = 0.03  # poles and trees, per side
    pole_offset: tuple[float, float] = (4.5, 6.5)
    kerb_offset: float = 4.6
    kerb_height: float = 0.12
    ground_contrast: float = 0.5  # worn asphalt: the ground texture's contrast against the flat world's
    # the camera's mounting, unknown to the model
    mount_pitch_deg: float = 0.6
    mount_roll_deg: float = -0.3
    height_error: float = 0.05
    # slopes: whether the road tilts (a recorded drive's own grade and banking, or random
    # profiles with these standard deviations)
    slopes: bool = True
    grade_deg: float = 1.0
    bank_deg: float = 0.6
    # exposure
    exposure_std: float = 0.12
    exposure_time_s: float = 1.5
    vignetting: float = 0.3


#: The street world of the experiments (``--world street``).
STREET = Street()
#: The flat world: none of the above (``--world flat``, the default).
FLAT = None
WORLDS: dict[str, Street | None] = {"flat": FLAT, "street": STREET}


def street_named(name: str) -> Street | None:
    """The street settings of a world name in :data:`WORLDS`."""
    if name not in WORLDS:
        raise ValueError(f"unknown world {name!r}; known: {sorted(WORLDS)}")
    return WORLDS[name]


def mounted_camera(camera: Camera, street: Street) -> Camera:
    """The camera the images are rendered with: ``camera`` pitched and rolled on its mount."""
    offset = level_to_body(jnp.float32(np.radians(street.mount_pitch_deg)), jnp.float32(np.radians(street.mount_roll_deg)))
    return eqx.tree_at(lambda c: c.rotation_body_to_camera, camera, jnp.asarray(FORWARD, jnp.float32) @ offset.T)


def _smooth_profile(rng: np.random.Generator, s: np.ndarray, std: float, wavelengths=(80.0, 400.0)) -> np.ndarray:
    """A sum of four sinusoids of distance ``s`` (wavelengths drawn in ``wavelengths``, random
    phases) with standard deviation ``std`` over a long drive."""
    k = 2 * np.pi / rng.uniform(wavelengths[0], wavelengths[1], 4)
    phase = rng.uniform(0, 2 * np.pi, 4)
    return std * np.sqrt(0.5) * np.sin(k[:, None] * s[None, :] + phase[:, None]).sum(0)


def road_tilt_profile(body_poses: np.ndarray, street: Street, seed: int) -> np.ndarray:
    """The road's ``(grade, banking)`` (radians, as pitch and roll: positive grade runs downhill,
    positive banking lowers the right side) under each pose, smooth in the distance driven."""
    steps = np.linalg.norm(np.diff(np.asarray(body_poses)[:, :2, 3], axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(steps)]
    rng = np.random.default_rng([seed, 7])
    grade = _smooth_profile(rng, s, np.radians(street.grade_deg))
    bank = _smooth_profile(rng, s, np.radians(street.bank_deg))
    return np.stack([grade, bank], -1)


def street_tilt(street: Street, recorded: np.ndarray | None, body_poses: np.ndarray, seed: int) -> np.ndarray:
    """The road's ``(grade, banking)`` under ``body_poses`` on ``street``: zero without slopes,
    else ``recorded`` where given, else :func:`road_tilt_profile`."""
    if not street.slopes:
        return np.zeros((len(body_poses), 2))
    return road_tilt_profile(body_poses, street, seed) if recorded is None else np.asarray(recorded, float)


def recorded_road_tilt(body_poses: np.ndarray, frame_rate: float = 10.0, window_s: float = 2.0) -> np.ndarray:
    """The road's ``(grade, banking)`` under a recorded drive: the Gaussian low-pass (sigma
    ``window_s``) of its pitch and roll (what is left is the suspension's motion)."""
    euler = euler_zyx(np.asarray(body_poses, float)[:, :3, :3])
    return gaussian_filter1d(euler[:, 1:], window_s * frame_rate, axis=0, mode="nearest")


def tilt_onto_road(body_poses: np.ndarray, tilt: np.ndarray) -> np.ndarray:
    """Poses on a level road (``T_world_body``) carried onto the road of ``tilt``: pitch and roll
    gain the grade and banking, and the height follows the climb (``-sin(grade)`` per metre)."""
    poses = np.asarray(body_poses, float)
    euler = euler_zyx(poses[:, :3, :3])
    euler[:, 1:] += tilt
    steps = np.linalg.norm(np.diff(poses[:, :2, 3], axis=0), axis=1)
    climb = np.r_[0.0, np.cumsum(-np.sin(0.5 * (tilt[1:, 0] + tilt[:-1, 0])) * steps)]
    position = poses[:, :3, 3] + np.c_[np.zeros((len(poses), 2)), climb]
    return poses_from_euler(euler, position)


def road_relative(body_poses: np.ndarray, tilt: np.ndarray, height: np.ndarray | float) -> np.ndarray:
    """The poses the camera has against the road (the renderer's level plane): pitch and roll less
    the road's ``tilt``, at ``height`` above it; x, y and yaw unchanged."""
    poses = np.asarray(body_poses, float)
    euler = euler_zyx(poses[:, :3, :3])
    euler[:, 1:] -= tilt
    position = np.c_[poses[:, :2, 3], np.broadcast_to(np.asarray(height, float), len(poses))]
    return poses_from_euler(euler, position)


def exposure_gains(frames: int, street: Street, seed: int, frame_rate: float = 10.0) -> np.ndarray:
    """Each frame's exposure gain: ``exp`` of a smooth random log-gain of std ``exposure_std``."""
    if street.exposure_std == 0 or frames == 0:
        return np.ones(frames, np.float32)
    rng = np.random.default_rng([seed, 11])
    sigma = street.exposure_time_s * frame_rate
    pad = int(4 * sigma)
    walk = gaussian_filter1d(rng.standard_normal(frames + 2 * pad), sigma)[pad : pad + frames]
    walk = walk / (walk.std() + 1e-12) if frames > 1 else walk
    return np.exp(street.exposure_std * walk).astype(np.float32)


def vignette(camera: Camera, strength: float) -> jnp.ndarray:
    """The radial falloff ``1 - strength * r^2`` of every pixel (``r`` = 1 in the farthest corner
    from the principal point)."""
    height, width = camera.image_shape
    k = np.asarray(camera.intrinsics, float)
    u = np.arange(width) - k[0, 2]
    v = np.arange(height) - k[1, 2]
    r2 = u[None, :] ** 2 + v[:, None] ** 2
    corner = max(x**2 + y**2 for x in (u[0], u[-1]) for y in (v[0], v[-1]))
    return jnp.asarray(1.0 - strength * r2 / corner, jnp.float32)


__all__ = [
    "FLAT",
    "STREET",
    "WORLDS",
    "Street",
    "exposure_gains",
    "mounted_camera",
    "recorded_road_tilt",
    "road_relative",
    "road_tilt_profile",
    "street_named",
    "street_tilt",
    "tilt_onto_road",
    "vignette",
]
