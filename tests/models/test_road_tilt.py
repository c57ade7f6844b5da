"""The road's tilt as a state (jbevo.models.road_tilt): its walk and update, its gradient, and,
on a drive whose camera looks at the road 0.4 deg further down than the IMU's level says (a
grade the IMU cannot see), BEVO with bands finds the tilt while its pitch against gravity stays
true; the plain band update instead pulls the gravity pitch off. Below the bands' travel gate,
the odometry's speed moves it toward the truth (nothing does without it), and keyframes let the
bands find it too. The joint update of the tilt and the attitude filter by the speed against an
independent Kalman update of the stacked state, and its gradient."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jbevo.data.synthetic.imu import NOISELESS
from jbevo.data.synthetic.sequences import make_sequence
from jbevo.data.synthetic.world import World
from jbevo.filtering.ukf import GaussianState
from jbevo.geometry.bev_grid import BevGrid
from jbevo.geometry.camera import FORWARD, Camera, level_to_body
from jbevo.geometry.euler import poses_from_euler
from jbevo.inertial.speed_aided import AttitudeState, SpeedAidedAttitude
from jbevo.models.bevo import Bevo
from jbevo.models.presets import street_model
from jbevo.models.road_tilt import RoadTilt
from jbevo.models.runners import run_bevo
from jbevo.vision.bands import BandGeometry, SlopeMeasurement

TILT = np.radians(0.4)


def test_walk_and_update():
    tilt = RoadTilt.create(walk_std=0.002, initial_std=0.01)
    state = tilt.predict(tilt.initial(jnp.float32), jnp.float32(-25.0))  # reversing walks too
    assert float(state.cov[0, 0]) == pytest.approx(0.01**2 + 0.002**2 * 25, rel=1e-5)
    # A slope of 0.01 with coefficient 2 D / h = 1.2: the state moves toward 0.01 / 1.2.
    slope = SlopeMeasurement(*(jnp.float32(v) for v in (0.01, 1.2, 0.0, 1e-8)), jnp.bool_(True))
    new = RoadTilt.update(state, slope)
    assert float(new.mean[0]) == pytest.approx(0.01 / 1.2, rel=1e-3) and float(new.cov[0, 0]) < 1e-6
    assert RoadTilt.update(state, slope, False) == state
    for bad in ({"walk_std": 0.0}, {"initial_std": -1.0}):
        with pytest.raises(ValueError, match="positive"):
            RoadTilt.create(**bad)


def test_gradient_of_the_walk(float64):
    state = GaussianState(jnp.zeros(1), jnp.full((1, 1), 1e-4))
    slope = SlopeMeasurement(*(jnp.float64(v) for v in (0.01, 1.2, 0.0, 1e-5)), jnp.bool_(True))

    def value(t):
        return RoadTilt.update(t.predict(state, jnp.float64(12.0)), slope).mean[0]

    tilt = RoadTilt(jnp.float64(np.log(0.003)))
    grad = jax.grad(value)(tilt).log_walk_std
    eps = 1e-6
    fd = (value(RoadTilt(tilt.log_walk_std + eps)) - value(RoadTilt(tilt.log_walk_std - eps))) / (2 * eps)
    assert float(grad) == pytest.approx(float(fd), rel=1e-6) and float(grad) > 0


def _speed_case(dtype):
    """An attitude belief at 10 m/s (0.5 m/s uncertain), a tilt 0.5 deg uncertain, DPC's speed
    9 m/s, and the street grid's sensitivity (2 x 16.75 m / 1.65 m)."""
    filt = SpeedAidedAttitude.create()
    belief = AttitudeState.initial(jnp.zeros(2, dtype), jnp.asarray(10.0, dtype), 0.003, 0.001, 0.5)
    tilt = GaussianState(jnp.asarray([0.002], dtype), jnp.full((1, 1), np.radians(0.5) ** 2, dtype))
    return filt, belief, tilt, jnp.asarray(9.0, dtype), 2 * 16.75 / 1.65


