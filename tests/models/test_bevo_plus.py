import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo import data
from jbevo.data.map import Map
from jbevo.data.splits import part_range
from jbevo.data.synthetic.scenes import SCENE_KINDS, scene
from jbevo.data.synthetic.world import World
from jbevo.eval.scores import pose_errors
from jbevo.filtering import ukf
from jbevo.filtering.planar import planar_pose_model
from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.se2 import se2_between, se2_compose
from jbevo.models.bevo_plus import BevoPlus
from jbevo.models.localization_smoother import smooth_localization
from jbevo.models.losses import localization_loss
from jbevo.models.presets import localization_model
from jbevo.vision.bands import BandGeometry
from jbevo.vision.bev import bev_project
from jbevo.vision.map_matching import map_crop, match_to_map
from tests.helpers import check_leaf_gradients


def kitti_planar(path):
    """(x, y, yaw) in a z-up world from KITTI camera-0 poses (camera: x right, y down, z forward)."""
    poses = np.loadtxt(path).reshape(-1, 3, 4)
    x, y = poses[:, 2, 3], -poses[:, 0, 3]  # forward, left
    yaw = np.arctan2(-poses[:, 0, 2], poses[:, 2, 2])  # heading of the camera's z axis
    return jnp.asarray(np.stack([x, y, yaw], axis=-1))


def test_model_composes_increments_and_wraps_yaw(float64):
    model = planar_pose_model()
    assert model is planar_pose_model()  # cached: one compilation for jitted callers
    out = model.motion(jnp.array([0.0, 0.0, np.pi - 0.1]), jnp.array([1.0, 0.0, 0.2]))
    np.testing.assert_allclose(out, [np.cos(np.pi - 0.1), np.sin(np.pi - 0.1), -np.pi + 0.1], atol=1e-12)


def test_fuses_real_kitti_motion_better_than_odometry_or_fixes_alone(reference_data):
    truth = kitti_planar(reference_data / "kitti_odom" / "gt_poses" / "09.txt")
    assert truth.shape == (1591, 3)
    true_inc = se2_between(truth[:-1], truth[1:])
    k_odo, k_fix, k_drop = jax.random.split(jax.random.PRNGKey(0), 3)
    odo_std, fix_std = jnp.array([0.05, 0.02, 0.002]), jnp.array([1.0, 1.0, 0.05])
    increments = true_inc + jax.random.normal(k_odo, true_inc.shape) * odo_std
    fixes = truth[1:] + jax.random.normal(k_fix, true_inc.shape) * fix_std
    fixes = fixes.at[:, 2].set(wrap_angle(fixes[:, 2]))
    fixes = jnp.where(jax.random.uniform(k_drop, (len(fixes), 1)) < 0.3, jnp.nan, fixes)

    res = ukf.filter(
        planar_pose_model(),
        ukf.GaussianState(truth[0], jnp.diag(fix_std**2)),
        increments,
        fixes,
        jnp.diag(odo_std**2),
        jnp.diag(fix_std**2),
    )
    filt_err = np.linalg.norm(np.asarray(res.filtered_mean[:, :2] - truth[1:, :2]), axis=1)
    fix_err = np.linalg.norm(np.asarray(fixes[:, :2] - truth[1:, :2]), axis=1)
    dead_reckoning = jax.lax.scan(lambda p, d: (se2_compose(p, d), se2_compose(p, d)), truth[0], increments)[1]
    odo_err = np.linalg.norm(np.asarray(dead_reckoning[:, :2] - truth[1:, :2]), axis=1)
    rmse = lambda e: float(np.sqrt(np.nanmean(e**2)))
    assert rmse(filt_err) < 0.6 * rmse(fix_err)
    assert rmse(filt_err) < 0.2 * rmse(odo_err)
    yaw_err = np.abs(np.asarray(wrap_angle(res.filtered_mean[:, 2] - truth[1:, 2])))
    assert np.degrees(yaw_err.mean()) < 1.0


