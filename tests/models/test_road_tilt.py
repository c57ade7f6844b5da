"""The road's tilt as a state (jbevo.models.road_tilt): its walk and update, its gradient, and,
on a drive whose camera looks at the road 0.4 deg further down than the IMU's level says (a
grade the IMU cannot see), BEVO with bands finds the tilt while its pitch against gravity stays
true; the plain band update instead pulls the gravity pitch off. Below the bands' travel gate,
keyframes let them find it too."""

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
from jbevo.models.bevo import Bevo
from jbevo.models.road_tilt import RoadTilt
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


def _tilted_drive(world, step, n, tilt=TILT):
    """A level straight drive at ``step`` metres per frame (noiseless IMU) whose KITTI camera is
    mounted ``tilt`` radians nose down (default :data:`TILT`, 0.4 deg), read back with the level
    camera: to the model, a road falling by ``tilt``."""
    nominal = Camera.kitti()
    mounted = eqx.tree_at(
        lambda c: c.rotation_body_to_camera,
        nominal,
        jnp.asarray(FORWARD, jnp.float32) @ level_to_body(jnp.float32(tilt), jnp.float32(0.0)).T,
    )
    x = 20.0 + step * np.arange(n)
    poses = poses_from_euler(np.zeros((n, 3)), np.stack([x, np.full(n, 30.0), np.full(n, 1.65)], -1))
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
    tilt, pitch = _tilt_and_pitch(dataclasses.replace(robust, road_tilt=RoadTilt.create()), tilted_view)
    assert abs(np.mean(tilt[-8:]) - TILT) < np.radians(0.1)
    assert np.abs(pitch - truth).max() < np.radians(0.01)
    _, pitch = _tilt_and_pitch(robust, tilted_view)
    assert np.all(np.abs(TILT - (pitch[-8:] - truth[-8:])) > np.radians(0.2))


def _street_bands(seq, keyframes, robust=True):
    """The real-street bands (robust, engaged from 1 m, road tilt) on the tilted drive's grid."""
    model = Bevo.create(BevGrid(0.1, (256, 256), near=4.0), seq.imu_dt, n_angles=256, road_tilt=True)
    return dataclasses.replace(model, bands=BandGeometry.create(robust=robust, min_travel=1.0, keyframes=keyframes))


def test_keyframes_find_the_road_tilt_below_the_travel_gate(world):
    """At 0.4 m per frame the bands engaged from 1 m per frame never see the tilted road, and the
    unmeasured grade pulls the gravity pitch off through the odometry's speed (by 0.03 deg here);
    with keyframes they measure it over every third frame (1.2 m) and find it within 0.1 deg (the
    mean of the last nine frames), the gravity pitch true to 0.01 deg."""
    slow = _tilted_drive(world, 0.4, 25)
    truth = np.asarray(slow.pitch_roll[:, 0])
    tilt, pitch = _tilt_and_pitch(_street_bands(slow, keyframes=False), slow)
    assert np.all(tilt == 0.0) and np.abs(pitch - truth).max() > np.radians(0.02)
    tilt, pitch = _tilt_and_pitch(_street_bands(slow, keyframes=True), slow)
    assert np.all(tilt[:3] == 0.0) and tilt[3] != 0.0  # the first keyframe pair spans 1.2 m
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