def test_speed_updates_the_tilt_and_the_speed_together(float64):
    filt, belief, tilt, speed, sensitivity = _speed_case(jnp.float64)
    new_belief, new_tilt = RoadTilt.update_with_speed(filt, belief, tilt, speed, sensitivity)
    # Independent reference: one Kalman update of the stacked 7-state, in numpy.
    mean = np.r_[np.asarray(belief.mean), np.asarray(tilt.mean)]
    cov = np.zeros((7, 7))
    cov[:6, :6], cov[6:, 6:] = np.asarray(belief.cov), np.asarray(tilt.cov)
    h = np.zeros(7)
    h[5], h[6] = 1.0, 10.0 * sensitivity
    innovation = 9.0 - 10.0
    r = float(jnp.exp(filt.measurement_noise.log_std[1])) ** 2 + innovation**2  # robust
    gain = cov @ h / (h @ cov @ h + r)
    post_mean, post_cov = mean + gain * innovation, cov - np.outer(gain, h @ cov)
    np.testing.assert_allclose(new_belief.mean, post_mean[:6], atol=1e-12)
    np.testing.assert_allclose(new_tilt.mean, post_mean[6:], atol=1e-12)
    np.testing.assert_allclose(new_belief.cov, post_cov[:6, :6], atol=1e-12)
    np.testing.assert_allclose(new_tilt.cov, post_cov[6:, 6:], atol=1e-12)
    # A slower odometry than the belief: less speed, less tilt (the BEV was projected too flat).
    assert float(new_belief.speed) < 10.0 and float(new_tilt.mean[0]) < 0.002
    # Zero sensitivity: the attitude filter's own speed update, the tilt untouched.
    alone, same = RoadTilt.update_with_speed(filt, belief, tilt, speed, 0.0)
    reference = filt.update_speed(belief, speed)
    np.testing.assert_allclose(alone.mean, reference.mean, atol=1e-12)
    np.testing.assert_allclose(alone.cov, reference.cov, atol=1e-12)
    assert np.array_equal(same.mean, tilt.mean) and np.array_equal(same.cov, tilt.cov)
    # No measurement (NaN): nothing moves.
    kept, kept_tilt = RoadTilt.update_with_speed(filt, belief, tilt, jnp.float64(np.nan), sensitivity)
    assert np.array_equal(kept.mean, belief.mean) and np.array_equal(kept_tilt.cov, tilt.cov)


def test_gradient_of_the_speed_update(float64):
    """The tilt after the joint update against the attitude filter's measurement noise (the
    speed's log standard deviation) and the sensitivity, by central differences."""
    filt, belief, tilt, speed, sensitivity = _speed_case(jnp.float64)

    def value(log_std, sens):
        f = eqx.tree_at(lambda m: m.measurement_noise.log_std, filt, log_std)
        return RoadTilt.update_with_speed(f, belief, tilt, speed, sens)[1].mean[0]

    log_std, sens = filt.measurement_noise.log_std.astype(jnp.float64), jnp.float64(sensitivity)
    grad_std, grad_sens = jax.grad(value, argnums=(0, 1))(log_std, sens)
    eps = 1e-6
    step = jnp.zeros(2).at[1].set(eps)
    fd_std = (value(log_std + step, sens) - value(log_std - step, sens)) / (2 * eps)
    fd_sens = (value(log_std, sens + eps) - value(log_std, sens - eps)) / (2 * eps)
    assert float(grad_std[1]) == pytest.approx(float(fd_std), rel=1e-6) and float(grad_std[1]) > 0
    assert float(grad_sens) == pytest.approx(float(fd_sens), rel=1e-6)