# ----------------------------------------------------------------------------- BEVO+ on the map


@pytest.fixture(scope="module")
def world():
    return World.create("town02", size=512)


@pytest.fixture(scope="module")
def carla(world):
    """60 frames of a CARLA-style drive (the whole drive, day) and its satellite map."""
    return scene("carla", "town02", "day", "all", seed=1, world=world, frames=60)


def test_map_crop_samples_the_map_where_the_grid_lies():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (200, 300)).astype(np.uint8)
    m = Map(jnp.asarray(image), 30.0, 40.0, 0.25)
    grid = SCENE_KINDS["carla"].grids()[1]
    pose = jnp.array([12.3, 20.1, 0.4])
    crop, inside = map_crop(m, pose, grid)
    g = np.asarray(grid.ground_points(), float)
    c, s = np.cos(0.4), np.sin(0.4)
    wx, wy = 12.3 + c * g[..., 0] - s * g[..., 1], 20.1 + s * g[..., 0] + c * g[..., 1]
    r, k = (30.0 - wx) / 0.25, (40.0 - wy) / 0.25
    ok = (r >= 0) & (r <= 199) & (k >= 0) & (k <= 299)
    np.testing.assert_array_equal(np.asarray(inside), ok)
    r0, k0 = np.floor(r[ok]).astype(int), np.floor(k[ok]).astype(int)
    fr, fk = r[ok] - r0, k[ok] - k0
    im = image.astype(float)
    at = lambda dr, dk: im[np.minimum(r0 + dr, 199), np.minimum(k0 + dk, 299)]
    expected = (1 - fr) * ((1 - fk) * at(0, 0) + fk * at(0, 1)) + fr * ((1 - fk) * at(1, 0) + fk * at(1, 1))
    np.testing.assert_allclose(np.asarray(crop)[ok] * 255, expected, atol=5e-3)  # float32 against float64
    assert np.all(np.asarray(crop)[~ok] == 0) and 0 < ok.mean() < 1  # the grid hangs over the map's edge
    grad = jax.grad(lambda p: jnp.sum(map_crop(m, p, grid)[0] * jnp.arange(64.0)[:, None]))(pose)
    assert np.all(np.isfinite(grad)) and np.any(grad != 0)


def test_match_recovers_the_pose_and_the_pitch_error(carla):
    seq, m = carla.sequence, carla.map
    grid = SCENE_KINDS["carla"].grids()[1]
    model = BevoPlus.create(map_grid=grid)
    match = jax.jit(
        lambda img, pitch, roll, pose: match_to_map(
            *bev_project(img.astype(jnp.float32) / 255, pitch, roll, seq.camera, grid),
            m,
            pose,
            grid,
            model.map_dpc,
            seq.camera.height,
            jnp.exp(model.log_pitch_gain),
        )
    )
    rng = np.random.default_rng(1)
    for t in (20, 35, 50):
        truth = np.asarray(seq.planar[t])
        pitch, roll = seq.pitch_roll[t]
        start = truth + np.array([*rng.uniform(-1.5, 1.5, 2), np.radians(rng.uniform(-2, 2))])
        fix = match(seq.images[t], pitch, roll, jnp.asarray(start))
        assert np.hypot(*(np.asarray(fix.fix[:2]) - truth[:2])) < 0.25
        assert abs(np.degrees(float(fix.fix[2] - truth[2]))) < 0.6
        assert float(fix.confidence) > 0.2
        off = match(seq.images[t], pitch + np.radians(0.3), roll, jnp.asarray(truth))
        assert np.degrees(float(off.pitch_error)) == pytest.approx(0.3, abs=0.12)


