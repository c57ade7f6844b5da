"""The renderer: a known world point lands on the pixel the pinhole model predicts."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.render import SKY_HORIZON, render, render_batch
from jbevo.data.synthetic.sequences import small_camera
from jbevo.data.synthetic.world import World
from jbevo.geometry.euler import rotation_zyx


def _blob_world():
    r, c = np.mgrid[:256, :256]
    tile = 0.2 + 0.7 * np.exp(-((r - 128) ** 2 + (c - 64) ** 2) / (2 * 5.0**2))
    return World.from_tile(tile, 0.04)  # blob at world (x, y) = (2.56, 5.12) modulo 10.24 m


def _pose(x, y, z, yaw, pitch, roll):
    pose = np.eye(4)
    pose[:3, :3] = rotation_zyx(np.array([yaw, pitch, roll]))
    pose[:3, 3] = (x, y, z)
    return pose


@pytest.mark.parametrize("angles_deg", [(0.0, 0.0, 0.0), (20.0, 4.0, -3.0), (-35.0, 3.0, 5.0)])
def test_known_world_point_lands_on_the_predicted_pixel(angles_deg):
    camera = small_camera()
    yaw, pitch, roll = np.radians(angles_deg)
    pose = _pose(2.56 - 8.0 * np.cos(yaw), 5.12 - 8.0 * np.sin(yaw), 1.6, yaw, pitch, roll)
    image = np.asarray(jax.jit(render)(_blob_world(), camera, jnp.asarray(pose, jnp.float32)))
    # Independent pinhole projection of the blob's centre.
    r_cw = np.asarray(camera.rotation_body_to_camera) @ pose[:3, :3].T
    p = np.asarray(camera.intrinsics) @ (r_cw @ (np.array([2.56, 5.12, 0.0]) - pose[:3, 3]))
    u, v = p[0] / p[2], p[1] / p[2]
    rows, cols = np.mgrid[int(v) - 12 : int(v) + 13, int(u) - 12 : int(u) + 13]
    w = np.clip(image[rows, cols] - 0.3, 0.0, None)
    assert w.sum() > 1.0
    centroid = (np.sum(w * cols) / w.sum(), np.sum(w * rows) / w.sum())
    np.testing.assert_allclose(centroid, (u, v), atol=0.35)


def test_sky_above_the_horizon_and_batch_equals_single():
    camera = small_camera()
    world = World.create("town01", size=128)
    poses = jnp.asarray(np.stack([_pose(i, 0.5 * i, 1.65, 0.1 * i, 0.01, -0.01) for i in range(3)]), jnp.float32)
    batch = render_batch(world, camera, poses)
    assert batch.shape == (3, *camera.image_shape) and batch.dtype == jnp.float32
    np.testing.assert_allclose(batch[1], render(world, camera, poses[1]), atol=1e-4)
    assert float(batch[0, 0].min()) >= SKY_HORIZON - 1e-6  # top row looks above the horizon
    assert bool(jnp.all(jnp.isfinite(batch)))


def test_render_batch_names_bad_poses(as_users_run):
    with pytest.raises(ValueError, match="poses must have shape"):
        render_batch(World.create("town01", size=128), small_camera(), jnp.eye(4))
