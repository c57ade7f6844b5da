"""The BEV band geometry (jbevo.vision.bands): on KITTI-size images of the synthetic world, a pitch error
is measured from the forward-shift slope and removed from the forward motion, a roll error's
false turn is corrected, a pitch drift at standstill is read as gyro bias, and BEVO with bands
pulls a wrong pitch back; gradients of the band parameters match finite differences."""

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
from jbevo.geometry.camera import Camera
from jbevo.geometry.euler import poses_from_euler
from jbevo.inertial.speed_aided import AttitudeState, SpeedAidedAttitude
from jbevo.models.bevo import Bevo
from jbevo.models.losses import motion_loss
from jbevo.vision.bands import BandGeometry, band_moments
from jbevo.vision.bev import bev_increment, feathered_bev
from jbevo.vision.dpc_params import DPCParams
from jbevo.vision.registration import register
from tests.helpers import check_leaf_gradients

CAMERA = Camera.kitti()
GRID = BevGrid(0.1, (256, 256), near=4.0)
DPC = DPCParams(n_angles=256)
H = CAMERA.height


@pytest.fixture(scope="module")
def world():
    return World.create("town01", size=1024)


def straight(world, steps, n=3):
    """A level drive along x moving ``steps`` metres per frame (noiseless IMU)."""
    x = np.concatenate([[0.0], np.cumsum(np.broadcast_to(steps, n - 1))]) + 20.0
    poses = poses_from_euler(np.zeros((n, 3)), np.stack([x, np.full(n, 30.0), np.full(n, H)], -1))
    return make_sequence(world, CAMERA, np.arange(n) * 0.1, poses, "day", NOISELESS, smoothing=None)


@pytest.fixture(scope="module")
def moving(world):
    return straight(world, 1.0)


@pytest.fixture(scope="module")
def standing(world):
    return straight(world, 0.0)


@jax.jit
def _pair(image0, image1, att0, att1):
    bev0 = feathered_bev(image0, att0[0], att0[1], CAMERA, GRID, 4)
    bev1 = feathered_bev(image1, att1[0], att1[1], CAMERA, GRID, 4)
    reg = register(bev0, bev1, DPC)
    return reg, BandGeometry.create().shifts(bev0, bev1, reg, GRID, DPC)


def pair(seq, att0, att1):
    return _pair(seq.images[0], seq.images[1], jnp.asarray(att0, float), jnp.asarray(att1, float))


def slope(shifts):
    x_far, x_near = band_moments(GRID, DPC.window_taper, 1)
    return float((shifts.forward[0] - shifts.forward[1]) / (x_far - x_near))


def test_band_moments_follow_the_rows():
    (x_far, x_near), (m2_far, m2_near) = band_moments(GRID, DPC.window_taper, 1), band_moments(GRID, DPC.window_taper, 2)
    assert 4.0 < x_near < 4.0 + 12.8 < x_far < 4.0 + 25.6
    assert x_far - x_near == pytest.approx(12.8, abs=0.1)  # the window is the same on both halves
    assert m2_far > x_far**2 and m2_near > x_near**2


def test_parameters_must_be_positive():
    with pytest.raises(ValueError, match="positive"):
        BandGeometry.create(slope_std=0.0)
    with pytest.raises(ValueError, match="positive"):
        BandGeometry.create(yaw_gain=-1.3)


@pytest.mark.parametrize("error_deg", [0.5, -0.5])
def test_a_pitch_error_is_measured_and_removed_from_the_motion(moving, error_deg):
    """Both BEVs projected 0.5 deg off in pitch: DPC's forward motion is off by ~10 cm, the
    slope reads the error to 25 %, and the extrapolated motion is good to 3 cm."""
    e = np.radians(error_deg)
    reg, shifts = pair(moving, (e, 0.0), (e, 0.0))
    plain = bev_increment(GRID, reg.rotation, reg.translation)
    assert abs(float(plain[0]) - 1.0) > 0.08
    measured = -slope(shifts) * H / 2.0  # m = -2 e D / h at D = 1 m
    assert measured == pytest.approx(e, rel=0.25)
    rotation, translation = BandGeometry.create().motion(shifts, reg, GRID, DPC, jnp.asarray(H), jnp.asarray(0.0))
    refined = bev_increment(GRID, rotation, translation)
    assert abs(float(refined[0]) - 1.0) < 0.03