def test_bevo_plus_stays_on_the_map_where_odometry_drifts(carla):
    seq, m = carla.sequence, carla.map
    model = localization_model("carla")
    assert model.num_learnable() == 29
    run = eqx.filter_jit(lambda mod, s, mp: mod(s, mp, warm_start=True))
    out = run(model, seq, m)
    err = pose_errors(out.poses, seq.planar)
    assert err["mean_position_error_m"] < 0.25 and err["max_position_error_m"] < 0.6
    assert err["mean_yaw_error_deg"] < 0.6
    assert np.asarray(out.accepted).mean() > 0.9
    odometry = eqx.filter_jit(lambda mod, s: mod(s, warm_start=True))(model.odometry, seq)
    assert pose_errors(odometry.poses, seq.planar)["final_position_error_m"] > 2 * err["final_position_error_m"]
    # Offline, every map fix informs every pose: the smoothed trajectory is closer still.
    smoothed = jax.jit(smooth_localization)(out)
    assert pose_errors(smoothed.smoothed_mean, seq.planar)["mean_position_error_m"] < 0.97 * err["mean_position_error_m"]
    np.testing.assert_array_equal(smoothed.smoothed_mean[-1], out.poses[-1])
    with pytest.raises(ValueError, match="one sequence's output"):
        smooth_localization(jax.tree.map(lambda a: a[None], out))
    # vmap over sequences sharing the map equals one at a time
    both = eqx.filter_jit(jax.vmap(lambda mod, s, mp: mod(s, mp, warm_start=True), in_axes=(None, 0, None)))(
        model, data.stack([seq, seq]), m
    )
    np.testing.assert_allclose(both.poses[1], out.poses, atol=1e-4)  # float32: batched FFTs round differently
    with pytest.raises(ValueError, match="map image"):
        model(seq, Map(m.image[None], m.x_max, m.y_max, m.resolution))


def test_off_the_map_or_textureless_it_coasts_and_says_so(carla):
    """A map that does not cover the drive, or one without texture: no fix is accepted, the
    filter follows the odometry and its position uncertainty grows."""
    seq, m = carla.sequence, carla.map
    model = localization_model("carla")
    run = eqx.filter_jit(lambda mod, s, mp: mod(s, mp, warm_start=True))
    far = Map(m.image, m.x_max + 5000.0, m.y_max, m.resolution)
    flat = Map(jnp.full_like(m.image, 128), m.x_max, m.y_max, m.resolution)
    on_map = run(model, seq, m)
    for bad in (far, flat):
        out = run(model, seq, bad)
        assert not np.any(np.asarray(out.accepted))
        assert np.all(np.isfinite(np.asarray(out.poses)))
        assert np.all(np.diff(np.asarray(out.position_std)) > 0)  # it grows every frame
        assert float(out.position_std[-1]) > 3 * float(on_map.position_std[-1])
        assert float(np.max(np.asarray(out.confidence))) < model.min_confidence
        # coasting = the filter's motion (BEVO's dx, dy and the gyro's yaw) composed from the start
        dead = jax.lax.scan(lambda p, d: (se2_compose(p, d),) * 2, seq.planar[0].astype(out.increments.dtype), out.increments)[1]
        np.testing.assert_allclose(np.asarray(out.poses[:, :2]), np.asarray(dead[:, :2]), atol=0.05)


def test_a_large_initial_pose_error_is_corrected(carla):
    seq, m = carla.sequence, carla.map
    model = localization_model("carla")
    start = seq.planar[0] + jnp.array([2.5, -2.0, np.radians(3.0)])
    out = eqx.filter_jit(lambda mod, s, mp, p: mod(s, mp, p, initial_std=(3.0, 3.0, 0.1), warm_start=True))(model, seq, m, start)
    err = np.hypot(*(np.asarray(out.poses[:, :2]) - np.asarray(seq.planar[:, :2])).T)
    assert err[0] < 1.0 and err[-10:].max() < 0.3


