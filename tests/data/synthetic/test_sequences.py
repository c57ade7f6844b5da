"""Synthetic sequences end to end: the Sequence pytree, windows and splits, file round trip,
conditions, maps and the command line."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo import data
from jbevo.cli.render import main
from jbevo.data.pose_files import read_kitti
from jbevo.data.synthetic.conditions import CONDITIONS
from jbevo.data.synthetic.maps import render_map
from jbevo.data.synthetic.sequences import (
    kitti_sequence,
    procedural_sequence,
    small_camera,
)
from jbevo.data.synthetic.world import World
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import Camera
from jbevo.vision.bev import bev_project


@pytest.fixture(scope="module")
def world():
    return World.create("town01", size=512)


@pytest.fixture(scope="module")
def camera():
    return Camera(60.0, 60.0, 47.5, 15.5, (32, 96), 1.65)


@pytest.fixture(scope="module")
def seq(world, camera):
    return procedural_sequence(5, 24, camera=camera, world=world)


def test_sequence_layout_and_truth(seq):
    assert seq.images.shape == (24, 32, 96) and seq.images.dtype == jnp.uint8
    assert seq.gyro.shape == seq.accel.shape == (24, 10, 3) and seq.imu_times.shape == (24, 10)
    np.testing.assert_allclose(np.diff(seq.frame_times), 0.1, atol=1e-5)
    # IMU block t covers [frame t-1, frame t)
    np.testing.assert_allclose(seq.imu_times[1:, 0], seq.frame_times[:-1], atol=1e-5)
    assert seq.imu_dt == pytest.approx(0.01, abs=1e-6)
    # at rest the specific force is about +g along body z; here driving: mean close to g
    assert 9.0 < float(jnp.mean(seq.accel[..., 2])) < 10.6
    assert seq.planar.shape == (24, 3) and seq.pitch_roll.shape == (24, 2)
    assert float(jnp.max(jnp.abs(seq.pitch_roll))) < np.radians(5)


def test_same_seed_same_sequence_and_different_seed_differs(seq, world, camera):
    again = procedural_sequence(5, 24, camera=camera, world=world)
    np.testing.assert_array_equal(seq.images, again.images)
    np.testing.assert_array_equal(seq.gyro, again.gyro)
    other = procedural_sequence(6, 24, camera=camera, world=world)
    assert not np.array_equal(seq.images, other.images)


def test_windows_stack_and_vmap(seq):
    batch = data.windows(seq, 8, stride=4)
    assert batch.images.shape == (5, 8, 32, 96) and batch.camera.intrinsics.shape == (5, 3, 3)
    np.testing.assert_array_equal(batch.gyro[2], seq.gyro[8:16])
    lengths = jax.vmap(lambda s: jnp.sum(jnp.linalg.norm(jnp.diff(s.planar[:, :2], axis=0), axis=1)))(batch)
    assert lengths.shape == (5,) and bool(jnp.all(lengths > 0))
    train, val, test = data.split_quarters(seq)
    assert (train.num_frames, val.num_frames, test.num_frames) == (12, 6, 6)
    np.testing.assert_array_equal(test.frame_times, seq.frame_times[18:])
    with pytest.raises(ValueError, match="windows"):
        data.windows(seq, 25)
    with pytest.raises(ValueError, match="sequence 1"):
        data.stack([seq, data.window(seq, 0, 10)])


def test_save_load_round_trip_and_bad_files(seq, tmp_path):
    path = tmp_path / "seq.npz"
    data.save(seq, path)
    back = data.load(path)
    for name in ("images", "frame_times", "imu_times", "gyro", "accel", "poses"):
        np.testing.assert_array_equal(getattr(back, name), getattr(seq, name))
    np.testing.assert_allclose(back.camera.intrinsics, seq.camera.intrinsics)
    with pytest.raises(FileNotFoundError):
        data.load(tmp_path / "missing.npz")
    path.write_bytes(path.read_bytes()[:200])
    with pytest.raises(ValueError, match="not a readable sequence"):
        data.load(path)


def test_check_names_the_bad_field(as_users_run, seq):
    bad = data.Sequence(seq.images[:-1], seq.frame_times, seq.imu_times, seq.gyro, seq.accel, seq.camera, seq.poses)
    with pytest.raises(ValueError, match="images"):
        data.check(bad)
    times = seq.frame_times.at[3].set(seq.frame_times[2])
    with pytest.raises(ValueError, match="frame_times"):
        data.check(data.Sequence(seq.images, times, seq.imu_times, seq.gyro, seq.accel, seq.camera, seq.poses))


@pytest.mark.parametrize("name", ["night", "fog", "rain", "dynamic"])
def test_conditions_change_the_images(seq, world, camera, name):
    other = procedural_sequence(5, 24, camera=camera, world=world, condition=name)
    diff = np.abs(np.asarray(other.images, float) - np.asarray(seq.images, float))
    assert diff.mean() > 2.0
    np.testing.assert_array_equal(other.gyro, seq.gyro)  # only the images change
    if name == "night":
        assert other.images.mean() < 0.5 * seq.images.mean()
    with pytest.raises(ValueError, match="unknown condition"):
        procedural_sequence(5, 4, camera=camera, world=world, condition="snow")


def test_map_matches_the_bev_at_the_true_pose(world):
    """A BEV of a level, noiseless frame correlates with the map crop at the true pose."""
    camera = small_camera()
    seq = procedural_sequence(2, 12, camera=camera, world=world, condition="day")
    grid = BevGrid(0.2, (64, 64), near=4.0)
    t = 10
    bev, valid = bev_project(seq.images[t].astype(jnp.float32) / 255, *seq.pitch_roll[t], camera, grid)
    m = render_map(world, np.asarray(seq.planar[:, :2]), resolution=0.2, style="drone")
    x, y, yaw = np.asarray(seq.planar[t], float)
    ground = np.asarray(grid.ground_points())  # level frame (x forward, y left)
    c, s = np.cos(yaw), np.sin(yaw)
    world_xy = np.stack([x + c * ground[..., 0] - s * ground[..., 1], y + s * ground[..., 0] + c * ground[..., 1]], -1)
    rc = np.asarray(m.world_to_pixel(jnp.asarray(world_xy)))
    crop = np.asarray(m.image, float)[np.round(rc[..., 0]).astype(int), np.round(rc[..., 1]).astype(int)]
    mask = np.asarray(valid)
    corr = np.corrcoef(np.asarray(bev)[mask], crop[mask])[0, 1]
    shifted = np.asarray(m.image, float)[np.round(rc[..., 0]).astype(int) + 15, np.round(rc[..., 1]).astype(int)]
    assert corr > 0.5 and corr > 2 * abs(np.corrcoef(np.asarray(bev)[mask], shifted[mask])[0, 1])


def test_kitti_sequence_follows_the_real_motion(reference_data, world, camera):
    kitti = read_kitti(reference_data / "kitti_odom" / "gt_poses" / "04.txt").poses
    seq = kitti_sequence(kitti, start=10, frames=20, camera=camera, world=world)
    assert seq.num_frames == 20
    # 04 drives straight ahead at ~14 m/s
    speed = np.linalg.norm(np.diff(np.asarray(seq.planar[:, :2]), axis=0), axis=1) / 0.1
    assert 10 < speed.mean() < 20
    with pytest.raises(ValueError, match="do not fit"):
        kitti_sequence(kitti, start=260, frames=20, camera=camera, world=world)


def test_command_line_writes_a_loadable_sequence(tmp_path, capsys):
    out = tmp_path / "cli.npz"
    main(["--out", str(out), "--frames", "3", "--seed", "1"])
    assert "wrote" in capsys.readouterr().out
    assert data.load(out).num_frames == 3
    assert list(CONDITIONS) == ["day", "night", "fog", "rain", "dynamic"]