def _tilted_drive(world, step, n, tilt=TILT, body_pitch=0.0):
    """A straight drive at ``step`` metres per frame (noiseless IMU), the body pitched
    ``body_pitch`` radians nose down against gravity, whose KITTI camera is mounted ``tilt``
    radians nose down against the body (default :data:`TILT`, 0.4 deg), read back with the
    nominal camera: to the model, a road falling by ``tilt``. With ``tilt = -body_pitch`` the
    camera looks at the level ground as the nominal one on a level body: a grade that the IMU
    sees and the camera's view of the road does not."""
    nominal = Camera.kitti()
    mounted = eqx.tree_at(
        lambda c: c.rotation_body_to_camera,
        nominal,
        jnp.asarray(FORWARD, jnp.float32) @ level_to_body(jnp.float32(tilt), jnp.float32(0.0)).T,
    )
    x = 20.0 + step * np.arange(n)
    euler = np.zeros((n, 3))
    euler[:, 1] = body_pitch
    poses = poses_from_euler(euler, np.stack([x, np.full(n, 30.0), np.full(n, 1.65)], -1))
    seq = make_sequence(world, mounted, np.arange(n) * 0.1, poses, "day", NOISELESS, smoothing=None)
    return eqx.tree_at(lambda s: s.camera, seq, nominal)


@pytest.fixture(scope="module")
def world():
    return World.create("town01", size=1024)


@pytest.fixture(scope="module")
def tilted_view(world):
    """The tilted road at 1.2 m per frame."""
    return _tilted_drive(world, 1.2, 16)


def _tilt_and_pitch(model, seq):
    """The road tilt and the gravity pitch after each frame (radians)."""
    carry, frames, seq_ = model.start(seq, warm_start=True)
    step = jax.jit(lambda c, f: model.step(c, f, seq_.camera, model.frame_dt(seq_))[0])

    def body(c, f):
        c = step(c, f)
        return c, (c.road_tilt.mean[0], c.attitude.pitch)

    _, (tilt, pitch) = jax.lax.scan(body, carry, frames)
    return np.asarray(tilt), np.asarray(pitch)


def test_bands_find_the_road_tilt_and_leave_the_gravity_pitch_alone(tilted_view):
    """With the road tilt, the bands find 0.4 deg within a few tenths of a degree's scatter per
    frame (the mean of the last eight frames within 0.1 deg) and the pitch against gravity stays
    true to 0.01 deg; without it, the filter's gravity reference resists the bands, and the
    projection stays more than 0.2 deg off the road."""
    grid = BevGrid(0.1, (256, 256), near=4.0)
    robust = Bevo.create(grid, tilted_view.imu_dt, n_angles=256)
    robust = dataclasses.replace(robust, bands=BandGeometry.create(robust=True))
    truth = np.asarray(tilted_view.pitch_roll[:, 0])
    with_tilt = dataclasses.replace(robust, road_tilt=RoadTilt.create())
    tilt, pitch = _tilt_and_pitch(with_tilt, tilted_view)
    assert abs(np.mean(tilt[-8:]) - TILT) < np.radians(0.1)
    assert np.abs(pitch - truth).max() < np.radians(0.01)
    # The output reports the tilt each frame's BEV was projected with: the previous frame's.
    out = run_bevo(with_tilt, tilted_view, warm_start=True)
    assert float(out.road_tilt[0]) == 0.0
    np.testing.assert_allclose(out.road_tilt[1:], tilt[:-1], atol=1e-5)
    assert np.all(np.asarray(run_bevo(robust, tilted_view, warm_start=True).road_tilt) == 0.0)
    _, pitch = _tilt_and_pitch(robust, tilted_view)
    assert np.all(np.abs(TILT - (pitch[-8:] - truth[-8:])) > np.radians(0.2))


def test_the_output_names_the_tilt_each_bev_was_projected_with(tilted_view):
    """The BEV that a frame's observation projects is the one at the output's pitch and roll with
    the output's road tilt added to the pitch, frame after frame while the bands move the tilt."""
    rows = _check_observed_bevs(
        _street_bands(tilted_view, keyframes=False), tilted_view, 6, lambda row: row.pitch_roll.at[0].add(row.road_tilt)
    )
    for row in rows:
        np.testing.assert_allclose(row.projection, row.pitch_roll.at[0].add(row.road_tilt), atol=1e-7)
    assert abs(float(rows[-1].road_tilt)) > np.radians(0.05)


