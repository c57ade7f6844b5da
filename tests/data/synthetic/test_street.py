"""The street world (jbevo.data.synthetic.street, .structures): boxes beside the path and never on
it, ray casting against an independent pinhole projection, occlusion of the ground, slopes that
the truth and the IMU see and the images do not, the mounted camera, exposure and vignetting, and
synthetic copies of a drive."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.imu import NOISELESS
from jbevo.data.synthetic.maps import render_map
from jbevo.data.synthetic.render import render
from jbevo.data.synthetic.scenes import scene
from jbevo.data.synthetic.sequences import frame_rate, make_sequence, procedural_sequence, small_camera, synthetic_copy
from jbevo.data.synthetic.street import (
    STREET,
    Street,
    exposure_gains,
    road_relative,
    road_tilt_profile,
    street_named,
    tilt_onto_road,
    vignette,
)
from jbevo.data.synthetic.structures import Boxes, nearest_boxes, place_structures
from jbevo.data.synthetic.trajectories import procedural_drive
from jbevo.data.synthetic.world import World
from jbevo.geometry.euler import euler_zyx, poses_from_euler


@pytest.fixture(scope="module")
def world():
    return World.create("town01", size=512)


@pytest.fixture(scope="module")
def drive():
    return procedural_drive(4, 300)


def _box(x, y, heading, half_l, half_w, z0, z1) -> Boxes:
    f = lambda *v: jnp.asarray([v], jnp.float32)
    return Boxes(f(x, y), f(heading)[0], f(half_l, half_w), f(z0, z1), f(0.9)[0], f(0.0)[0], f(0.0, 0.0), f(1.0)[0])


def test_structures_line_the_path_and_never_stand_on_it(drive):
    _, poses = drive
    boxes = place_structures(poses, STREET, seed=1)
    again = place_structures(poses, STREET, seed=1)
    assert all(np.array_equal(a, b) for a, b in zip(boxes, again))
    assert len(boxes.heading) > 50
    assert set(np.unique(boxes.facade)) == {0.0, 1.0}
    # No path point inside any box grown by 1 m (placement keeps 1.2 m).
    path = poses[:, :2, 3]
    rel = path[None] - boxes.centre[:, None]
    c, s = np.cos(boxes.heading)[:, None], np.sin(boxes.heading)[:, None]
    u, v = rel[..., 0] * c + rel[..., 1] * s, -rel[..., 0] * s + rel[..., 1] * c
    inside = (np.abs(u) < boxes.half[:, :1] + 1.0) & (np.abs(v) < boxes.half[:, 1:] + 1.0)
    assert not inside.any()
    bare = dataclasses.replace(STREET, facades=False, parked_car_probability=0.0, poles_per_metre=0.0, kerb_height=0.0)
    assert len(place_structures(poses, bare, seed=1).heading) == 0


def test_each_frame_keeps_the_nearest_boxes_in_view(drive):
    _, poses = drive
    boxes = place_structures(poses, STREET, seed=1)
    chosen = nearest_boxes(boxes, poses, np.radians(45), k=16, reach=40.0)
    assert chosen.centre.shape == (len(poses), 16, 2) and chosen.valid.shape == (len(poses), 16)
    t = 200
    valid = chosen.valid[t] > 0
    assert valid.sum() > 0
    rel = chosen.centre[t, valid] - poses[t, :2, 3]
    # Kept boxes are within reach (of their footprint) and not wholly behind the camera.
    assert np.all(np.linalg.norm(rel, axis=1) - np.linalg.norm(chosen.half[t, valid], axis=1) < 40.0)
    forward = poses[t, :2, 0]
    assert np.all(rel @ forward + np.linalg.norm(chosen.half[t, valid], axis=1) > 0)
    # No boxes at all: every slot invalid.
    none = nearest_boxes(jax.tree_util.tree_map(lambda x: x[:0], boxes), poses[:3], k=4)
    assert none.valid.shape == (3, 4) and not none.valid.any()


def test_a_box_hides_the_ground_where_the_pinhole_model_puts_it(world):
    """A 2 m wide, 3 m tall wall 10 m ahead: the pixels inside its projected outline show the
    wall, those outside the ground as without it; its top edge falls on the predicted row."""
    camera = small_camera()
    pose = jnp.asarray(poses_from_euler(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.65]]))[0], jnp.float32)
    wall = _box(10.0, 0.0, 0.0, 0.1, 1.0, 0.0, 3.0)
    plain = np.asarray(render(world, camera, pose))
    walled = np.asarray(render(world, camera, pose, boxes=wall))
    k = np.asarray(camera.intrinsics, float)
    # Camera: x right, y down, z forward. The wall's front face is at 9.9 m.
    u_left, u_right = k[0, 2] - k[0, 0] * 1.0 / 9.9, k[0, 2] + k[0, 0] * 1.0 / 9.9
    v_top, v_bottom = k[1, 2] - k[1, 1] * (3.0 - 1.65) / 9.9, k[1, 2] + k[1, 1] * 1.65 / 9.9
    changed = np.abs(walled - plain) > 1e-6
    inner = changed[int(v_top) + 2 : int(v_bottom) - 1, int(u_left) + 2 : int(u_right) - 1]
    assert inner.mean() > 0.9
    outside = np.ones_like(changed)
    outside[int(v_top) - 1 : int(v_bottom) + 2, int(u_left) - 1 : int(u_right) + 2] = False
    assert not changed[outside].any()
    column = changed[:, int(k[0, 2])]
    assert abs(np.argmax(column) - v_top) <= 1.0


def test_a_box_behind_the_camera_or_invalid_changes_nothing(world):
    camera = small_camera()
    pose = jnp.asarray(poses_from_euler(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.65]]))[0], jnp.float32)
    plain = np.asarray(render(world, camera, pose))
    behind = _box(-10.0, 0.0, 0.0, 0.1, 1.0, 0.0, 3.0)
    invalid = behind._replace(centre=jnp.asarray([[10.0, 0.0]], jnp.float32), valid=jnp.zeros(1, jnp.float32))
    for boxes in (behind, invalid):
        np.testing.assert_array_equal(np.asarray(render(world, camera, pose, boxes=boxes)), plain)


def test_slopes_tilt_the_truth_and_not_the_view(drive):
    times, poses = drive
    tilt = road_tilt_profile(poses, STREET, seed=2)
    assert 0.4 < np.degrees(tilt[:, 0]).std() < 2.0  # a few hundred metres: around the 1 deg asked
    sloped = tilt_onto_road(poses, tilt)
    np.testing.assert_allclose(euler_zyx(sloped[:, :3, :3])[:, 1:], euler_zyx(poses[:, :3, :3])[:, 1:] + tilt, atol=1e-9)
    # Downhill (positive grade, nose down) loses height.
    const = np.tile([np.radians(2.0), 0.0], (len(poses), 1))
    down = tilt_onto_road(poses, const)
    travelled = np.sum(np.linalg.norm(np.diff(poses[:, :2, 3], axis=0), axis=1))
    assert down[-1, 2, 3] - poses[-1, 2, 3] == pytest.approx(-np.sin(np.radians(2.0)) * travelled, rel=1e-6)
    back = road_relative(sloped, tilt, poses[:, 2, 3])
    np.testing.assert_allclose(back, poses, atol=1e-9)


def test_a_street_sequence_keeps_the_slope_in_the_truth_and_imu(world):
    """The same drive on a level and on a 2 deg downhill road: the truth's pitch and the
    accelerometer's gravity differ by the grade, the images (against the road) barely."""
    camera = small_camera()
    n = 12
    x = 0.8 * np.arange(n)
    poses = poses_from_euler(np.zeros((n, 3)), np.stack([x, np.zeros(n), np.full(n, 1.65)], -1))
    quiet = Street(facades=False, parked_car_probability=0.0, poles_per_metre=0.0, kerb_height=0.0,
                   mount_pitch_deg=0.0, mount_roll_deg=0.0, height_error=0.0, exposure_std=0.0, vignetting=0.0,
                   ground_contrast=1.0)  # fmt: skip
    grade = np.tile([np.radians(2.0), 0.0], (n, 1))
    times = np.arange(n) * 0.1
    level = make_sequence(world, camera, times, poses, "day", NOISELESS, street=dataclasses.replace(quiet, slopes=False))
    sloped = make_sequence(world, camera, times, poses, "day", NOISELESS, street=quiet, road_tilt=grade)
    pitch_gap = np.degrees(np.asarray(sloped.pitch_roll[:, 0] - level.pitch_roll[:, 0]))
    np.testing.assert_allclose(pitch_gap, 2.0, atol=0.01)
    # Gravity in the body frame: a nose-down body sees it tilted forward (specific force x < 0).
    fx = np.nanmean(np.asarray(sloped.accel[..., 0]))
    assert fx == pytest.approx(-9.81 * np.sin(np.radians(2.0)), abs=0.05)
    image_gap = np.abs(np.asarray(sloped.images, float) - np.asarray(level.images, float)).mean()
    assert image_gap < 2.0  # grey levels: the same view of the road
    flat_world = make_sequence(world, camera, times, poses, "day", NOISELESS)
    assert np.abs(np.asarray(flat_world.pitch_roll)).max() < 1e-4


