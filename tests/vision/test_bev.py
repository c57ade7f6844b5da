"""Camera and BEV projection: geometry against OpenCV, a render-and-project round trip at known
pitch and roll, the valid region and scale, batching, gradients and bad input."""

import cv2
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import (
    Camera,
    level_to_body,
    level_to_camera,
    project_ground_points,
)
from jbevo.vision.bev import bev_increment, bev_project

KITTI = Camera.kitti()
GRID = BevGrid(resolution=0.05, shape=(200, 160), near=5.0)  # 5-15 m ahead, +-4 m lateral
BLOB_SIGMA = 0.15  # metres
project_jit = eqx.filter_jit(bev_project)


def render(camera: Camera, pitch: float, roll: float, texture) -> np.ndarray:
    """The image of the ground ``texture(x, y)`` (level frame) seen at ``pitch`` and ``roll``:
    cast each pixel's ray to the ground plane (independent of the homography code)."""
    h, w = camera.image_shape
    k = np.asarray(camera.intrinsics, float)
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(k).T
    r_cl = np.asarray(level_to_camera(camera, pitch, roll), float)
    d = rays @ r_cl  # level-frame directions (R^T d_cam, row-vector form)
    down = d[..., 2] < -1e-9
    s = np.where(down, float(camera.height) / np.where(down, -d[..., 2], 1.0), 0.0)
    return np.where(down, texture(s * d[..., 0], s * d[..., 1]), 0.0)


def blobs(x, y):
    """Gaussian blobs of BLOB_SIGMA at every integer (x, y) metre."""
    dx, dy = x - np.round(x), y - np.round(y)
    return np.exp(-(dx**2 + dy**2) / (2 * BLOB_SIGMA**2))


def blob_errors(bev: np.ndarray, valid: np.ndarray, grid: BevGrid) -> np.ndarray:
    """Pixel offsets (row, col) between each fully visible blob's centroid and where it should be."""
    half = int(np.ceil(3.5 * BLOB_SIGMA / grid.resolution))
    errors = []
    for x in range(0, 30):
        for y in range(-10, 11):
            row = grid.origin[0] - x / grid.resolution
            col = grid.origin[1] - y / grid.resolution
            r0, c0 = int(round(row)), int(round(col))
            if r0 - half < 0 or c0 - half < 0 or r0 + half >= grid.shape[0] or c0 + half >= grid.shape[1]:
                continue
            win = bev[r0 - half : r0 + half + 1, c0 - half : c0 + half + 1]
            if not valid[r0 - half : r0 + half + 1, c0 - half : c0 + half + 1].all():
                continue
            rr, cc = np.mgrid[r0 - half : r0 + half + 1, c0 - half : c0 + half + 1]
            m = win.sum()
            errors.append([(win * rr).sum() / m - row, (win * cc).sum() / m - col])
    return np.asarray(errors)


def test_projection_matches_opencv():
    xy = np.array([[5.0, 0.0], [8.0, 2.5], [12.0, -3.0], [20.0, 6.0]])
    for pitch, roll in [(0.0, 0.0), (0.05, -0.03), (-0.08, 0.07)]:
        uv, front = project_ground_points(KITTI, pitch, roll, jnp.asarray(xy, jnp.float32))
        r = np.asarray(level_to_camera(KITTI, pitch, roll), float)
        centre = np.array([0.0, 0.0, float(KITTI.height)])
        pts = np.concatenate([xy, np.zeros((len(xy), 1))], 1)
        ref, _ = cv2.projectPoints(pts, cv2.Rodrigues(r)[0], -r @ centre, np.asarray(KITTI.intrinsics, float), None)
        np.testing.assert_allclose(uv, ref[:, 0], atol=1e-3)
        assert bool(jnp.all(front))