def test_gradient_of_the_loss_matches_finite_differences(float64, world):
    """Every learnable leaf of the localizer itself (the odometry's are checked in
    tests/models/test_bevo.py), central differences in float64."""
    assert jnp.result_type(float) == jnp.float64
    sc = scene("carla", "town02", "day", "all", seed=2, world=world, frames=8)
    model = localization_model("carla")
    params, static = eqx.partition(model, eqx.is_inexact_array)

    def loss(p):
        return localization_loss(eqx.combine(p, static)(sc.sequence, sc.map, warm_start=True), sc.sequence)

    grads = eqx.filter_jit(jax.grad(loss))(params)
    value = eqx.filter_jit(loss)
    checked = check_leaf_gradients(value, grads, params, abs_tol=1e-8, skip=jax.tree_util.tree_leaves(params.odometry))
    assert checked == 15


def test_scene_parts_follow_the_seed_split(world):
    whole = scene("aeroground", "town02", "day", "all", seed=3, world=world, frames=40)
    test = scene("aeroground", "town02", "night", "test", seed=3, world=world, frames=40)
    assert part_range(40, "train") == (0, 20) and part_range(40, "val") == (20, 30) and part_range(40, "test") == (30, 40)
    assert test.sequence.num_frames == 10
    np.testing.assert_allclose(test.sequence.poses, whole.sequence.poses[30:], atol=1e-5)
    assert abs(float(whole.sequence.camera.height) - 0.8) < 1e-6 and whole.map.resolution == 0.1
    with pytest.raises(ValueError, match="unknown part"):
        part_range(40, "holdout")
    with pytest.raises(ValueError, match="unknown scene kind"):
        scene("boat", frames=40, world=world)


def test_bevo_plus_composes_an_odometry_with_bands(carla):
    """BEVO+ runs with the band geometry in its odometry (the odometry BEV is then projected once
    more, with the attitude after both the bands and the map updated it). On this 128 x 416
    camera the far band is too blurred for the bands to help (jbevo.vision.bands): only the mechanics
    are checked here."""
    seq, m = carla.sequence, carla.map
    model = localization_model("carla")
    odo = model.odometry
    with_bands = eqx.tree_at(lambda mod: mod.odometry, model, dataclasses.replace(odo, bands=BandGeometry.create()))
    assert with_bands.num_learnable() == 31
    out = eqx.filter_jit(lambda mod, s, mp: mod(s, mp, warm_start=True))(with_bands, seq, m)
    assert np.all(np.isfinite(np.asarray(out.poses))) and np.all(np.isfinite(np.asarray(out.position_std)))
    assert np.asarray(out.accepted).any()
    plain = eqx.filter_jit(lambda mod, s, mp: mod(s, mp, warm_start=True))(model, seq, m)
    assert not np.allclose(np.asarray(out.odometry), np.asarray(plain.odometry))


def test_map_matching_sees_the_camera_against_the_road(carla):
    """With a road view on the odometry, the map match projects at the camera's attitude and
    height against the road: the same as matching at the offset attitude with the scaled camera."""
    from jbevo.vision.road_view import RoadView

    seq, m = carla.sequence, carla.map
    model = localization_model("carla")
    view = RoadView.create(pitch=0.004, roll=-0.003, height_scale=1.03)
    with_road = dataclasses.replace(model, odometry=dataclasses.replace(model.odometry, road=view))
    pose, attitude = seq.planar[20], seq.pitch_roll[20]
    got = jax.jit(lambda mod: mod.match(seq.images[20], attitude, seq.camera, m, pose))(with_road)
    want = jax.jit(
        lambda mod: mod.match(seq.images[20], attitude + jnp.array([0.004, -0.003]), view.camera(seq.camera), m, pose)
    )(model)
    np.testing.assert_allclose(got.fix, want.fix, atol=1e-5)
    assert float(got.confidence) == pytest.approx(float(want.confidence), abs=1e-6)


def test_the_street_start_gives_the_odometry_the_street_presets_parts():
    plain, street = localization_model("carla"), localization_model("carla", street=True)
    assert plain.odometry.road is None and plain.odometry.yaw_fusion is None
    assert street.odometry.road is not None and street.odometry.yaw_fusion is not None
    assert street.num_learnable() > plain.num_learnable()
    assert street.map_grid == plain.map_grid and street.odometry.grid == plain.odometry.grid