def test_the_mounted_camera_exposure_and_vignetting_change_only_the_images(world):
    seq = procedural_sequence(3, 6, world=world)
    street = procedural_sequence(3, 6, world=world, street=STREET)
    assert not np.array_equal(np.asarray(seq.images), np.asarray(street.images))
    assert eqx.tree_equal(seq.camera, street.camera)  # the sequence keeps the nominal camera
    gains = exposure_gains(500, STREET, seed=0)
    assert np.log(gains).std() == pytest.approx(STREET.exposure_std, rel=1e-3)
    assert np.abs(np.diff(np.log(gains))).max() < 0.05  # smooth from frame to frame
    falloff = np.asarray(vignette(small_camera(), 0.3))
    assert falloff.max() <= 1.0 and falloff.min() == pytest.approx(0.7, abs=1e-6)
    assert street_named("flat") is None and street_named("street") is STREET
    with pytest.raises(ValueError, match="unknown world"):
        street_named("moon")


def test_a_synthetic_copy_keeps_the_drive_and_replaces_the_images(world):
    source = procedural_sequence(5, 10, world=world)
    flat = synthetic_copy(source, world)
    street = synthetic_copy(source, world, STREET)
    for copy in (flat, street):
        for field in ("frame_times", "imu_times", "gyro", "accel", "poses"):
            np.testing.assert_array_equal(np.asarray(getattr(copy, field)), np.asarray(getattr(source, field)))
    # The flat copy renders what the source saw (same attitude over the same plane, noise aside).
    assert np.abs(np.asarray(flat.images, float) - np.asarray(source.images, float)).mean() < 3.0
    assert np.abs(np.asarray(street.images, float) - np.asarray(source.images, float)).mean() > 5.0
    broken = eqx.tree_at(lambda s: s.poses, source, source.poses.at[3, 0, 3].set(jnp.nan))
    with pytest.raises(ValueError, match="NaN"):
        synthetic_copy(broken, world)