def test_positive_pitch_is_nose_down_and_positive_roll_lowers_the_right_side():
    # Nose down: a ground point ahead moves up in the image (smaller v).
    uv0, _ = project_ground_points(KITTI, 0.0, 0.0, jnp.array([[10.0, 0.0]]))
    uvp, _ = project_ground_points(KITTI, 0.05, 0.0, jnp.array([[10.0, 0.0]]))
    assert float(uvp[0, 1]) < float(uv0[0, 1])
    # The body x axis expressed in the level frame points down for a positive pitch.
    assert float(level_to_body(0.1, 0.0)[2, 0]) < 0
    # Positive roll: the body y (left) axis rises, the right side goes down.
    assert float(level_to_body(0.0, 0.1)[2, 1]) > 0


@pytest.mark.parametrize("pitch_deg, roll_deg", [(0.0, 0.0), (3.0, -2.0), (-5.0, 5.0), (5.0, 5.0), (-5.0, -5.0)])
def test_render_then_project_recovers_the_ground_texture(pitch_deg, roll_deg):
    pitch, roll = np.radians(pitch_deg), np.radians(roll_deg)
    image = render(KITTI, pitch, roll, blobs)
    bev, valid = project_jit(jnp.asarray(image, jnp.float32), jnp.float32(pitch), jnp.float32(roll), KITTI, GRID)
    errors = blob_errors(np.asarray(bev), np.asarray(valid), GRID)
    assert len(errors) >= 10
    rms = np.sqrt(np.mean(np.sum(errors**2, axis=1)))
    print(f"blob RMS {rms:.3f} px over {len(errors)} blobs")
    assert rms <= 0.5, rms
    # Projected with the wrong attitude the blobs land elsewhere: the test can fail.
    wrong, wrong_valid = project_jit(jnp.asarray(image, jnp.float32), jnp.float32(pitch + 0.02), jnp.float32(roll), KITTI, GRID)
    off = blob_errors(np.asarray(wrong), np.asarray(wrong_valid), GRID)
    assert np.sqrt(np.mean(np.sum(off**2, axis=1))) > 1.0


def test_valid_region_and_scale_at_zero_attitude():
    grid = BevGrid(resolution=0.1, shape=(100, 81), near=2.0)
    _, valid = bev_project(jnp.zeros(KITTI.image_shape), 0.0, 0.0, KITTI, grid)
    valid = np.asarray(valid)
    # The bottom image row sees the ground at x = h f / (H - 1 - cy) ahead.
    k = np.asarray(KITTI.intrinsics)
    x_near = 1.65 * k[1, 1] / (KITTI.image_shape[0] - 1 - k[1, 2])
    x = (grid.origin[0] - np.arange(grid.shape[0])) * grid.resolution
    centre = int(round(grid.origin[1]))
    assert np.all(valid[x > x_near + 1e-3, centre]) and not np.any(valid[x < x_near - 1e-3, centre])
    # The lateral edge follows the horizontal field of view: |y| <= x (cx or W-1-cx) / f.
    row = int(np.argmin(np.abs(x - 9.0)))
    y = (grid.origin[1] - np.arange(grid.shape[1])) * grid.resolution
    inside = (y <= x[row] * k[0, 2] / k[0, 0]) & (-y <= x[row] * (KITTI.image_shape[1] - 1 - k[0, 2]) / k[0, 0])
    np.testing.assert_array_equal(valid[row], inside)
    np.testing.assert_allclose(grid.ground_points()[0, 0], [grid.origin[0] * 0.1, grid.origin[1] * 0.1], rtol=1e-6)


def test_batched_frames_equal_single_frames():
    rng = np.random.default_rng(0)
    small = Camera(200.0, 200.0, 80.0, 10.0, (64, 160), 1.5)
    grid = BevGrid(0.1, (48, 48), near=6.0)
    images = jnp.asarray(rng.random((3, 64, 160)), jnp.float32)
    pitch = jnp.array([0.0, 0.03, -0.05], jnp.float32)
    roll = jnp.array([0.02, -0.04, 0.0], jnp.float32)
    batch, valid = jax.vmap(bev_project, in_axes=(0, 0, 0, None, None))(images, pitch, roll, small, grid)
    for i in range(3):
        one, one_valid = bev_project(images[i], pitch[i], roll[i], small, grid)
        np.testing.assert_allclose(batch[i], one, atol=1e-6)
        np.testing.assert_array_equal(valid[i], one_valid)
    assert valid.any()