def _check_observed_bevs(model, seq, frames, attitude):
    """Step ``model`` over the first ``frames`` frames of ``seq``, checking that the BEV each
    observation projects is the one at ``attitude(output row)``; the output rows."""
    carry, scanned, seq = model.start(seq, warm_start=True)
    frame_dt = model.frame_dt(seq)
    observe = jax.jit(lambda c, f: model.observe(c, f, seq.camera, frame_dt))
    step = jax.jit(lambda c, f: model.step(c, f, seq.camera, frame_dt))
    bev = jax.jit(lambda image, pitch_roll: model.bev(image, pitch_roll, seq.camera))
    rows = []
    for t in range(frames):
        frame = jax.tree_util.tree_map(lambda a, t=t: a[t], scanned)
        projected = observe(carry, frame).bev
        carry, row = step(carry, frame)
        np.testing.assert_allclose(bev(frame.image, attitude(row)), projected, atol=1e-4)
        rows.append(row)
    return rows


def _street_bands(seq, keyframes, robust=True):
    """The real-street bands (robust, engaged from 1 m, road tilt) on the tilted drive's grid."""
    model = Bevo.create(BevGrid(0.1, (256, 256), near=4.0), seq.imu_dt, n_angles=256, road_tilt=True)
    return dataclasses.replace(model, bands=BandGeometry.create(robust=robust, min_travel=1.0, keyframes=keyframes))


GRADE = np.radians(0.6)


def test_a_level_road_projects_on_the_road_whatever_the_grade(world):
    """A 0.6 deg grade that the IMU sees while the camera's view of the road is the nominal one:
    on a level road the BEV's pitch is the tilt alone (its roll zero) and stays within 0.1 deg of
    the road from the first frame, while the filter keeps the pitch against gravity to 0.01 deg;
    the tilt added to the filter's pitch projects the first two BEVs a grade off, and the bands
    bring it within 0.1 deg by the 16th. Each observation's BEV is the one at the output's
    ``projection``."""
    with pytest.raises(ValueError, match="level_road needs bands"):
        street_model(0.01, bands=False, level_road=True)
    graded = _tilted_drive(world, 1.2, 16, tilt=-GRADE, body_pitch=GRADE)
    truth = np.asarray(graded.pitch_roll[:, 0])
    assert np.allclose(truth, GRADE, atol=1e-4)
    gravity_tilt = _street_bands(graded, keyframes=False)
    assert gravity_tilt.road_tilt is not None
    level = dataclasses.replace(gravity_tilt, road_tilt=dataclasses.replace(gravity_tilt.road_tilt, level=True))
    out = run_bevo(level, graded, warm_start=True)
    projection = np.asarray(out.projection)
    np.testing.assert_array_equal(projection[:, 0], np.asarray(out.road_tilt))
    assert np.all(projection[:, 1] == 0.0)
    assert np.abs(projection[:, 0]).max() < np.radians(0.1)
    assert np.abs(np.asarray(out.pitch_roll[:, 0]) - truth).max() < np.radians(0.01)
    added = run_bevo(gravity_tilt, graded, warm_start=True)
    np.testing.assert_allclose(added.projection[:, 0], added.pitch_roll[:, 0] + added.road_tilt, atol=1e-7)
    np.testing.assert_array_equal(added.projection[:, 1], added.pitch_roll[:, 1])
    assert np.all(np.abs(np.asarray(added.projection[:2, 0]) - GRADE) < np.radians(0.02))
    assert abs(float(added.projection[-1, 0])) < np.radians(0.1)
    _check_observed_bevs(level, graded, 4, lambda row: row.projection)