def test_a_roll_error_false_turn_is_corrected(moving):
    """0.5 deg of roll makes DPC see a turn on a straight drive; the bands' lateral shifts take
    most of it back."""
    r = np.radians(0.5)
    reg, shifts = pair(moving, (0.0, r), (0.0, r))
    rotation, _ = BandGeometry.create().motion(shifts, reg, GRID, DPC, jnp.asarray(H), jnp.asarray(0.0))
    assert abs(float(reg.rotation)) > np.radians(0.05)
    assert abs(float(rotation)) < 0.5 * abs(float(reg.rotation))


def _state(pitch, bias_std=0.05):
    state = AttitudeState.initial(jnp.asarray([pitch, 0.0]), jnp.asarray(10.0), np.radians(0.5), 1e-2, 1.0)
    cov = jnp.diag(jnp.asarray([np.radians(0.5) ** 2, 1e-4, 1e-4, bias_std**2, 1e-4, 1.0]))
    return state._replace(cov=cov)


def _update(bands, state, shifts, use):
    """The bands' slope measurement applied to the attitude belief, as BEVO applies it."""
    m = bands.slope_measurement(shifts, GRID, DPC, jnp.asarray(H), 0.1)
    h = AttitudeState.row(pitch=m.pitch, pitch_rate_bias=m.pitch_rate_bias, dtype=state.mean.dtype)
    return SpeedAidedAttitude.update_linear(state, h, m.value, m.variance, jnp.asarray(use) & m.valid)


def test_the_update_pulls_the_pitch_toward_the_truth(moving):
    """With the gyro bias known (a tight prior; one frame cannot tell a pitch error from a bias,
    the filter does over frames of changing speed), the update removes most of a pitch error."""
    e = np.radians(0.5)
    _, shifts = pair(moving, (e, 0.0), (e, 0.0))
    bands = BandGeometry.create()
    new = _update(bands, _state(e, bias_std=1e-4), shifts, True)
    assert abs(float(new.pitch)) < 0.3 * e
    skipped = _update(bands, _state(e), shifts, False)
    assert float(skipped.pitch) == float(np.float32(e))


def test_the_robust_update_keeps_its_pull_and_discounts_a_gross_slope(moving):
    """The robust update still removes a good part of a real 0.5 deg pitch error in one frame
    (about half, where the plain update removes most: the price of robustness, paid back over
    frames), but a slope that off-ground content bent far moves the pitch less than a tenth as
    much as the plain update lets it (which follows it)."""
    e = np.radians(0.5)
    _, shifts = pair(moving, (e, 0.0), (e, 0.0))
    robust = BandGeometry.create(robust=True)
    assert abs(float(_update(robust, _state(e, bias_std=1e-4), shifts, True).pitch)) < 0.6 * e
    gross = shifts._replace(forward=shifts.forward + jnp.array([0.8, 0.0], shifts.forward.dtype))
    plain_move = float(_update(BandGeometry.create(), _state(0.0, bias_std=1e-4), gross, True).pitch)
    robust_move = float(_update(robust, _state(0.0, bias_std=1e-4), gross, True).pitch)
    assert abs(plain_move) > np.radians(1.0) and abs(robust_move) < 0.1 * abs(plain_move)
    m = robust.slope_measurement(gross, GRID, DPC, jnp.asarray(H), 0.1)
    assert float(m.variance) == pytest.approx(0.003**2 + float(m.value) ** 2, rel=1e-5)


def test_below_min_travel_the_bands_stand_aside(moving):
    """At 1 m per frame, bands engaged from 100 m per frame give exactly the motion of BEVO
    without bands (the true attitude: no reprojection, no slope update), and from 0.5 m they
    change it."""
    plain = Bevo.create(GRID, attitude_source="truth")
    run = eqx.filter_jit(lambda m, s: m(s, warm_start=True))
    without = run(plain, moving).increments
    idle = eqx.tree_at(lambda m: m.bands, plain, BandGeometry.create(min_travel=100.0), is_leaf=lambda x: x is None)
    np.testing.assert_array_equal(run(idle, moving).increments, without)
    engaged = eqx.tree_at(lambda m: m.bands, plain, BandGeometry.create(min_travel=0.5), is_leaf=lambda x: x is None)
    assert float(jnp.max(jnp.abs(run(engaged, moving).increments - without))) > 1e-4
    with pytest.raises(ValueError, match="min_travel"):
        BandGeometry.create(min_travel=-1.0)


