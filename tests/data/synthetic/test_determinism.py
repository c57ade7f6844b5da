"""Every generator of the synthetic world is a pure function of its arguments and seed: two
calls are bit-equal, with other work (and freed memory full of other values) between them."""

import jax
import numpy as np
import pytest

from jbevo.data.synthetic import (
    World,
    kitti_drive,
    place_obstacles,
    procedural_drive,
    procedural_sequence,
    render_map,
    scene,
    simulate_imu,
    simulate_planar_sequence,
)
from jbevo.geometry import Camera

CAMERA = Camera(60.0, 60.0, 47.5, 15.5, (32, 96), 1.65)


def _churn():
    """Allocate and free arrays of garbage of many sizes, so that uninitialised memory a
    generator might read differs between the two calls."""
    rng = np.random.default_rng()
    for size in (1_000, 60_001, 240_001, 600_001):
        garbage = rng.normal(size=size) * 1e6
        del garbage


def _equal(a, b):
    leaves_a, leaves_b = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    assert len(leaves_a) == len(leaves_b)
    for x, y in zip(leaves_a, leaves_b):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.fixture(scope="module")
def world():
    return World.create("town02", size=256)


GENERATORS = {
    "procedural_drive": lambda w: procedural_drive(11, 3001, stop_probability=0.5),
    "kitti_drive": lambda w: kitti_drive(procedural_drive(2, 200)[1]),
    "simulate_imu": lambda w: simulate_imu(*procedural_drive(3, 60), seed=4),
    "procedural_sequence": lambda w: procedural_sequence(5, 8, camera=CAMERA, world=w, condition="night"),
    "dynamic_obstacles": lambda w: place_obstacles(procedural_drive(6, 50)[1], 5, 7),
    "render_map": lambda w: render_map(w, procedural_drive(8, 60)[1][:, :2, 3], 0.2, style="satellite", seed=9),
    "scene": lambda w: scene("carla", "town02", "dynamic", "test", 3, w, 40),
    "planar": lambda w: simulate_planar_sequence(jax.random.PRNGKey(10), 50, fix_dropout=0.3),
}


@pytest.mark.parametrize("name", sorted(GENERATORS))
def test_two_calls_are_bit_equal(name, world):
    first = GENERATORS[name](world)
    _churn()
    second = GENERATORS[name](world)
    _equal(first, second)


def test_worlds_are_bit_equal():
    _equal(World.create("town03", size=256), World.create("town03", size=256))