def test_keyframes_find_the_road_tilt_below_the_travel_gate(world):
    """At 0.4 m per frame the bands engaged from 1 m per frame never see the tilted road: only the
    odometry's speed, 14 % too fast, measures it, and moves it steadily toward the truth (past
    0.15 deg of the 0.4 in 25 frames; the rest, for now, in the gravity pitch, 0.01-0.03 deg off;
    without the speed's share the tilt stays level); with keyframes the bands measure it over every third frame (1.2 m) and find it within 0.1 deg
    (the mean of the last nine frames), the gravity pitch true to 0.01 deg."""
    slow = _tilted_drive(world, 0.4, 25)
    truth = np.asarray(slow.pitch_roll[:, 0])
    gated = _street_bands(slow, keyframes=False)
    tilt, pitch = _tilt_and_pitch(gated, slow)
    assert np.all(np.diff(tilt) > 0) and np.radians(0.15) < tilt[-1] < TILT
    assert np.radians(0.01) < np.abs(pitch - truth).max() < np.radians(0.03)
    # Without the speed's share (speed_coupling off) nothing measures it: the tilt stays level.
    assert gated.road_tilt is not None
    uncoupled = dataclasses.replace(gated, road_tilt=dataclasses.replace(gated.road_tilt, speed_coupling=False))
    np.testing.assert_array_equal(_tilt_and_pitch(uncoupled, slow)[0], 0.0)
    tilt, pitch = _tilt_and_pitch(_street_bands(slow, keyframes=True), slow)
    # Before the first keyframe pair (1.2 m, at frame 3) only the speed moves the tilt, slowly.
    assert tilt[2] < np.radians(0.05) and tilt[3] - tilt[2] > 5 * (tilt[2] - tilt[1])
    assert abs(np.mean(tilt[-9:]) - TILT) < np.radians(0.1)
    assert np.abs(pitch - truth).max() < np.radians(0.01)


def test_keyframes_change_nothing_above_the_travel_gate(tilted_view):
    """At 1.2 m per frame every frame engages the bands, so the keyframe is always the previous
    frame: the same run as without keyframes (to float32 round-off, which XLA's different fusion
    of the two programs moves, and DPC's peaks carry along the run)."""
    plain = eqx.filter_jit(lambda m, s: m(s, warm_start=True))(_street_bands(tilted_view, False), tilted_view)
    keyed = eqx.filter_jit(lambda m, s: m(s, warm_start=True))(_street_bands(tilted_view, True), tilted_view)
    np.testing.assert_allclose(keyed.increments, plain.increments, atol=1e-4)
    np.testing.assert_allclose(keyed.pitch_roll, plain.pitch_roll, atol=1e-6)


def test_a_keyframe_pairs_slope_is_read_net_of_the_filters_corrections(world):
    """A keyframe BEV projected 0.05 deg off the truth in pitch, the current one at the filter's
    (true) prediction, 1.2 m apart on a level road: the road tilt the pair measures (plain band
    update) is half a degree when the keyframe's error is unknown; when the keyframe records that
    the filter corrected its pitch by -0.05 deg since its BEV was projected, most of it goes
    (``remove_drift`` is first order in the band distances and overshoots by about a third, as in
    ``tests/vision/test_bands.py``), and with the wrong sign it grows."""
    level = _tilted_drive(world, 1.2, 3, tilt=0.0)
    model = _street_bands(level, keyframes=True, robust=False)
    carry, frames, seq = model.start(level, warm_start=True)
    frame_dt = model.frame_dt(seq)
    carry, _ = model.step(carry, jax.tree_util.tree_map(lambda a: a[0], frames), seq.camera, frame_dt)
    offset = np.radians(0.05)
    key_bev = model.bev(frames.image[0], jnp.asarray(level.pitch_roll[0]) + jnp.array([offset, 0.0]), seq.camera)
    observe = jax.jit(lambda c: model.observe(c, jax.tree_util.tree_map(lambda a: a[1], frames), seq.camera, frame_dt))

    def tilt_read(pitch_drift):
        key = carry.keyframe._replace(bev=key_bev, pitch_drift=jnp.float32(pitch_drift))
        return float(observe(carry._replace(keyframe=key)).road_tilt.mean[0])

    unknown, net, wrong = tilt_read(0.0), tilt_read(-offset), tilt_read(offset)
    assert abs(unknown) > np.radians(0.3)
    assert abs(net) < 0.45 * abs(unknown)
    assert abs(wrong) > 1.5 * abs(unknown)