def test_gradients_with_respect_to_pitch_roll_and_image(float64):
    small = Camera(200.0, 200.0, 80.0, 10.0, (64, 160), 1.5)
    grid = BevGrid(0.1, (32, 32), near=6.0)
    u, v = np.meshgrid(np.arange(160.0), np.arange(64.0))
    image = jnp.asarray(np.sin(u / 7.0) * np.cos(v / 5.0) + 0.3 * np.sin((u + v) / 11.0))  # smooth, float64
    weights = jnp.asarray(np.random.default_rng(1).normal(size=grid.shape))

    def loss(pitch, roll, image):
        bev, _ = bev_project(image, pitch, roll, small, grid)
        return jnp.sum(bev * weights)

    args = (jnp.float64(0.02), jnp.float64(-0.01), image)
    g = jax.grad(loss, argnums=(0, 1, 2))(*args)
    assert all(np.all(np.isfinite(x)) for x in g)
    assert abs(float(g[0])) > 0 and abs(float(g[1])) > 0 and float(jnp.abs(g[2]).sum()) > 0
    eps = 1e-6
    for i in (0, 1):
        plus = list(args)
        minus = list(args)
        plus[i] = args[i] + eps
        minus[i] = args[i] - eps
        fd = (loss(*plus) - loss(*minus)) / (2 * eps)
        assert float(g[i]) == pytest.approx(float(fd), rel=1e-3)


def test_bad_input_is_named(as_users_run):
    with pytest.raises(ValueError, match="camera's shape"):
        bev_project(jnp.zeros((10, 10)), 0.0, 0.0, KITTI, GRID)
    with pytest.raises(ValueError, match="height must be positive"):
        Camera(1.0, 1.0, 0.0, 0.0, (10, 10), 0.0)
    with pytest.raises(ValueError, match="resolution must be positive"):
        BevGrid(resolution=0.0)


BEV_GRID = BevGrid(0.1, (64, 64), near=7.5)


def test_increment_inverts_the_bev_motion_of_ground_points():
    """DPC's (rotation, translation) between two BEVs -> body increment, checked point by point:
    ground points seen from the earlier pose, moved by the increment, must land where DPC's
    image transform puts their pixels."""
    rng = np.random.default_rng(0)
    res, (o_row, o_col) = BEV_GRID.resolution, BEV_GRID.origin
    centre = np.array([(BEV_GRID.shape[1] - 1) / 2, (BEV_GRID.shape[0] - 1) / 2])
    for _ in range(5):
        theta, t = rng.uniform(-0.1, 0.1), rng.uniform(-8, 8, 2)
        dx, dy, dyaw = np.asarray(bev_increment(BEV_GRID, jnp.float32(theta), jnp.asarray(t, jnp.float32)), float)
        q0 = rng.uniform(5, 15, (10, 2))  # level-frame ground points (x forward, y left)
        p0 = np.stack([o_col - q0[:, 1] / res, o_row - q0[:, 0] / res], -1)  # (col, row)
        r_img = np.array([[np.cos(theta), np.sin(theta)], [-np.sin(theta), np.cos(theta)]])
        p1 = (p0 - centre) @ r_img.T + centre + t
        q1 = np.stack([(o_row - p1[:, 1]) * res, (o_col - p1[:, 0]) * res], -1)
        c, s = np.cos(dyaw), np.sin(dyaw)
        expected = (q0 - [dx, dy]) @ np.array([[c, -s], [s, c]])  # R(dyaw)^T (q0 - d)
        np.testing.assert_allclose(q1, expected, atol=1e-4)
        assert dyaw == pytest.approx(-theta, abs=1e-6)
