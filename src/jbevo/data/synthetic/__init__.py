"""The synthetic world: seeded road textures, a renderer, car-like and KITTI-driven trajectories,
an IMU simulator, imaging conditions, drone and satellite maps, localization scenes and a planar
odometry simulator.

Example::

    from jbevo.data.synthetic import procedural_sequence

    seq = procedural_sequence(seed=0, frames=200, town="town01", condition="night")
"""

from jbevo.data.synthetic.conditions import CONDITIONS, Condition, Obstacles, draw_obstacles, expose, place_obstacles
from jbevo.data.synthetic.imu import ADIS16448, NOISELESS, ImuData, ImuNoise, simulate_imu
from jbevo.data.synthetic.maps import MAP_STYLES, MapStyle, render_map
from jbevo.data.synthetic.planar import PlanarSequence, simulate_planar_sequence
from jbevo.data.synthetic.render import render, render_batch
from jbevo.data.synthetic.scenes import SCENE_KINDS, Scene, SceneKind, scene
from jbevo.data.synthetic.sequences import builtin_dataset, kitti_sequence, make_sequence, procedural_sequence, small_camera
from jbevo.data.synthetic.trajectories import kitti_drive, procedural_drive
from jbevo.data.synthetic.world import TOWNS, Town, World

__all__ = [
    "ADIS16448",
    "CONDITIONS",
    "MAP_STYLES",
    "NOISELESS",
    "SCENE_KINDS",
    "TOWNS",
    "Condition",
    "ImuData",
    "ImuNoise",
    "MapStyle",
    "Obstacles",
    "draw_obstacles",
    "expose",
    "place_obstacles",
    "PlanarSequence",
    "Scene",
    "SceneKind",
    "Town",
    "World",
    "builtin_dataset",
    "kitti_drive",
    "kitti_sequence",
    "make_sequence",
    "procedural_drive",
    "procedural_sequence",
    "render",
    "render_batch",
    "render_map",
    "scene",
    "simulate_imu",
    "simulate_planar_sequence",
    "small_camera",
]