def test_keyframes_need_a_travel_gate():
    with pytest.raises(ValueError, match="keyframes need a positive min_travel"):
        BandGeometry.create(keyframes=True)
    assert BandGeometry.create(min_travel=1.0, keyframes=True).keyframes


def test_a_known_pitch_drift_is_removed_from_the_slope(moving):
    """The previous BEV projected 0.1 deg above the current one (both otherwise true): the slope
    reads the drift as a pitch error of over a degree (the drift's lever is the bands' distance
    ahead, the pitch error's the travel). Removing the drift, as a keyframe's pair does with the filter's corrections since
    the keyframe, takes most of that reading away (the model is first order in the distance
    moments; DPC's peak on the blurred far band sits nearer), and removing it with the wrong sign
    makes it worse."""
    drift = np.radians(0.1)
    _, shifts = pair(moving, (drift, 0.0), (0.0, 0.0))
    bands = BandGeometry.create()

    def reads(s):  # the pitch error a slope reads at D = 1 m
        return -slope(s) * H / 2.0

    raw = reads(shifts)
    assert raw > np.radians(1.0)
    assert abs(reads(bands.remove_drift(shifts, GRID, DPC, jnp.asarray(H), jnp.asarray(drift)))) < 0.35 * raw
    assert reads(bands.remove_drift(shifts, GRID, DPC, jnp.asarray(H), jnp.asarray(-drift))) > 1.5 * raw


def test_a_pitch_drift_at_standstill_reads_as_gyro_bias(standing):
    """Standing still, the previous BEV 0.2 deg above the current one: nothing moved, so the
    stretch can only be a pitch drift, which the model reads as a pitch-rate bias estimate
    ``0.2 deg / 0.1 s`` too high."""
    drift = np.radians(0.2)
    _, shifts = pair(standing, (drift, 0.0), (0.0, 0.0))
    new = _update(BandGeometry.create(), _state(0.0), shifts, True)
    # b_hat - b = drift / T: the update lowers the bias estimate by about that much.
    assert -2.0 * drift / 0.1 < float(new.pitch_rate_bias) < -0.5 * drift / 0.1
    assert abs(float(new.pitch)) < np.radians(0.05)


def test_bevo_with_bands_corrects_a_wrong_pitch(world):
    """A straight drive at 1 m per frame, the filter started 0.4 deg off in pitch: the bands
    bring it within 0.1 deg in 12 frames, where without them it stays off. (The start is
    uncertain by as much: a confident filter would blame the gyro bias first.)"""
    seq = straight(world, 1.0, n=13)

    def final_pitch_error(bands):
        model = Bevo.create(GRID, seq.imu_dt, bands=bands, n_angles=256)
        carry, frames, seq_ = model.start(seq, warm_start=True)
        h = AttitudeState.row(pitch=1.0, dtype=carry.attitude.mean.dtype)
        old = carry.attitude
        extra = np.radians(0.4) ** 2 - float(old.cov @ h @ h)
        carry = carry._replace(attitude=AttitudeState(old.mean + np.radians(0.4) * h, old.cov + extra * jnp.outer(h, h)))
        step = jax.jit(lambda c, f: model.step(c, f, seq_.camera, model.frame_dt(seq_)))
        _, out = jax.lax.scan(step, carry, frames)
        return abs(float(out.pitch_roll[-1, 0] - seq.pitch_roll[-1, 0]))

    assert final_pitch_error(True) < np.radians(0.1)
    assert final_pitch_error(False) > np.radians(0.3)


def test_gradients_of_the_band_parameters_match_finite_differences(float64, world):
    """The two band leaves (and the rest, through the band path), float64, on the small camera."""
    assert jnp.result_type(float) == jnp.float64
    seq = procedural_sequence(3, 5, camera=small_camera(), world=world)
    model = Bevo.create(BevGrid(0.1, (64, 64), near=7.5), bands=True)
    params, static = eqx.partition(model, eqx.is_inexact_array)

    def loss(p):
        return motion_loss(eqx.combine(p, static)(seq, warm_start=True), seq)

    grads = eqx.filter_jit(jax.grad(loss))(params)
    assert model.num_learnable() == 16
    skip = jax.tree_util.tree_leaves(eqx.filter(params, lambda x: x is not None).attitude)
    checked = check_leaf_gradients(eqx.filter_jit(loss), grads, params, abs_tol=1e-7, skip=skip)
    assert checked == 8  # DPC: 6, bands: 2
    assert abs(float(grads.bands.log_yaw_gain)) > 0 and abs(float(grads.bands.log_slope_std)) > 0