def test_a_copy_takes_the_frame_rate_of_its_drive(world, monkeypatch):
    # KITTI's camera runs at 9.6 Hz, not 10: the road's 2 s low-pass and the exposure's 1.5 s
    # walk are set in seconds, so their width in frames follows the drive's own rate.
    import jbevo.data.synthetic.sequences as sequences

    seen = {}
    road_tilt, gains = sequences.recorded_road_tilt, sequences.exposure_gains

    def road_tilt_spy(body_poses, frame_rate=10.0, **kwargs):
        seen["road"] = frame_rate
        return road_tilt(body_poses, frame_rate, **kwargs)

    def gains_spy(frames, street, seed, frame_rate=10.0):
        seen["exposure"] = frame_rate
        return gains(frames, street, seed, frame_rate)

    monkeypatch.setattr(sequences, "recorded_road_tilt", road_tilt_spy)
    monkeypatch.setattr(sequences, "exposure_gains", gains_spy)
    source = procedural_sequence(5, 6, world=world)
    at_20_hz = eqx.tree_at(lambda s: s.frame_times, source, source.frame_times[0] + 0.05 * jnp.arange(6))
    synthetic_copy(at_20_hz, world, STREET)
    assert seen == {"road": pytest.approx(20.0), "exposure": pytest.approx(20.0)}

    kitti_like = 0.1038752 * np.arange(50)
    assert frame_rate(kitti_like) == pytest.approx(1 / 0.1038752)
    assert frame_rate(0.05 * np.arange(5)) == pytest.approx(20.0)
    assert frame_rate(np.array([3.0])) == 10.0
    with pytest.raises(ValueError, match="increase"):
        frame_rate(np.array([1.0, 1.0, 1.0]))
    slow, fast = exposure_gains(400, STREET, 0, frame_rate=5.0), exposure_gains(400, STREET, 0, frame_rate=20.0)
    assert np.abs(np.diff(np.log(slow))).mean() > 2 * np.abs(np.diff(np.log(fast))).mean()


def test_the_map_shows_the_tops_of_the_structures(world):
    """The same map with and without a 4 m x 2 m box: they differ exactly on its footprint."""
    box = jax.tree_util.tree_map(np.asarray, _box(10.0, 5.0, np.radians(30.0), 2.0, 1.0, 0.0, 1.5))
    box = box._replace(shade=np.array([0.02], np.float32))  # a dark roof on the bright ground
    xy = np.array([[0.0, 0.0], [20.0, 10.0]])
    plain = np.asarray(render_map(world, xy, 0.1, 5.0, "drone", seed=3).image, float)
    roofed_map = render_map(world, xy, 0.1, 5.0, "drone", seed=3, structures=box)
    roofed = np.asarray(roofed_map.image, float)
    changed = np.abs(roofed - plain) > 0
    rows, cols = np.nonzero(changed)
    x = roofed_map.x_max - rows * 0.1 - 10.0
    y = roofed_map.y_max - cols * 0.1 - 5.0
    h = np.radians(30.0)
    u, v = x * np.cos(h) + y * np.sin(h), -x * np.sin(h) + y * np.cos(h)
    assert np.all((np.abs(u) <= 2.0 + 1e-6) & (np.abs(v) <= 1.0 + 1e-6))
    assert changed.sum() > 0.8 * (4.0 * 2.0) / 0.1**2


def test_a_street_scene_renders_with_its_map(world):
    flat = scene("carla", "town01", "day", "train", 0, world, frames=40)
    street = scene("carla", "town01", "day", "train", 0, world, frames=40, street=STREET)
    assert street.sequence.num_frames == flat.sequence.num_frames
    assert not np.array_equal(np.asarray(street.map.image), np.asarray(flat.map.image))
    assert not np.array_equal(np.asarray(street.sequence.images), np.asarray(flat.sequence.images))
