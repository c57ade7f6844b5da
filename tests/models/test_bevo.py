"""BEVO: the metric increment from DPC, the recursion against ground truth, vmap, and gradients
of the loss against finite differences for every learnable leaf."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.imu import NOISELESS
from jbevo.data.synthetic.sequences import (
    make_sequence,
    procedural_sequence,
    small_camera,
)
from jbevo.data.synthetic.world import World
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.euler import poses_from_euler
from jbevo.models.bevo import Bevo
from jbevo.models.losses import motion_loss, relative_motion
from jbevo.models.presets import street_model
from tests.helpers import check_leaf_gradients

CAMERA = small_camera()
GRID = BevGrid(0.1, (64, 64), near=7.5)


@pytest.fixture(scope="module")
def world():
    return World.create("town01", size=512)


@pytest.fixture(scope="module")
def level_drive(world):
    """A level drive at constant height: forward 0.5-0.9 m per frame, turning 0-1.5 deg per frame."""
    n = 9
    yaw = np.cumsum(np.radians(np.linspace(0.0, 1.5, n)))
    step = np.linspace(0.5, 0.9, n)
    x = np.cumsum(step * np.cos(yaw))
    y = np.cumsum(step * np.sin(yaw))
    euler = np.stack([yaw, np.zeros(n), np.zeros(n)], -1)
    poses = poses_from_euler(euler, np.stack([x, y, np.full(n, 1.65)], -1))
    return make_sequence(world, CAMERA, np.arange(n) * 0.1, poses, "day", NOISELESS, smoothing=None)


def test_increments_match_the_true_planar_motion(level_drive):
    """A level drive at constant height (nothing but DPC's own error): about 1 cm along, 3 cm
    across and 0.2 deg of yaw per frame (RMS) on the default 128x128 BEV; a sign or lever-arm
    error would be tens of centimetres."""
    model = Bevo.create(attitude_source="truth")
    out = eqx.filter_jit(lambda m, s: m(s))(model, level_drive)
    truth = relative_motion(level_drive)
    np.testing.assert_array_equal(out.increments[0], 0.0)
    np.testing.assert_allclose(out.increments[1:, 0], truth[1:, 0], atol=0.05)
    np.testing.assert_allclose(out.increments[1:, 1], truth[1:, 1], atol=0.12)
    np.testing.assert_allclose(np.degrees(out.increments[1:, 2]), np.degrees(truth[1:, 2]), atol=0.6)
    np.testing.assert_allclose(out.poses[-1, :2], level_drive.planar[-1, :2], atol=0.3)
    assert bool(jnp.all(out.confidence[1:] > 0.2))


def test_vmap_over_sequences_equals_single_runs(world):
    seqs = [procedural_sequence(s, 6, camera=CAMERA, world=world) for s in (0, 1)]
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *seqs)
    model = Bevo.create(GRID)
    many = eqx.filter_jit(jax.vmap(lambda m, s: m(s), in_axes=(None, 0)))(model, batch)
    one = eqx.filter_jit(lambda m, s: m(s))(model, seqs[1])
    np.testing.assert_allclose(many.poses[1], one.poses, atol=1e-4)
    assert many.increments.shape == (2, 6, 3) and many.pitch_roll.shape == (2, 6, 2)
    with pytest.raises(ValueError, match="use jax.vmap"):
        model(batch)


def test_learnable_parameters_and_sources():
    model = Bevo.create(GRID)
    assert model.num_learnable() == 14  # Q: 6, R: 2, DPC: 6
    with pytest.raises(ValueError, match="attitude_source"):
        Bevo.create(GRID, attitude_source="gps")


def test_gradient_of_the_loss_matches_finite_differences(float64, world):
    """Every learnable leaf, central differences in float64 (the ``float64`` fixture; the
    model then computes in float64). The loss has kinks where a correlation peak changes its
    integer position, so the step is small (1e-5)."""
    assert jnp.result_type(float) == jnp.float64
    seq = procedural_sequence(3, 5, camera=CAMERA, world=world)
    model = Bevo.create(GRID)
    params, static = eqx.partition(model, eqx.is_inexact_array)

    def loss(p):
        return motion_loss(eqx.combine(p, static)(seq, warm_start=True), seq)

    grads = eqx.filter_jit(jax.grad(loss))(params)
    value = eqx.filter_jit(loss)
    checked = check_leaf_gradients(value, grads, params, abs_tol=1e-7)
    assert checked == 14


@pytest.mark.parametrize("level_road", [False, True])
def test_street_model_gradients_match_finite_differences(float64, world, level_road):
    """The real-street configuration: road view, yaw fusion, road tilt, robust bands (their 8
    leaves, DPC's 6 and the band pair through them), float64 on the small camera, with the tilt
    added to the filter's pitch and on a level road (the tilt the BEV's only pitch); the attitude
    filter's leaves are checked by the test above."""
    seq = procedural_sequence(3, 5, camera=CAMERA, world=world)
    # The bands at any speed (the travel gate is a step: its kinks are not what this checks).
    model = street_model(seq.imu_dt, grid=GRID, bands_min_travel=0.0, level_road=level_road)
    model = dataclasses.replace(model, gyro_window=0.0)
    assert model.road_tilt is not None and model.road_tilt.level == level_road
    assert model.num_learnable() == 14 + 2 + 4 + 1 + 1
    assert model.bands is not None and model.bands.robust
    params, static = eqx.partition(model, eqx.is_inexact_array)
    params = jax.tree_util.tree_map(lambda x: x.astype(jnp.float64), params)  # steps of 1e-7 need it

    def loss(p):
        return motion_loss(eqx.combine(p, static)(seq, warm_start=True), seq)

    grads = eqx.filter_jit(jax.grad(loss))(params)
    value = eqx.filter_jit(loss)
    attitude = jax.tree_util.tree_leaves(params.attitude)
    # The road view's camera pitch, roll and height move the far BEV rows across many pixel
    # boundaries (kinks of bilinear sampling), and its corridor reweights every column: the
    # central difference settles only below 1e-6.
    road = jax.tree_util.tree_leaves(params.road)
    assert check_leaf_gradients(value, grads, params, abs_tol=1e-7, skip=attitude + road) == 6 + 2 + 1 + 1
    others = [x for x in jax.tree_util.tree_leaves(params) if all(x is not r for r in road)]
    assert check_leaf_gradients(value, grads, params, abs_tol=1e-7, eps=1e-7, skip=others) == 4
    assert abs(float(grads.road.pitch)) > 0 and abs(float(grads.yaw_fusion.log_std_ratio)) > 0
    assert abs(float(grads.road_tilt.log_walk_std)) > 0


def test_street_model_with_keyframes_gradients_match_finite_differences(float64, level_drive):
    """The street model's bands with keyframes, engaged from 1 m: on a drive at 0.5-0.9 m per
    frame each band pair spans two frames, and the gradients of DPC, the bands, the road tilt and
    the yaw fusion match central differences. No engaged pair is a consecutive one, so the bands'
    motion (and with it their yaw gain) is never taken: its gradient is exactly zero."""
    model = dataclasses.replace(street_model(level_drive.imu_dt, grid=GRID, bands_keyframes=True), gyro_window=0.0)
    assert model.bands is not None and model.bands.keyframes and model.bands.min_travel == 1.0
    params, static = eqx.partition(model, eqx.is_inexact_array)
    params = jax.tree_util.tree_map(lambda x: x.astype(jnp.float64), params)

    def loss(p):
        return motion_loss(eqx.combine(p, static)(level_drive, warm_start=True), level_drive)

    grads = eqx.filter_jit(jax.grad(loss))(params)
    skip = jax.tree_util.tree_leaves(params.attitude) + jax.tree_util.tree_leaves(params.road)
    assert check_leaf_gradients(eqx.filter_jit(loss), grads, params, abs_tol=1e-7, skip=skip) == 6 + 2 + 1 + 1
    assert abs(float(grads.bands.log_slope_std)) > 0 and abs(float(grads.road_tilt.log_walk_std)) > 0
    assert float(grads.bands.log_yaw_gain) == 0.0


def test_forward_fusion_replaces_the_forward_motion_only(level_drive):
    """With the accelerometer's speed fused in, the lateral motion, the turn and the attitude are
    those of the same model without it (bit for bit: it only replaces the increment's forward
    component), and the forward motion is closer to the truth than DPC's alone."""
    plain = Bevo.create(GRID, level_drive.imu_dt)
    fused = Bevo.create(GRID, level_drive.imu_dt, forward_fusion=True)
    run = eqx.filter_jit(lambda m, s: m(s, warm_start=True))
    a, b = run(plain, level_drive), run(fused, level_drive)
    np.testing.assert_array_equal(b.increments[:, 1:], a.increments[:, 1:])
    np.testing.assert_array_equal(b.pitch_roll, a.pitch_roll)
    np.testing.assert_array_equal(b.increments[0], 0.0)
    truth = np.asarray(relative_motion(level_drive))[1:, 0]
    rms = lambda inc: float(np.sqrt(np.mean((np.asarray(inc)[1:, 0] - truth) ** 2)))
    assert rms(b.increments) < 0.5 * rms(a.increments)


def test_forward_fusion_gradients_match_finite_differences(float64, level_drive):
    """The forward fusion's three noise parameters in the street model, against central
    differences (the other leaves are checked above)."""
    model = dataclasses.replace(street_model(level_drive.imu_dt, grid=GRID, forward_fusion=True), gyro_window=0.0)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    params = jax.tree_util.tree_map(lambda x: x.astype(jnp.float64), params)

    def loss(p):
        return motion_loss(eqx.combine(p, static)(level_drive, warm_start=True), level_drive)

    grads = eqx.filter_jit(jax.grad(loss))(params)
    forward = set(map(id, jax.tree_util.tree_leaves(params.forward)))
    skip = [leaf for leaf in jax.tree_util.tree_leaves(params) if id(leaf) not in forward]
    assert check_leaf_gradients(eqx.filter_jit(loss), grads, params, abs_tol=1e-7, skip=skip) == 3
    assert all(
        abs(float(g)) > 0 for g in (grads.forward.log_accel_std, grads.forward.log_displacement_std, grads.forward.log_bias_walk)
    )
