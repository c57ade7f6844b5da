"""Localization scenes: a long drive in a town, its camera and IMU under an imaging condition, and
a top-down map of the area from another sensor (:mod:`jbevo.data.synthetic.maps`).

Two kinds, after the BEVO+ experiments:

* ``carla``: a car (camera 1.65 m up, 4-14 m/s) localized on a satellite-look map (0.2 m per
  pixel, blurred, another tone curve, cloud shadows).
* ``aeroground``: a ground robot (camera 0.8 m up, 1-3 m/s, a stiffer, shakier chassis)
  localized on a map rendered from a drone's viewpoint (0.1 m per pixel, drone look).

Each scene is split in quarters: the first two quarters train, the third validates, the last
tests (:func:`scene` renders only the part asked for; the drive and the quarters are the same
whatever the condition). The map covers the part's trajectory plus a margin.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from jbevo.data.map import Map
from jbevo.data.sequence import Sequence
from jbevo.data.splits import part_range
from jbevo.data.synthetic.maps import render_map
from jbevo.data.synthetic.sequences import make_sequence, small_camera
from jbevo.data.synthetic.street import Street
from jbevo.data.synthetic.structures import place_structures
from jbevo.data.synthetic.trajectories import procedural_drive
from jbevo.data.synthetic.world import World
from jbevo.geometry.bev_grid import BevGrid


@dataclass(frozen=True)
class SceneKind:
    """A platform, its map and the BEV grids that suit its camera height and speed."""

    name: str
    height: float  #: camera height (m)
    speed_range: tuple[float, float]  #: m/s
    suspension_std_deg: float
    map_style: str
    map_resolution: float  #: metres per map pixel
    frames: int  #: frames of the whole drive (10 Hz)
    odometry_grid: tuple[float, int, float]  #: (resolution, size, near) of BEVO's BEV
    map_grid: tuple[float, int, float]  #: (resolution, size, near) of the map-matching BEV

    def grids(self) -> tuple[BevGrid, BevGrid]:
        (r0, s0, n0), (r1, s1, n1) = self.odometry_grid, self.map_grid
        return BevGrid(r0, (s0, s0), near=n0), BevGrid(r1, (s1, s1), near=n1)


SCENE_KINDS = {
    # 6000 frames: each quarter is ~1.1 km of driving.
    "carla": SceneKind("carla", 1.65, (4.0, 14.0), 0.7, "satellite", 0.2, 6000, (0.1, 128, 7.5), (0.2, 64, 4.0)),
    "aeroground": SceneKind("aeroground", 0.8, (1.0, 3.0), 1.0, "drone", 0.1, 2400, (0.05, 128, 3.0), (0.1, 64, 3.0)),
}


class Scene(NamedTuple):
    name: str
    sequence: Sequence
    map: Map


def scene_drive(kind: SceneKind | str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The whole drive of a scene: ``(frame_times, body_poses)`` with ``kind.frames + 1`` poses
    (the first starts the IMU)."""
    kind = _kind(kind)
    return procedural_drive(
        seed, kind.frames + 1, speed_range=kind.speed_range, suspension_std_deg=kind.suspension_std_deg, height=kind.height
    )


def scene(
    kind: SceneKind | str = "carla",
    town: str = "town01",
    condition: str = "day",
    part: str = "all",
    seed: int = 0,
    world: World | None = None,
    frames: int | None = None,
    street: Street | None = None,
) -> Scene:
    """Render ``part`` of the drive ``seed`` of ``kind`` in ``town`` under ``condition``, and its
    map. ``frames`` overrides the drive's length (tests, notebooks). On a ``street``
    (:mod:`jbevo.data.synthetic.street`) the drive has its slopes, structures, camera mounting and
    exposure, and the map shows the structures' tops."""
    kind = _kind(kind)
    if frames is not None:
        kind = SceneKind(**{**kind.__dict__, "frames": int(frames)})
    if kind.frames < 8:
        raise ValueError(f"a scene needs at least 8 frames, got {kind.frames}")
    world = World.create(town) if world is None else world
    times, poses = scene_drive(kind, seed)
    start, stop = part_range(kind.frames, part)
    # Poses [start, stop] (one more: the frame before the part starts its IMU).
    structures = None if street is None else place_structures(poses[start + 1 : stop + 1], street, seed)
    seq = make_sequence(
        world,
        small_camera(height=kind.height),
        times[start : stop + 1],
        poses[start : stop + 1],
        condition,
        seed=seed,
        street=street,
        structures=structures,
    )
    map_ = render_map(
        world, poses[start : stop + 1, :2, 3], kind.map_resolution, style=kind.map_style, seed=seed + 1, structures=structures
    )
    return Scene(f"{kind.name}_{town}_{condition}_{part}_s{seed}", seq, map_)


def _kind(kind: SceneKind | str) -> SceneKind:
    if isinstance(kind, SceneKind):
        return kind
    if kind not in SCENE_KINDS:
        raise ValueError(f"unknown scene kind {kind!r}; known: {sorted(SCENE_KINDS)}")
    return SCENE_KINDS[kind]


__all__ = ["SCENE_KINDS", "Scene", "SceneKind", "scene", "scene_drive"]
