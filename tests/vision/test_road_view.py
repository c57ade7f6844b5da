"""The road view (jbevo.vision.road_view): a camera mounted off the body's axes and higher than
assumed is undone by the road view's pitch and height (a drive rendered that way, read with the
nominal camera, comes back to scale); the corridor fades the columns beside the lane; gradients
through the projection match finite differences."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.imu import NOISELESS
from jbevo.data.synthetic.sequences import make_sequence, small_camera
from jbevo.data.synthetic.world import World
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import FORWARD, level_to_body
from jbevo.geometry.euler import poses_from_euler
from jbevo.models.bevo import Bevo
from jbevo.models.losses import relative_motion
from jbevo.vision.bev import feathered_bev
from jbevo.vision.road_view import RoadView
from tests.helpers import check_leaf_gradients

GRID = BevGrid(0.1, (64, 64), near=7.5)
MOUNT_PITCH = np.radians(1.0)
TRUE_HEIGHT = 1.8


def _drive(mount_pitch: float, height: float):
    """A level straight drive at 0.8 m per frame seen by a camera pitched ``mount_pitch`` down
    against the body at ``height``, read back with the nominal camera (level, 1.65 m)."""
    nominal = small_camera()
    mounted = eqx.tree_at(
        lambda c: (c.rotation_body_to_camera, c.height),
        nominal,
        (jnp.asarray(FORWARD, jnp.float32) @ level_to_body(jnp.float32(mount_pitch), jnp.float32(0.0)).T, jnp.float32(height)),
    )
    n = 7
    x = 20.0 + 0.8 * np.arange(n)
    poses = poses_from_euler(np.zeros((n, 3)), np.stack([x, np.full(n, 30.0), np.full(n, height)], -1))
    seq = make_sequence(World.create("town01", size=512), mounted, np.arange(n) * 0.1, poses, "day", NOISELESS)
    return eqx.tree_at(lambda s: s.camera, seq, nominal)


def _forward_ratio(model, seq):
    out = eqx.filter_jit(lambda m, s: m(s, warm_start=True))(model, seq)
    return float(jnp.sum(out.increments[1:, 0]) / jnp.sum(relative_motion(seq)[1:, 0]))


def test_the_road_view_undoes_a_mounting_pitch_and_height():
    """Against the same drive seen by the nominal camera (DPC's own bias on this small BEV is a
    few percent), a camera 1 deg nose down and 9 % higher than assumed lengthens the motion by
    7 % (the pitch: +22 %, the height: -7 %); the road view with those values restores it, and
    the opposite pitch doubles the error (the sign is the projection's)."""
    base = Bevo.create(GRID, attitude_source="truth")
    reference = _forward_ratio(base, _drive(0.0, 1.65))
    mounted = _drive(MOUNT_PITCH, TRUE_HEIGHT)
    assert _forward_ratio(base, mounted) - reference > 0.08
    view = RoadView.create(pitch=MOUNT_PITCH, height_scale=TRUE_HEIGHT / 1.65, corridor=50.0)
    assert _forward_ratio(dataclasses.replace(base, road=view), mounted) == pytest.approx(reference, abs=0.02)
    wrong = RoadView.create(pitch=-MOUNT_PITCH, height_scale=TRUE_HEIGHT / 1.65, corridor=50.0)
    assert _forward_ratio(dataclasses.replace(base, road=wrong), mounted) - reference > 0.3


def test_offsets_height_and_corridor():
    view = RoadView.create(pitch=0.01, roll=-0.02, height_scale=1.1, corridor=2.0)
    np.testing.assert_allclose(view.attitude(jnp.array([0.1, 0.2])), [0.11, 0.18], atol=1e-7)
    assert float(view.height(small_camera())) == pytest.approx(1.1 * float(small_camera().height), rel=1e-6)
    grid = BevGrid(0.1, (8, 81), near=4.0)  # columns from +4 m (left) to -4 m
    w = np.asarray(view.corridor_weight(grid))
    y = np.asarray(grid.ground_points()[0, :, 1])
    assert w[np.argmin(np.abs(y))] > 0.99 and w[0] < 1e-4 and w[-1] < 1e-4
    assert w[np.argmin(np.abs(y - 2.0))] == pytest.approx(0.5, abs=0.01)
    bev = jnp.asarray(np.random.default_rng(0).random((8, 81)), jnp.float32)
    kept = view.keep_road(bev, grid)
    np.testing.assert_allclose(kept[:, 0], float(jnp.mean(bev)), atol=1e-4)
    np.testing.assert_allclose(kept[:, 40], bev[:, 40], atol=1e-3)
    for bad in ({"height_scale": 0.0}, {"corridor": -1.0}, {"corridor_edge": 0.0}):
        with pytest.raises(ValueError, match="positive"):
            RoadView.create(**bad)


def test_projection_with_the_road_view_equals_the_offset_projection():
    camera = small_camera()
    image = jnp.asarray(np.random.default_rng(1).integers(0, 255, camera.image_shape), jnp.uint8)
    view = RoadView.create(pitch=0.01, roll=0.005, height_scale=1.05, corridor=100.0)
    model = dataclasses.replace(Bevo.create(GRID), road=view)
    got = model.bev(image, jnp.array([0.02, -0.01]), camera)
    want = feathered_bev(image, jnp.float32(0.03), jnp.float32(-0.005), view.camera(camera), GRID, model.feather)
    np.testing.assert_allclose(got, want, atol=1e-5)


def test_gradients_through_the_projection_match_finite_differences(float64):
    camera = small_camera()
    # A smooth texture: bilinear sampling of pixel noise has kinks finite differences trip on.
    rows, cols = np.mgrid[0 : camera.image_shape[0], 0 : camera.image_shape[1]]
    image = jnp.asarray(127 + 60 * np.sin(cols / 9.0) * np.cos(rows / 7.0) + 40 * np.sin((cols + 2 * rows) / 23.0), jnp.uint8)
    target = jnp.asarray(np.random.default_rng(3).random(GRID.shape))
    base = Bevo.create(GRID)
    view = RoadView.create(pitch=0.01, roll=0.005, height_scale=1.05, corridor=2.0)

    def value(v):
        bev = dataclasses.replace(base, road=v).bev(image, jnp.array([0.01, 0.0]), camera)
        return jnp.sum((bev - target) ** 2)

    grads = jax.grad(value)(view)
    assert check_leaf_gradients(jax.jit(value), grads, view, abs_tol=1e-6, eps=1e-6) == 4
